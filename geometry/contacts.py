"""Contacts between posed shapes: interpenetration, what rests on what, stability with loads.

Design rule: the oracle's physics, static and exact (see `geometry.convex`): records are
``{"id", "mesh", "pose"}`` with `pose` = ``T_world_object`` (4, 4) [m] and `shapes` maps mesh
keys to `geometry.Shape`s (a `Geometry` is such a mapping). An object rests on another where
its bottom lies within the contact tolerance of the other's top and their outlines overlap;
it is stable when, together with everything that rests only on it (its load), its centre of
mass lies over the convex hull of its contact patches. The table is the plane z = 0 and is
named "table". Pair results are cached on the posed pieces (a planner asks about the same
poses again and again).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from geometry.convex import Body, body_separation, piece_gap
from geometry.planar import clip, hull2, inside_margin, segment_margin
from geometry.shape import Shape, _cached, _Posed
from geometry.tolerances import TOLERANCES

TABLE = "table"


class UnknownShape(KeyError):
    """A record names a mesh the shapes do not hold, or has no usable pose."""

    def __str__(self) -> str:
        return str(self.args[0])


def _posed(records: Sequence[Mapping], shapes: Mapping[str, Shape]) -> list[tuple[str, _Posed]]:
    out = []
    for i, r in enumerate(records):
        key = r.get("mesh") if isinstance(r, Mapping) else None
        if key not in shapes:
            known = ", ".join(sorted(map(str, shapes))) or "(none)"
            raise UnknownShape(f"records[{i}].mesh {key!r} has no shape; known: {known}")
        T = np.asarray(r.get("pose"), dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise UnknownShape(f"records[{i}].pose must be a finite (4, 4) matrix")
        out.append((str(r.get("id", i)), shapes[str(key)]._posed(T)))
    return out


def _body_gap(A: list, B: list, cutoff: float) -> tuple[float, np.ndarray]:
    best, axis = np.inf, np.array([0.0, 0.0, 1.0])
    for a in A:
        for b in B:
            if np.linalg.norm(a.centre - b.centre) - a.radius - b.radius > cutoff:
                continue
            g, n = piece_gap(a, b)
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
    records: Sequence[Mapping],
    shapes: Mapping[str, Shape],
    *,
    tolerance: float = TOLERANCES.penetration,
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
        if abs(n[2]) < TOLERANCES.vertical:
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
            out.append(clip(bottom, top))
    return np.concatenate(out) if out else np.zeros((0, 2))


def supports(
    records: Sequence[Mapping],
    shapes: Mapping[str, Shape],
    *,
    contact_tol: float = TOLERANCES.contact,
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
    contact_tol: float = TOLERANCES.contact,
    margin: float = -TOLERANCES.com_margin,
) -> dict[str, str]:
    """Objects that would fall or tip, with the reason: {} when the structure stands.

    Loads are carried down: an object together with everything that rests only on it
    (directly or through others) must have its joint centre of mass at least `margin` [m]
    inside the convex hull of its contact patches, seen from above (a negative margin allows
    it that far outside; the default allows the tolerance table's `com_margin`, which
    `toolbox.stability` names `COM_MARGIN`). So a beam on two pillars with a block at one end
    tips when the block moves the joint centre past a pillar, and a part resting on nothing is
    reported.
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
        inside = inside_margin(pts, c[:2]) if len(hull2(pts)) >= 3 else segment_margin(pts, c[:2])
        if inside < margin:
            what = "its centre of mass" if len(load) == 1 else "its centre of mass with its load"
            out[name] = f"{what} lies {1000 * -inside:.1f} mm outside its support"
    return out


def scene_problems(
    records: Sequence[Mapping],
    shapes: Mapping[str, Shape],
    *,
    penetration: float = TOLERANCES.penetration,
    contact: float = TOLERANCES.contact,
) -> list[str]:
    """Why a static scene could not stand (interpenetration, objects unsupported or tipping);
    [] when it could."""
    out = [
        f"'{a}' and '{b}' interpenetrate by {1000 * d:.1f} mm"
        for a, b, d in collisions(records, shapes, tolerance=penetration)
    ]
    out += [
        f"'{i}' {why}" for i, why in unstable_objects(records, shapes, contact_tol=contact).items()
    ]
    return out


class Geometry(Mapping[str, Shape]):
    """A domain's shapes by mesh key, with the bodies of records."""

    def __init__(self, shapes: Mapping[str, Shape]) -> None:
        self._shapes = dict(shapes)

    @staticmethod
    def from_parts(parts: Mapping[str, Sequence[np.ndarray]]) -> Geometry:
        """Shapes from convex parts: mesh key → vertex arrays (n, 3), one per part."""
        return Geometry({k: Shape.from_pieces(ps) for k, ps in parts.items()})

    def __getitem__(self, key: str) -> Shape:
        return self._shapes[key]

    def __iter__(self):
        return iter(self._shapes)

    def __len__(self) -> int:
        return len(self._shapes)

    def body(self, record: Mapping) -> Body:
        """The world body of a record ``{"id", "mesh", "pose"}``."""
        key = record["mesh"]
        if key not in self._shapes:
            known = ", ".join(sorted(self._shapes))
            raise UnknownShape(f"unknown mesh {key!r}; known: {known}")
        T = np.asarray(record["pose"], float)
        return Body(id=str(record["id"]), pieces=tuple(self._shapes[key]._posed(T)))

    def bodies(self, records: Sequence[Mapping]) -> list[Body]:
        return [self.body(r) for r in records]


def contact_edges(
    bodies: Sequence[Body],
    *,
    on_gap: float,
    adjacent_gap: float | None,
    vertical: float = TOLERANCES.vertical,
) -> list[tuple[str, str, str]]:
    """Relations from geometry: ``(a, b, "on")`` when a rests on b, and ``"adjacent"`` both ways.

    Args:
        on_gap: largest vertical gap [m] still counted as resting on.
        adjacent_gap: largest horizontal gap [m] counted as adjacent; None: no adjacency.
        vertical: |normal_z| above which a contact is a support rather than a side contact.
    """
    edges: list[tuple[str, str, str]] = []
    limit = max(on_gap, adjacent_gap or 0.0)
    for i, a in enumerate(bodies):
        for b in bodies[i + 1 :]:
            gap, n = body_separation(a, b, cutoff=limit)
            if gap > limit:
                continue
            if abs(n[2]) >= vertical:
                if gap <= on_gap:
                    edges.append((a.id, b.id, "on") if n[2] > 0 else (b.id, a.id, "on"))
            elif adjacent_gap is not None and gap <= adjacent_gap:
                edges += [(a.id, b.id, "adjacent"), (b.id, a.id, "adjacent")]
    return edges


def resting_on(bodies: Sequence[Body], *, gap: float = TOLERANCES.contact) -> dict[str, set[str]]:
    """For every body, the ids of the bodies it rests on (the table is not listed)."""
    out: dict[str, set[str]] = {b.id: set() for b in bodies}
    for a, b, kind in contact_edges(bodies, on_gap=gap, adjacent_gap=None):
        if kind == "on":
            out[a].add(b)
    return out
