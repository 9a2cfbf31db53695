"""Static stability of rigid parts: convex pieces, resting poses, separation, support, loads.

Design rule: exact polyhedral geometry, no simulation and no sampling, fast enough to call
inside a planner's loop. An object's geometry is a `Shape`: convex pieces (vertex arrays in its
own frame) whose union is the object, made from a watertight mesh by `Shape.from_mesh` or
given directly. Distances between pieces come from the separating-axis theorem (face normals
and edge-pair cross products): exact for penetration and for the face-to-face contacts of
resting parts. The table is the plane z = 0. Uniform density: masses and centres of mass
come from the pieces' volumes. Records are `{"id", "mesh", "pose"}` with `pose` =
`T_world_object` (4, 4) [m]; `shapes` maps mesh keys to `Shape`s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise

import cv2
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from toolbox.errors import ToolboxError

__all__ = [
    "RestingPose",
    "Shape",
    "collisions",
    "separation",
    "stable_poses",
    "supports",
    "unstable_objects",
]

TABLE = "table"
VERTICAL = 0.7  # |axis z| above which a contact carries weight rather than touching sideways


@dataclass(frozen=True)
class _Piece:
    vertices: np.ndarray  # (n, 3)
    normals: np.ndarray  # (f, 3) distinct outward face normals
    edges: np.ndarray  # (e, 3) distinct unit edge directions (up to sign)
    centre: np.ndarray  # (3,) bounding-sphere centre
    radius: float
    volume: float
    centroid: np.ndarray  # (3,)

    @staticmethod
    def of(points: np.ndarray) -> _Piece:
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        try:
            hull = ConvexHull(pts)
        except (QhullError, ValueError) as err:
            raise ToolboxError(
                f"a convex piece is degenerate (flat or < 4 points): {err}"
            ) from None
        verts = pts[hull.vertices]
        planes = np.round(hull.equations, 9)
        edges = []
        for i, tri in enumerate(hull.simplices):
            for j, nb in enumerate(hull.neighbors[i]):
                if nb > i and not np.array_equal(planes[i], planes[nb]):
                    a, b = np.delete(tri, j)
                    edges.append(pts[b] - pts[a])
        e = np.asarray(edges, dtype=float).reshape(-1, 3)
        e /= np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-12)
        inner = verts.mean(axis=0)
        tets = pts[hull.simplices] - inner  # (f, 3, 3)
        vol = np.abs(np.linalg.det(tets)) / 6.0
        centroid = inner + (vol[:, None] * tets.sum(axis=1) / 4.0).sum(axis=0) / vol.sum()
        lo, hi = verts.min(axis=0), verts.max(axis=0)
        centre = (lo + hi) / 2
        return _Piece(
            vertices=verts,
            normals=_distinct(hull.equations[:, :3], signed=True),
            edges=_distinct(e, signed=False),
            centre=centre,
            radius=float(np.linalg.norm(verts - centre, axis=1).max()),
            volume=float(hull.volume),
            centroid=centroid,
        )

    def posed(self, T: np.ndarray) -> _Piece:
        R, t = T[:3, :3], T[:3, 3]
        return _Piece(
            vertices=self.vertices @ R.T + t,
            normals=self.normals @ R.T,
            edges=self.edges @ R.T,
            centre=self.centre @ R.T + t,
            radius=self.radius,
            volume=self.volume,
            centroid=self.centroid @ R.T + t,
        )


def _distinct(d: np.ndarray, *, signed: bool) -> np.ndarray:
    if not signed:  # ±d is one axis: make the first non-zero coordinate positive
        key = np.round(d, 6) @ np.array([1e6, 1e3, 1.0])
        d = np.where((key < 0)[:, None], -d, d)
    _, idx = np.unique(np.round(d, 6), axis=0, return_index=True)
    return d[np.sort(idx)]


class _Posed(list):
    """A shape's pieces at one pose; hashed by identity, so pair results can be cached for as
    long as the shape's pose cache keeps it (the same shape and pose give the same object)."""

    __hash__ = object.__hash__  # type: ignore[assignment]

    def __eq__(self, other: object) -> bool:
        return self is other


