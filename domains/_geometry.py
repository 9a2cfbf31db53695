"""Exact-enough rigid geometry for generators, planners and reference relations.

Objects are unions of convex parts (the collision parts listed in the catalogue). Distances
between convex parts come from the separating-axis theorem over face normals and edge-pair
cross products: exact for penetration depth, a lower bound for separations (exact for the
face-face and edge-edge contacts that matter here). Pure numpy, no simulator, so results do
not depend on a physics engine's contact tolerances.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import trimesh


@dataclass(frozen=True, kw_only=True)
class ConvexPart:
    """One convex piece of an object, in the object frame."""

    vertices: np.ndarray  # (n, 3) [m]
    normals: np.ndarray  # (f, 3) distinct face normals
    edges: np.ndarray  # (e, 3) distinct unit edge directions (feature edges only)
    radius: float  # bounding radius about `centre` [m]
    centre: np.ndarray  # (3,)

    @staticmethod
    def from_points(points: np.ndarray) -> ConvexPart:
        hull = trimesh.Trimesh(vertices=np.asarray(points, float)).convex_hull
        normals = _unique_directions(hull.face_normals, signed=True)
        sharp = hull.face_adjacency_angles > 1e-6
        ev = hull.vertices[hull.face_adjacency_edges[sharp]]  # (e, 2, 3)
        d = ev[:, 1] - ev[:, 0]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        verts = np.asarray(hull.vertices, float)
        centre = 0.5 * (verts.min(axis=0) + verts.max(axis=0))
        return ConvexPart(
            vertices=verts,
            normals=normals,
            edges=_unique_directions(d, signed=False),
            radius=float(np.linalg.norm(verts - centre, axis=1).max()),
            centre=centre,
        )

    def transformed(self, pose: np.ndarray) -> ConvexPart:
        r, t = pose[:3, :3], pose[:3, 3]
        return ConvexPart(
            vertices=self.vertices @ r.T + t,
            normals=self.normals @ r.T,
            edges=self.edges @ r.T,
            radius=self.radius,
            centre=r @ self.centre + t,
        )


def _unique_directions(d: np.ndarray, *, signed: bool) -> np.ndarray:
    d = np.asarray(d, float)
    if not signed:
        # a direction and its opposite give the same separating axis
        flip = (d[:, 0] < -1e-9) | ((np.abs(d[:, 0]) <= 1e-9) & (d[:, 1] < -1e-9))
        flip |= (np.abs(d[:, 0]) <= 1e-9) & (np.abs(d[:, 1]) <= 1e-9) & (d[:, 2] < 0)
        d = np.where(flip[:, None], -d, d)
    _, idx = np.unique(np.round(d, 6), axis=0, return_index=True)
    return d[np.sort(idx)]


def separation(a: ConvexPart, b: ConvexPart) -> tuple[float, np.ndarray]:
    """Signed separation of two world-frame convex parts and its direction.

    Returns:
        gap: distance [m] (negative: penetration depth).
        normal: (3,) unit vector pointing from `b` towards `a` along the separating axis.
    """
    cross = np.cross(a.edges[:, None, :], b.edges[None, :, :]).reshape(-1, 3)
    n = np.linalg.norm(cross, axis=1)
    cross = cross[n > 1e-6] / n[n > 1e-6, None]
    axes = np.concatenate([a.normals, b.normals, cross])
    pa = a.vertices @ axes.T  # (na, k)
    pb = b.vertices @ axes.T
    gap_pos = pa.min(axis=0) - pb.max(axis=0)  # a beyond b along +axis
    gap_neg = pb.min(axis=0) - pa.max(axis=0)
    gaps = np.maximum(gap_pos, gap_neg)
    i = int(np.argmax(gaps))
    sign = 1.0 if gap_pos[i] >= gap_neg[i] else -1.0
    return float(gaps[i]), sign * axes[i]


@dataclass(frozen=True, kw_only=True)
class Body:
    """An object placed in the world: its id and its convex parts in the world frame."""

    id: str
    parts: tuple[ConvexPart, ...]

    @property
    def lowest(self) -> float:
        return float(min(p.vertices[:, 2].min() for p in self.parts))

    @property
    def highest(self) -> float:
        return float(max(p.vertices[:, 2].max() for p in self.parts))

    def xy(self) -> np.ndarray:
        return np.concatenate([p.vertices[:, :2] for p in self.parts])


def place(object_id: str, parts: Sequence[ConvexPart], pose: np.ndarray) -> Body:
    """The body of `parts` (object frame) moved to `pose` (4, 4)."""
    pose = np.asarray(pose, float)
    return Body(id=object_id, parts=tuple(p.transformed(pose) for p in parts))


def body_separation(a: Body, b: Body, *, cutoff: float = np.inf) -> tuple[float, np.ndarray]:
    """Smallest part-to-part separation [m] between two bodies, with its direction (b → a).

    Pairs whose bounding spheres are farther apart than `cutoff` are skipped; if all are,
    the returned gap is a lower bound larger than `cutoff` and the normal is +z.
    """
    best, normal = np.inf, np.array([0.0, 0.0, 1.0])
    for pa in a.parts:
        for pb in b.parts:
            bound = np.linalg.norm(pa.centre - pb.centre) - pa.radius - pb.radius
            if bound > cutoff:
                best = min(best, float(bound))
                continue
            gap, n = separation(pa, pb)
            if gap < best - 1e-12:
                best, normal = gap, n
    return best, normal


def contact_edges(
    bodies: Sequence[Body],
    *,
    on_gap: float,
    adjacent_gap: float | None,
    vertical: float = 0.7,
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


def supports(bodies: Sequence[Body], *, on_gap: float = 0.002) -> dict[str, set[str]]:
    """For every body, the ids of the bodies it rests on (the table is not listed)."""
    out: dict[str, set[str]] = {b.id: set() for b in bodies}
    for a, b, kind in contact_edges(bodies, on_gap=on_gap, adjacent_gap=None):
        if kind == "on":
            out[a].add(b)
    return out


def resting_height(parts: Sequence[ConvexPart], rotation: np.ndarray) -> float:
    """z of the object origin [m] that puts the lowest point of the rotated object on z = 0."""
    return -float(min((p.vertices @ rotation.T)[:, 2].min() for p in parts))


def yaw_pose(
    x: float, y: float, z: float, yaw: float, base: np.ndarray | None = None
) -> np.ndarray:
    """Pose (4, 4) at (x, y, z) [m]: a rotation `yaw` [rad] about world z applied to `base`."""
    c, s = np.cos(yaw), np.sin(yaw)
    t = np.eye(4)
    t[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    if base is not None:
        t[:3, :3] = t[:3, :3] @ base[:3, :3]
    t[:3, 3] = (x, y, z)
    return t


def yaw_of(pose: np.ndarray) -> float:
    """Heading [rad] of the object's x axis projected on the table (for upright rotations)."""
    return float(np.arctan2(pose[1, 0], pose[0, 0]))


def bodies_of(
    records: Sequence[Mapping], parts_by_mesh: Mapping[str, Sequence[ConvexPart]]
) -> list[Body]:
    """World bodies of scene records ``{"id", "mesh", "pose"}``."""
    return [place(r["id"], parts_by_mesh[r["mesh"]], np.asarray(r["pose"], float)) for r in records]
