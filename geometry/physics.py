"""Abstract physics for checking plans: interpenetration and support of meshes at poses.

Design rule: pure numpy geometry, no simulator and no I/O, so the same answers come out inside
the sandbox (the `plan` check suite) and on the host (the trial harness's "plan success"). An
object is the union of convex parts (a domain's collision parts, or the convex hull of its
mesh). Distances between convex parts come from the separating-axis theorem over face normals
and edge-pair cross products: exact for penetration depth, a lower bound for separations (exact
for the face-face contacts of resting objects). The table is the plane z = 0.

An object is *supported* when it rests on the table or on other objects (its lowest points
within `CONTACT_TOL` of their top) and its centre of mass lies, seen from above, inside the
convex hull of its contact patches. Loads from objects above are not propagated: an overhang
built from individually stable objects is accepted.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from contracts import se3

PENETRATION_TOL = 0.0015  # deepest interpenetration still counted as touching [m]
CONTACT_TOL = 0.002  # largest gap still counted as resting on [m]
COM_MARGIN = 0.0005  # the centre of mass may lie this far outside the support polygon [m]
VERTICAL = 0.7  # |normal_z| above which a contact supports rather than touches sideways
TABLE = "table"


# -- convex parts -----------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class ConvexPart:
    """One convex piece of an object (object or world frame)."""

    vertices: np.ndarray  # (n, 3) [m]
    normals: np.ndarray  # (f, 3) distinct outward face normals
    edges: np.ndarray  # (e, 3) distinct unit edge directions
    centre: np.ndarray  # (3,)
    radius: float  # bounding radius about `centre` [m]

    @staticmethod
    def from_points(points: Any) -> ConvexPart:
        """The convex hull of points (n, 3) [m] as a part."""
        from scipy.spatial import ConvexHull

        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        hull = ConvexHull(pts)
        verts = pts[np.unique(hull.simplices)]
        normals = hull.equations[:, :3]
        # feature edges: those between triangles of different planes
        planes = np.round(hull.equations, 9)
        edges = []
        for i, tri in enumerate(hull.simplices):
            for j, nb in enumerate(hull.neighbors[i]):
                if nb > i and not np.array_equal(planes[i], planes[nb]):
                    a, b = np.delete(tri, j)
                    edges.append(pts[b] - pts[a])
        e = np.asarray(edges, dtype=float).reshape(-1, 3)
        e = e / np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-12)
        centre = 0.5 * (verts.min(axis=0) + verts.max(axis=0))
        return ConvexPart(
            vertices=verts,
            normals=_unique_directions(normals, signed=True),
            edges=_unique_directions(e, signed=False),
            centre=centre,
            radius=float(np.linalg.norm(verts - centre, axis=1).max()),
        )

    def transformed(self, pose: np.ndarray) -> ConvexPart:
        r, t = pose[:3, :3], pose[:3, 3]
        return ConvexPart(
            vertices=self.vertices @ r.T + t,
            normals=self.normals @ r.T,
            edges=self.edges @ r.T,
            centre=r @ self.centre + t,
            radius=self.radius,
        )


def _unique_directions(d: np.ndarray, *, signed: bool) -> np.ndarray:
    d = np.asarray(d, dtype=float).reshape(-1, 3)
    if not signed:  # a direction and its opposite give the same separating axis
        key = np.round(d, 6)
        first = np.argmax(np.abs(key) > 1e-6, axis=1)
        flip = key[np.arange(len(d)), first] < 0
        d = np.where(flip[:, None], -d, d)
    if len(d) == 0:
        return d
    _, idx = np.unique(np.round(d, 6), axis=0, return_index=True)
    return d[np.sort(idx)]


def separation(a: ConvexPart, b: ConvexPart) -> tuple[float, np.ndarray]:
    """Signed separation [m] of two convex parts (negative: penetration depth) and its axis.

    The axis is a unit vector pointing from `b` towards `a`.
    """
    cross = np.cross(a.edges[:, None, :], b.edges[None, :, :]).reshape(-1, 3)
    n = np.linalg.norm(cross, axis=1)
    keep = n > 1e-6
    axes = np.concatenate([a.normals, b.normals, cross[keep] / n[keep, None]])
    pa = a.vertices @ axes.T  # (na, k)
    pb = b.vertices @ axes.T
    gap_pos = pa.min(axis=0) - pb.max(axis=0)  # a beyond b along +axis
    gap_neg = pb.min(axis=0) - pa.max(axis=0)
    gaps = np.maximum(gap_pos, gap_neg)
    i = int(np.argmax(gaps))
    sign = 1.0 if gap_pos[i] >= gap_neg[i] else -1.0
    return float(gaps[i]), sign * axes[i]


# -- bodies -----------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Body:
    """An object placed in the world: its convex parts and centre of mass, world frame."""

    id: str
    parts: tuple[ConvexPart, ...]
    com: np.ndarray  # (3,) [m]

    @property
    def lowest(self) -> float:
        return float(min(p.vertices[:, 2].min() for p in self.parts))

    @property
    def vertices(self) -> np.ndarray:
        return np.concatenate([p.vertices for p in self.parts])


class Geometry:
    """The convex parts of a domain's meshes, by mesh key (object frames).

    Args:
        parts: mesh key → list of vertex arrays (n, 3), each the hull of one convex part.
        centres: mesh key → centre of mass (3,) in the object frame; default: the mean of the
            parts' bounding-box centres.
    """

    def __init__(
        self,
        parts: Mapping[str, Sequence[Any]],
        centres: Mapping[str, Any] | None = None,
    ) -> None:
        self.parts = {k: [ConvexPart.from_points(p) for p in ps] for k, ps in parts.items()}
        self.centres = {
            k: np.asarray(centres[k], float)
            if centres and k in centres
            else np.mean([p.centre for p in ps], axis=0)
            for k, ps in self.parts.items()
        }

    @staticmethod
    def from_meshes(meshes: Mapping[str, Any]) -> Geometry:
        """One convex part per mesh (its hull); meshes are trimesh-like (`.vertices`)."""
        return Geometry(
            {k: [np.asarray(m.vertices, float)] for k, m in meshes.items()},
            {k: np.asarray(m.vertices, float).mean(axis=0) for k, m in meshes.items()},
        )

    def body(self, record: Mapping[str, Any]) -> Body:
        key = record["mesh"]
        if key not in self.parts:
            raise KeyError(f"unknown mesh {key!r}; known: {', '.join(sorted(self.parts))}")
        pose = se3.as_matrix(record["pose"])
        return Body(
            id=str(record["id"]),
            parts=tuple(p.transformed(pose) for p in self.parts[key]),
            com=pose[:3, :3] @ self.centres[key] + pose[:3, 3],
        )

    def bodies(self, records: Sequence[Mapping[str, Any]]) -> list[Body]:
        return [self.body(r) for r in records]


def body_separation(a: Body, b: Body, *, cutoff: float = np.inf) -> tuple[float, np.ndarray]:
    """Smallest part-to-part separation [m] of two bodies and its axis (b → a).

    Part pairs whose bounding spheres are farther apart than `cutoff` are skipped; if all are,
    the gap returned is a lower bound above `cutoff`.
    """
    best, normal = np.inf, np.array([0.0, 0.0, 1.0])
    for pa in a.parts:
        for pb in b.parts:
            bound = float(np.linalg.norm(pa.centre - pb.centre)) - pa.radius - pb.radius
            if bound > cutoff:
                best = min(best, bound)
                continue
            gap, n = separation(pa, pb)
            if gap < best - 1e-12:
                best, normal = gap, n
    return best, normal


# -- collisions and support -------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Collision:
    """Two objects (or an object and the table) interpenetrating by `depth` [m]."""

    a: str
    b: str
    depth: float

    def describe(self) -> str:
        return f"'{self.a}' and '{self.b}' interpenetrate by {self.depth * 1000:.1f} mm"


def _pairs(
    bodies: Sequence[Body], cutoff: float
) -> dict[tuple[int, int], tuple[float, np.ndarray]]:
    """Separation and axis (j → i) of every pair i < j closer than `cutoff` [m]."""
    out = {}
    for i, a in enumerate(bodies):
        for j in range(i + 1, len(bodies)):
            gap, n = body_separation(a, bodies[j], cutoff=cutoff)
            if gap <= cutoff:
                out[i, j] = (gap, n)
    return out


def collisions(
    bodies: Sequence[Body], *, tol: float = PENETRATION_TOL, pairs: Mapping | None = None
) -> list[Collision]:
    """Pairs interpenetrating by more than `tol` [m], the table included, in body order."""
    pairs = _pairs(bodies, CONTACT_TOL) if pairs is None else pairs
    out = []
    for i, a in enumerate(bodies):
        if a.lowest < -tol:
            out.append(Collision(a=a.id, b=TABLE, depth=-a.lowest))
        for j in range(i + 1, len(bodies)):
            gap = pairs.get((i, j), (np.inf,))[0]
            if gap < -tol:
                out.append(Collision(a=a.id, b=bodies[j].id, depth=-gap))
    return out


@dataclass(frozen=True, kw_only=True)
class Support:
    """How one object rests: its supporters and whether it is statically stable."""

    id: str
    on: tuple[str, ...]  # supporter ids ("table" for the table), sorted
    stable: bool
    reason: str = ""  # why it is not stable


def supports(
    bodies: Sequence[Body],
    *,
    contact_tol: float = CONTACT_TOL,
    pen_tol: float = PENETRATION_TOL,
    pairs: Mapping | None = None,
) -> dict[str, Support]:
    """For every body: what it rests on and whether its centre of mass is over its support."""
    pairs = _pairs(bodies, contact_tol) if pairs is None else pairs
    below: dict[int, list[int]] = {i: [] for i in range(len(bodies))}
    for (i, j), (gap, n) in pairs.items():
        if gap > contact_tol:
            continue
        if n[2] >= VERTICAL:  # i rests on j
            below[i].append(j)
        elif n[2] <= -VERTICAL:
            below[j].append(i)
    out: dict[str, Support] = {}
    for i, a in enumerate(bodies):
        patches: list[np.ndarray] = []
        on: list[str] = []
        if -pen_tol - 1e-9 <= a.lowest <= contact_tol:
            on.append(TABLE)
            patches.append(_bottom(a, a.lowest, contact_tol))
        for j in sorted(below[i]):
            patch = _patch(a, bodies[j], contact_tol)
            if len(patch):
                on.append(bodies[j].id)
                patches.append(patch)
        if not on:
            out[a.id] = Support(
                id=a.id,
                on=(),
                stable=False,
                reason=f"rests on nothing: its lowest point is {a.lowest * 1000:.1f} mm above "
                f"the table and no object is within {contact_tol * 1000:.0f} mm below it",
            )
            continue
        pts = np.concatenate(patches)
        inside = _inside_hull(a.com[:2], pts, COM_MARGIN)
        out[a.id] = Support(
            id=a.id,
            on=tuple(sorted(on)),
            stable=inside,
            reason=""
            if inside
            else f"has its centre of mass outside its support on {', '.join(sorted(on))} "
            "(it would tip over)",
        )
    return out


def _bottom(a: Body, z: float, tol: float) -> np.ndarray:
    v = a.vertices
    return v[v[:, 2] <= z + tol][:, :2]


def _patch(upper: Body, lower: Body, tol: float) -> np.ndarray:
    """Contact points (k, 2) where `upper`'s bottom meets `lower`'s top, seen from above."""
    out = []
    for pa in upper.parts:
        za = pa.vertices[:, 2].min()
        bottom = pa.vertices[pa.vertices[:, 2] <= za + tol][:, :2]
        for pb in lower.parts:
            zb = pb.vertices[:, 2].max()
            if abs(za - zb) > tol + PENETRATION_TOL:
                continue
            top = pb.vertices[pb.vertices[:, 2] >= zb - tol][:, :2]
            out.append(_intersect(bottom, top))
    return np.concatenate(out) if out else np.zeros((0, 2))


def _hull2d(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull (k, 2) of 2D points (monotone chain); k may be < 3."""
    pts = np.unique(np.round(points, 9), axis=0)
    if len(pts) <= 2:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 1e-15:
            lower.pop()
        lower.append(p)
    upper: list = []
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 1e-15:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _inside_hull(p: np.ndarray, points: np.ndarray, margin: float) -> bool:
    hull = _hull2d(points)
    if len(hull) == 0:
        return False
    if len(hull) <= 2:  # a point or a segment: inside when within the margin of it
        a, b = hull[0], hull[-1]
        ab = b - a
        t = 0.0 if not ab.any() else float(np.clip(np.dot(p - a, ab) / np.dot(ab, ab), 0, 1))
        return float(np.linalg.norm(p - (a + t * ab))) <= margin
    edges = np.roll(hull, -1, axis=0) - hull
    rel = p - hull
    cross = edges[:, 0] * rel[:, 1] - edges[:, 1] * rel[:, 0]
    dist = cross / np.linalg.norm(edges, axis=1)  # signed distance, > 0 inside
    return bool(dist.min() >= -margin)