_PAIRS: dict[tuple, tuple] = {}  # (posed a, posed b, tolerance) → (gap, axis) or patch


def _cached(key: tuple, compute):
    got = _PAIRS.get(key)
    if got is None:
        if len(_PAIRS) >= 50000:
            _PAIRS.clear()
        got = _PAIRS[key] = compute()
    return got


class Shape:
    """A rigid object as convex pieces in its own frame [m].

    Attributes:
        pieces: list of vertex arrays (k, 3), one per convex piece.
        volume: total volume [m³].
        centre_of_mass: (3,) for uniform density.
        exact: False when `from_mesh` had to fall back to the convex hull (conservative).
    """

    def __init__(self, pieces: Sequence[np.ndarray], *, exact: bool = True) -> None:
        if not pieces:
            raise ToolboxError("a Shape needs at least one convex piece")
        self._pieces = [_Piece.of(p) for p in pieces]
        self.pieces = [p.vertices.copy() for p in self._pieces]
        vols = np.array([p.volume for p in self._pieces])
        self.volume = float(vols.sum())
        self.centre_of_mass = (vols[:, None] * [p.centroid for p in self._pieces]).sum(
            axis=0
        ) / max(self.volume, 1e-18)
        self.exact = exact
        self._cache: dict[bytes, _Posed] = {}

    def _posed(self, T: np.ndarray) -> _Posed:
        """The pieces in the world at pose T, cached: planners ask about the same poses often."""
        key = T.tobytes()
        got = self._cache.get(key)
        if got is None:
            if len(self._cache) >= 4096:
                self._cache.clear()
            got = self._cache[key] = _Posed(p.posed(T) for p in self._pieces)
        return got

    @staticmethod
    def from_pieces(pieces: Sequence[np.ndarray]) -> Shape:
        """A shape from convex vertex arrays (k, 3) [m] in the object frame."""
        return Shape([np.asarray(p, dtype=float).reshape(-1, 3) for p in pieces])

    @staticmethod
    def from_mesh(mesh, *, tolerance: float = 1e-3) -> Shape:
        """Convex pieces of a watertight mesh (trimesh.Trimesh) in its own frame.

        A convex mesh is one piece. Otherwise the mesh is cut into slabs between its vertices'
        coordinates along x, y or z; the axis whose slabs are all convex (their hulls add up to
        the mesh volume within `tolerance`, relative) wins, and neighbouring slabs whose union
        is convex are merged. Extruded profiles such as an arch, an L or a T decompose exactly.
        When no axis works the convex hull is returned with `exact` False (conservative for
        collisions, wrong for what rests inside a hollow).
        """
        V = np.asarray(mesh.vertices, dtype=float)
        E = np.asarray(mesh.edges_unique, dtype=int)
        total = abs(float(mesh.volume))
        if len(V) < 4 or total <= 0:
            raise ToolboxError("Shape.from_mesh needs a closed mesh with volume")
        if ConvexHull(V).volume <= total * (1 + tolerance):
            return Shape([V])
        best = None
        for axis in range(3):
            slabs = _slabs(V, E, axis)
            vols = [_hull_volume(s) for s in slabs]
            if sum(vols) > total * (1 + tolerance):
                continue
            merged = _merge(slabs, vols, tolerance)
            if best is None or len(merged) < len(best):
                best = merged
        if best is None:
            return Shape([V], exact=False)
        return Shape(best)


def _hull_volume(points: np.ndarray) -> float:
    try:
        return float(ConvexHull(points).volume)
    except (QhullError, ValueError):
        return 0.0


def _slabs(V: np.ndarray, E: np.ndarray, axis: int) -> list[np.ndarray]:
    """Vertex sets of the mesh between consecutive vertex coordinates along `axis`.

    Each slab's boundary sections are taken just inside it, so that a face lying in a cutting
    plane (the inner side of an arch's leg) does not leak into the neighbouring slab.
    """
    c = V[:, axis]
    cuts = np.unique(np.round(c, 9))
    a, b = c[E[:, 0]], c[E[:, 1]]
    out = []
    for lo, hi in pairwise(cuts):
        eps = 1e-6 * (hi - lo)
        pts = [V[(c > lo + eps) & (c < hi - eps)]]
        for plane, snap in ((lo + eps, lo), (hi - eps, hi)):
            cross = (a - plane) * (b - plane) < 0
            if cross.any():
                t = (plane - a[cross]) / (b[cross] - a[cross])
                p0, p1 = V[E[cross, 0]], V[E[cross, 1]]
                q = p0 + t[:, None] * (p1 - p0)
                q[:, axis] = snap
                pts.append(q)
        out.append(np.unique(np.round(np.concatenate(pts), 12), axis=0))
    return [s for s in out if _hull_volume(s) > 0]


def _merge(slabs: list[np.ndarray], vols: list[float], tolerance: float) -> list[np.ndarray]:
    out, cur, vol = [], slabs[0], vols[0]
    for s, v in zip(slabs[1:], vols[1:], strict=True):
        union = np.concatenate([cur, s])
        if _hull_volume(union) <= (vol + v) * (1 + tolerance):
            cur, vol = union, vol + v
        else:
            out.append(cur)
            cur, vol = s, v
    out.append(cur)
    return out


@dataclass(frozen=True, kw_only=True)
class RestingPose:
    """One way an object can rest on a flat surface.

    Attributes:
        rotation: (3, 3) object orientation; any yaw about world z may be applied before it
            (`Rz(yaw) @ rotation`).
        height: z [m] of the object's origin when its lowest point touches z = 0.
        margin: how far [m] the centre of mass lies inside the contact face, seen from above
            (larger is steadier; < 0 would tip).
        com_height: height [m] of the centre of mass above the surface.
    """

    rotation: np.ndarray
    height: float
    margin: float
    com_height: float


def stable_poses(shape: Shape | object, *, min_tip_angle: float = 0.09) -> list[RestingPose]:
    """The resting orientations of an object on a flat surface, steadiest first.

    Each face of the convex hull whose contact polygon holds the centre of mass so far inside
    that the object must be tilted by more than `min_tip_angle` [rad] to tip over is a
    resting pose (this leaves out the facets of a faceted cylinder's side, on which it rolls). The rotation
    brings that face's outward normal to world -z by the smallest turn (a half turn about x
    for the top face), so an upright object's own bottom face gives the identity. Sorted by
    decreasing margin / centre-of-mass height, then deterministically.

    Args:
        shape: a `Shape`, or a watertight mesh (decomposed with `Shape.from_mesh`).
    """
    s = shape if isinstance(shape, Shape) else Shape.from_mesh(shape)
    pts = np.concatenate(s.pieces)
    hull = ConvexHull(pts)
    com = s.centre_of_mass
    out: list[RestingPose] = []
    for eq in np.unique(np.round(hull.equations, 7), axis=0):
        n, d = eq[:3] / np.linalg.norm(eq[:3]), eq[3]
        on = pts[np.abs(pts @ n + d) < 1e-6]
        if len(on) < 3:
            continue
        R = _rotation_to_down(n)
        flat = on @ R.T
        c = R @ com
        margin = _inside_margin(flat[:, :2], c[:2])
        z0 = float(flat[:, 2].mean())
        if margin <= 0 or np.arctan2(margin, c[2] - z0) < min_tip_angle:
            continue
        out.append(
            RestingPose(rotation=R, height=-z0, margin=float(margin), com_height=float(c[2] - z0))
        )
    out.sort(
        key=lambda p: (-p.margin / max(p.com_height, 1e-9), tuple(np.round(p.rotation, 6).ravel()))
    )
    return out


def _rotation_to_down(n: np.ndarray) -> np.ndarray:
    """Smallest rotation (3, 3) taking unit vector n to (0, 0, -1)."""
    down = np.array([0.0, 0.0, -1.0])
    c = float(n @ down)
    if c > 1 - 1e-12:
        return np.eye(3)
    if c < -1 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])  # a half turn about x
    v = np.cross(n, down)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