def _intersect(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Points of the intersection of the convex hulls of two 2D point sets (Sutherland–Hodgman)."""
    ha, hb = _hull2d(a), _hull2d(b)
    if len(ha) < 3 or len(hb) < 3:  # degenerate: keep the points of one inside the other
        small, big = (ha, hb) if len(ha) < 3 else (hb, ha)
        if len(big) < 3:
            return np.zeros((0, 2))
        return np.array([p for p in small if _inside_hull(p, big, 1e-4)]).reshape(-1, 2)
    poly = list(ha)
    for i in range(len(hb)):
        c0, c1 = hb[i], hb[(i + 1) % len(hb)]
        e = c1 - c0

        def side(p, c0=c0, e=e):
            return e[0] * (p[1] - c0[1]) - e[1] * (p[0] - c0[0])

        nxt = []
        for j in range(len(poly)):
            p, q = poly[j], poly[(j + 1) % len(poly)]
            sp, sq = side(p), side(q)
            if sp >= -1e-12:
                nxt.append(p)
            if (sp >= -1e-12) != (sq >= -1e-12):
                nxt.append(p + (q - p) * (sp / (sp - sq)))
        poly = nxt
        if not poly:
            return np.zeros((0, 2))
    return np.array(poly).reshape(-1, 2)


# -- plans ------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Workspace:
    """Where objects may be placed: every vertex inside an x, y box and within `reach` of the
    robot's base axis [m]."""

    x: tuple[float, float]
    y: tuple[float, float]
    reach: float

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> Workspace:
        return Workspace(x=tuple(d["x"]), y=tuple(d["y"]), reach=float(d["reach"]))  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, Any]:
        return {"x": list(self.x), "y": list(self.y), "reach": self.reach}

    def outside(self, points: np.ndarray) -> np.ndarray | None:
        """The point (3,) farthest outside, or None when all are inside."""
        xy = np.asarray(points, float)[:, :2]
        excess = np.stack(
            [
                self.x[0] - xy[:, 0],
                xy[:, 0] - self.x[1],
                self.y[0] - xy[:, 1],
                xy[:, 1] - self.y[1],
                np.linalg.norm(xy, axis=1) - self.reach,
            ],
            axis=1,
        ).max(axis=1)
        i = int(np.argmax(excess))
        return np.asarray(points, float)[i] if excess[i] > 1e-9 else None