def _inside_margin(poly_pts: np.ndarray, p: np.ndarray) -> float:
    """Signed distance of p inside the convex hull of 2D points (< 0 outside)."""
    h = _hull2(poly_pts)
    if len(h) < 3:
        return -np.inf
    e = np.roll(h, -1, axis=0) - h
    cross = e[:, 0] * (p[1] - h[:, 1]) - e[:, 1] * (p[0] - h[:, 0])
    return float((cross / np.linalg.norm(e, axis=1)).min())


# -- separation, collisions, support -------------------------------------------------------


def _posed(records: Sequence[Mapping], shapes: Mapping[str, Shape]) -> list[tuple[str, _Posed]]:
    out = []
    for i, r in enumerate(records):
        key = r.get("mesh") if isinstance(r, Mapping) else None
        if key not in shapes:
            known = ", ".join(sorted(map(str, shapes))) or "(none)"
            raise ToolboxError(f"records[{i}].mesh {key!r} has no shape; known: {known}")
        T = np.asarray(r.get("pose"), dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ToolboxError(f"records[{i}].pose must be a finite (4, 4) matrix")
        out.append((str(r.get("id", i)), shapes[str(key)]._posed(T)))
    return out


def _piece_gap(a: _Piece, b: _Piece) -> tuple[float, np.ndarray]:
    ea, eb = a.edges[:, None, :], b.edges[None, :, :]
    cross = (
        ea[..., [1, 2, 0]] * eb[..., [2, 0, 1]] - ea[..., [2, 0, 1]] * eb[..., [1, 2, 0]]
    ).reshape(-1, 3)
    n = np.linalg.norm(cross, axis=1)
    ok = n > 1e-6
    axes = np.concatenate([a.normals, b.normals, cross[ok] / n[ok, None]])
    pa, pb = a.vertices @ axes.T, b.vertices @ axes.T
    up = pa.min(axis=0) - pb.max(axis=0)  # a beyond b along the axis
    down = pb.min(axis=0) - pa.max(axis=0)
    gaps = np.maximum(up, down)
    i = int(np.argmax(gaps))
    return float(gaps[i]), axes[i] * (1.0 if up[i] >= down[i] else -1.0)


def _body_gap(A: list, B: list, cutoff: float) -> tuple[float, np.ndarray]:
    best, axis = np.inf, np.array([0.0, 0.0, 1.0])
    for a in A:
        for b in B:
            if np.linalg.norm(a.centre - b.centre) - a.radius - b.radius > cutoff:
                continue
            g, n = _piece_gap(a, b)
            if g < best:
                best, axis = g, n
    return best, axis


def separation(
    shape_a: Shape, pose_a: object, shape_b: Shape, pose_b: object, *, cutoff: float = np.inf
) -> tuple[float, np.ndarray]:
    """Gap [m] between two posed shapes and its unit axis, pointing from b towards a.

    Negative: they interpenetrate that deep. An axis with |z| >= 0.7 means one rests on (or
    hangs under) the other; a horizontal axis means a side contact. Pairs of pieces farther
    apart than `cutoff` [m] are skipped (the gap is then inf).
    """
    A = shape_a._posed(np.asarray(pose_a, float))
    B = shape_b._posed(np.asarray(pose_b, float))
    return _body_gap(A, B, cutoff)


def collisions(
    records: Sequence[Mapping], shapes: Mapping[str, Shape], *, tolerance: float = 0.0015
) -> list[tuple[str, str, float]]:
    """Pairs (id_a, id_b, depth [m]) interpenetrating by more than `tolerance` [m], the table
    ("table") included, in record order."""
    bodies = _posed(records, shapes)
    out = []
    pairs = _pairs(bodies, 0.0)
    for i, (ia, A) in enumerate(bodies):
        low = min(p.vertices[:, 2].min() for p in A)
        if low < -tolerance:
            out.append((ia, TABLE, float(-low)))
        for j in range(i + 1, len(bodies)):
            g = pairs.get((i, j), (np.inf,))[0]
            if g < -tolerance:
                out.append((ia, bodies[j][0], float(-g)))
    return out


def _box(B: list) -> tuple[np.ndarray, np.ndarray]:
    return (
        np.min([p.vertices.min(axis=0) for p in B], axis=0),
        np.max([p.vertices.max(axis=0) for p in B], axis=0),
    )


def _pairs(bodies, cutoff: float) -> dict[tuple[int, int], tuple[float, np.ndarray]]:
    """Gap and axis (j → i) of every pair i < j whose bounding boxes are within `cutoff`."""
    boxes = [_cached((B, "box"), lambda B=B: _box(B)) for _, B in bodies]
    out = {}
    for i in range(len(bodies)):
        for j in range(i + 1, len(bodies)):
            (la, ha), (lb, hb) = boxes[i], boxes[j]
            if np.any(la > hb + cutoff) or np.any(lb > ha + cutoff):
                continue
            A, B = bodies[i][1], bodies[j][1]
            g, n = _cached((A, B, "gap", cutoff), lambda A=A, B=B: _body_gap(A, B, cutoff))
            if g <= cutoff:
                out[i, j] = (g, n)
    return out


def _contacts(bodies, contact_tol: float) -> dict[int, list[tuple[int, np.ndarray]]]:
    """For every body index: (supporter index or -1 for the table, contact points (k, 2))."""
    out: dict[int, list[tuple[int, np.ndarray]]] = {i: [] for i in range(len(bodies))}
    for i, (_, A) in enumerate(bodies):
        low = min(p.vertices[:, 2].min() for p in A)
        if low <= contact_tol:
            pts = np.concatenate([p.vertices[p.vertices[:, 2] <= contact_tol, :2] for p in A])
            out[i].append((-1, pts))
    for (i, j), (_, n) in _pairs(bodies, contact_tol).items():
        if abs(n[2]) < VERTICAL:
            continue
        upper, lower = (i, j) if n[2] > 0 else (j, i)
        A, B = bodies[upper][1], bodies[lower][1]
        patch = _cached((A, B, "patch", contact_tol), lambda A=A, B=B: _patch(A, B, contact_tol))
        if len(patch):
            out[upper].append((lower, patch))
    for i in out:
        out[i].sort(key=lambda c: c[0])
    return out


def _patch(A: list, B: list, tol: float) -> np.ndarray:
    out = []
    for pa in A:
        za = pa.vertices[:, 2].min()
        bottom = pa.vertices[pa.vertices[:, 2] <= za + tol, :2]
        lo, hi = pa.vertices[:, :2].min(axis=0), pa.vertices[:, :2].max(axis=0)
        for pb in B:
            zb = pb.vertices[:, 2].max()
            if abs(za - zb) > 2 * tol:
                continue
            if np.any(pb.vertices[:, :2].min(axis=0) > hi) or np.any(
                pb.vertices[:, :2].max(axis=0) < lo
            ):
                continue
            top = pb.vertices[pb.vertices[:, 2] >= zb - tol, :2]
            out.append(_clip(bottom, top))
    return np.concatenate(out) if out else np.zeros((0, 2))


def _hull2(pts: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull (k, 2) of 2D points; k < 3 when they are degenerate."""
    pts = np.asarray(pts, dtype=float).reshape(-1, 2)
    if len(pts) < 3:
        return pts
    idx = cv2.convexHull(pts.astype(np.float32), clockwise=False, returnPoints=False)
    h = pts[idx.ravel()]
    if len(h) >= 3:
        area = 0.5 * np.sum(h[:, 0] * np.roll(h[:, 1], -1) - np.roll(h[:, 0], -1) * h[:, 1])
        if abs(area) < 1e-12:  # collinear: the two extreme points
            return h[[int(np.argmin(h[:, 0] + h[:, 1])), int(np.argmax(h[:, 0] + h[:, 1]))]]
        if area < 0:
            h = h[::-1]
    return h


def _clip(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Vertices of the intersection of the convex hulls of two 2D point sets."""
    ha, hb = _hull2(a), _hull2(b)
    if len(ha) < 3 or len(hb) < 3:
        small, big = (ha, hb) if len(ha) < 3 else (hb, ha)
        if len(big) < 3:
            return np.zeros((0, 2))
        return np.array([p for p in small if _inside_margin(big, p) > -1e-4]).reshape(-1, 2)
    poly = list(ha)
    for c0, c1 in zip(hb, np.roll(hb, -1, axis=0), strict=True):
        e = c1 - c0

        def side(p, c0=c0, e=e):
            return e[0] * (p[1] - c0[1]) - e[1] * (p[0] - c0[0])

        nxt = []
        for p, q in zip(poly, poly[1:] + poly[:1], strict=True):
            sp, sq = side(p), side(q)
            if sp >= -1e-12:
                nxt.append(p)
            if (sp >= -1e-12) != (sq >= -1e-12):
                nxt.append(p + (q - p) * (sp / (sp - sq)))
        poly = nxt
        if not poly:
            return np.zeros((0, 2))
    return np.array(poly).reshape(-1, 2)


def supports(
    records: Sequence[Mapping], shapes: Mapping[str, Shape], *, contact_tol: float = 0.002
) -> dict[str, list[str]]:
    """What each object rests on: id → sorted supporter ids ("table" for the table).

    A rests on B when A's bottom lies within `contact_tol` [m] of B's top where their
    outlines overlap (side contacts are not support). [] means it rests on nothing.
    """
    bodies = _posed(records, shapes)
    found = _contacts(bodies, contact_tol)
    return {
        bodies[i][0]: sorted(TABLE if j < 0 else bodies[j][0] for j, _ in found[i])
        for i in range(len(bodies))
    }


def unstable_objects(
    records: Sequence[Mapping],
    shapes: Mapping[str, Shape],
    *,
    contact_tol: float = 0.002,
    margin: float = 0.0,
) -> dict[str, str]:
    """Objects that would fall or tip, with the reason: {} when the structure stands.

    Loads are carried down: an object together with everything that rests only on it
    (directly or through others) must have its joint centre of mass at least `margin` [m]
    inside the convex hull of its contact patches, seen from above. So a beam on two pillars
    with a block at one end tips when the block moves the joint centre past a pillar, and a
    part resting on nothing is reported.
    """
    bodies = _posed(records, shapes)
    found = _contacts(bodies, contact_tol)
    mass = [sum(p.volume for p in B) for _, B in bodies]
    com = [
        sum(p.volume * p.centroid for p in B) / max(m, 1e-18)
        for (_, B), m in zip(bodies, mass, strict=True)
    ]
    under = {i: {j for j, _ in found[i]} for i in found}
    out: dict[str, str] = {}
    for i, (name, _) in enumerate(bodies):
        if not found[i]:
            out[name] = "rests on nothing"
            continue
        load = {i}
        changed = True
        while changed:  # everything whose supporters all lie in the load
            changed = False
            for k in under:
                if k not in load and under[k] and under[k] <= load:
                    load.add(k)
                    changed = True
        m = sum(mass[k] for k in load)
        c = sum(mass[k] * com[k] for k in load) / m
        pts = np.concatenate([p for _, p in found[i]])
        inside = (
            _inside_margin(pts, c[:2]) if len(_hull2(pts)) >= 3 else _segment_margin(pts, c[:2])
        )
        if inside < margin:
            what = "its centre of mass" if len(load) == 1 else "its centre of mass with its load"
            out[name] = f"{what} lies {1000 * -inside:.1f} mm outside its support"
    return out


def _segment_margin(pts: np.ndarray, p: np.ndarray) -> float:
    h = _hull2(pts)
    if len(h) == 0:
        return -np.inf
    a, b = h[0], h[-1]
    ab = b - a
    t = 0.0 if not ab.any() else float(np.clip((p - a) @ ab / (ab @ ab), 0, 1))
    return -float(np.linalg.norm(p - (a + t * ab)))