@dataclass(frozen=True, kw_only=True)
class PlanProblem:
    """The first thing wrong when a plan's steps are applied (step None: the final state)."""

    kind: str  # unknown_object | not_clear | collision | unsupported | workspace | goal
    message: str
    step: int | None = None
    object: str | None = None


@dataclass(frozen=True, kw_only=True)
class PlanOutcome:
    """What applying a plan did: its first problem (None when it reaches the goal) and the
    states after each step (records, poses as arrays)."""

    problem: PlanProblem | None
    states: list[list[dict]] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.problem is None


def apply_plan(
    geometry: Geometry,
    start: Sequence[Mapping[str, Any]],
    steps: Sequence[Mapping[str, Any]],
    goal: Sequence[Mapping[str, Any]],
    *,
    trans_tol: float,
    rot_tol: float | None = None,
    symmetries: Mapping[str, Sequence[np.ndarray]] | None = None,
    workspace: Workspace | None = None,
    pen_tol: float = PENETRATION_TOL,
    contact_tol: float = CONTACT_TOL,
) -> PlanOutcome:
    """Apply transfer steps ``{"object", "target_pose"}`` to `start` and judge every state.

    Each step may move an object only when nothing rests on it; the state after it must be
    collision-free, every object supported, and the moved object inside `workspace`. The last
    state must put every object within tolerance of its pose in `goal`, modulo `symmetries`
    (mesh key → object-frame transforms).
    """
    state = [dict(r, pose=se3.as_matrix(r["pose"])) for r in start]
    index = {r["id"]: i for i, r in enumerate(state)}
    states: list[list[dict]] = []
    before: dict[str, Support] | None = None
    for k, step in enumerate(steps):
        oid = step["object"]
        if oid not in index:
            known = ", ".join(sorted(index))
            return PlanOutcome(
                problem=PlanProblem(
                    kind="unknown_object",
                    step=k,
                    object=str(oid),
                    message=f"step {k} moves unknown object {oid!r}; known: {known}",
                ),
                states=states,
            )
        if before is None:
            before = supports(geometry.bodies(state), contact_tol=contact_tol, pen_tol=pen_tol)
        loaded = sorted(s.id for s in before.values() if oid in s.on)
        if loaded:
            names = ", ".join(f"'{i}'" for i in loaded)
            return PlanOutcome(
                problem=PlanProblem(
                    kind="not_clear",
                    step=k,
                    object=oid,
                    message=f"step {k} picks '{oid}' while {names} rest(s) on it",
                ),
                states=states,
            )
        state = [dict(r) for r in state]
        state[index[oid]] = dict(state[index[oid]], pose=se3.as_matrix(step["target_pose"]))
        states.append(state)
        bodies = geometry.bodies(state)
        moved = bodies[index[oid]]
        if workspace is not None:
            far = workspace.outside(moved.vertices)
            if far is not None:
                return PlanOutcome(
                    problem=PlanProblem(
                        kind="workspace",
                        step=k,
                        object=oid,
                        message=f"step {k} puts '{oid}' outside the reachable workspace (a "
                        f"point at x={far[0]:.3f}, y={far[1]:.3f} m; allowed x∈[{workspace.x[0]}, "
                        f"{workspace.x[1]}], y∈[{workspace.y[0]}, {workspace.y[1]}], within "
                        f"{workspace.reach} m of the base)",
                    ),
                    states=states,
                )
        pairs = _pairs(bodies, contact_tol)
        hits = collisions(bodies, tol=pen_tol, pairs=pairs)
        if hits:
            hit = max(hits, key=lambda c: (oid in (c.a, c.b), c.depth))
            return PlanOutcome(
                problem=PlanProblem(
                    kind="collision",
                    step=k,
                    object=oid,
                    message=f"after step {k} (moving '{oid}'): {hit.describe()}",
                ),
                states=states,
            )
        before = supports(bodies, contact_tol=contact_tol, pen_tol=pen_tol, pairs=pairs)
        bad = [s for s in before.values() if not s.stable]
        if bad:
            s = next((s for s in bad if s.id == oid), bad[0])
            return PlanOutcome(
                problem=PlanProblem(
                    kind="unsupported",
                    step=k,
                    object=s.id,
                    message=f"after step {k} (moving '{oid}'): '{s.id}' {s.reason}",
                ),
                states=states,
            )
    target = {r["id"]: r for r in goal}
    worst: tuple[float, str] | None = None
    for r in state:
        g = target.get(r["id"])
        if g is None:
            continue
        syms = list((symmetries or {}).get(r["mesh"], [np.eye(4)]))
        if not se3.within_tolerance(
            r["pose"],
            se3.as_matrix(g["pose"]),
            trans_tol=trans_tol,
            rot_tol=rot_tol,
            symmetries=syms,
        ):
            t, a = se3.pose_error(r["pose"], se3.as_matrix(g["pose"]), syms)
            if rot_tol is None:
                err = f"{t * 1000:.1f} mm from its goal (tolerance {trans_tol * 1000:.0f} mm)"
            else:
                err = (
                    f"{t * 1000:.1f} mm and {np.degrees(a):.1f}° from its goal (tolerance "
                    f"{trans_tol * 1000:.0f} mm, {np.degrees(rot_tol):.1f}°)"
                )
            if worst is None or t > worst[0]:
                worst = (t, f"'{r['id']}' ends {err}")
    if worst is not None:
        return PlanOutcome(
            problem=PlanProblem(
                kind="goal", message=f"the plan does not reach the goal: {worst[1]}"
            ),
            states=states,
        )
    return PlanOutcome(problem=None, states=states)


def scene_problems(
    geometry: Geometry,
    records: Sequence[Mapping[str, Any]],
    *,
    pen_tol: float = PENETRATION_TOL,
    contact_tol: float = CONTACT_TOL,
) -> list[str]:
    """Why a static scene is not physically valid (collisions, unsupported objects); [] if it is."""
    bodies = geometry.bodies(records)
    pairs = _pairs(bodies, contact_tol)
    out = [c.describe() for c in collisions(bodies, tol=pen_tol, pairs=pairs)]
    for s in supports(bodies, contact_tol=contact_tol, pen_tol=pen_tol, pairs=pairs).values():
        if not s.stable:
            out.append(f"'{s.id}' {s.reason}")
    return out
