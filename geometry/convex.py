"""Convex pieces and the bodies made of them: separating-axis distances, placement helpers.

Design rule: exact polyhedral geometry, pure numpy/scipy. An object is the union of convex
pieces (a domain's collision parts, or a mesh's decomposition, `geometry.shape`). Distances
between pieces come from the separating-axis theorem over face normals and edge-pair cross
products: exact for penetration depth, a lower bound for separations (exact for the face-face
and edge-edge contacts that matter here). The table is the plane z = 0.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from contracts import se3


class DegenerateError(ValueError):
    """A convex piece is flat or has fewer than four points."""


@dataclass(frozen=True)
class Piece:
    """One convex piece of an object (object or world frame)."""

    vertices: np.ndarray  # (n, 3) [m]
    normals: np.ndarray  # (f, 3) distinct outward face normals
    edges: np.ndarray  # (e, 3) distinct unit edge directions (up to sign)
    centre: np.ndarray  # (3,) bounding-sphere centre
    radius: float  # [m]
    volume: float  # [m³]
    centroid: np.ndarray  # (3,) for uniform density

    @staticmethod
    def of(points: object) -> Piece:
        """The convex hull of points (n, 3) [m] as a piece."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        try:
            hull = ConvexHull(pts)
        except (QhullError, ValueError) as err:
            raise DegenerateError(
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
        return Piece(
            vertices=verts,
            normals=_distinct(hull.equations[:, :3], signed=True),
            edges=_distinct(e, signed=False),
            centre=centre,
            radius=float(np.linalg.norm(verts - centre, axis=1).max()),
            volume=float(hull.volume),
            centroid=centroid,
        )

    def posed(self, T: np.ndarray) -> Piece:
        """The piece moved by the pose T (4, 4)."""
        R, t = T[:3, :3], T[:3, 3]
        return Piece(
            vertices=self.vertices @ R.T + t,
            normals=self.normals @ R.T,
            edges=self.edges @ R.T,
            centre=self.centre @ R.T + t,
            radius=self.radius,
            volume=self.volume,
            centroid=self.centroid @ R.T + t,
        )


def _distinct(d: np.ndarray, *, signed: bool) -> np.ndarray:
    d = np.asarray(d, dtype=float).reshape(-1, 3)
    if len(d) == 0:
        return d
    if not signed:  # ±d is one axis: make the first non-zero coordinate positive
        key = np.round(d, 6) @ np.array([1e6, 1e3, 1.0])
        d = np.where((key < 0)[:, None], -d, d)
    _, idx = np.unique(np.round(d, 6), axis=0, return_index=True)
    return d[np.sort(idx)]


def piece_gap(a: Piece, b: Piece) -> tuple[float, np.ndarray]:
    """Signed separation [m] of two world-frame pieces (negative: penetration depth) and its
    unit axis, pointing from `b` towards `a`."""
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


@dataclass(frozen=True, kw_only=True)
class Body:
    """An object placed in the world: its id and its convex pieces in the world frame."""

    id: str
    pieces: tuple[Piece, ...]

    @property
    def lowest(self) -> float:
        return float(min(p.vertices[:, 2].min() for p in self.pieces))

    @property
    def highest(self) -> float:
        return float(max(p.vertices[:, 2].max() for p in self.pieces))

    @property
    def vertices(self) -> np.ndarray:
        return np.concatenate([p.vertices for p in self.pieces])

    @property
    def com(self) -> np.ndarray:
        """Centre of mass (3,) for uniform density [m]."""
        vols = np.array([p.volume for p in self.pieces])
        return (vols[:, None] * [p.centroid for p in self.pieces]).sum(axis=0) / max(
            vols.sum(), 1e-18
        )

    def xy(self) -> np.ndarray:
        return np.concatenate([p.vertices[:, :2] for p in self.pieces])


def place(object_id: str, pieces: Sequence[Piece], pose: object) -> Body:
    """The body of `pieces` (object frame) moved to `pose` (4, 4)."""
    T = np.asarray(pose, float)
    return Body(id=object_id, pieces=tuple(p.posed(T) for p in pieces))


def body_separation(a: Body, b: Body, *, cutoff: float = np.inf) -> tuple[float, np.ndarray]:
    """Smallest piece-to-piece separation [m] between two bodies, with its axis (b → a).

    Pairs whose bounding spheres are farther apart than `cutoff` are skipped; if all are,
    the returned gap is a lower bound larger than `cutoff` and the axis is +z.
    """
    best, axis = np.inf, np.array([0.0, 0.0, 1.0])
    for pa in a.pieces:
        for pb in b.pieces:
            bound = float(np.linalg.norm(pa.centre - pb.centre)) - pa.radius - pb.radius
            if bound > cutoff:
                best = min(best, bound)
                continue
            gap, n = piece_gap(pa, pb)
            if gap < best - 1e-12:
                best, axis = gap, n
    return best, axis


def bodies_of(
    records: Sequence[Mapping], pieces_by_mesh: Mapping[str, Sequence[Piece]]
) -> list[Body]:
    """World bodies of records ``{"id", "mesh", "pose"}``."""
    return [place(r["id"], pieces_by_mesh[r["mesh"]], r["pose"]) for r in records]


def resting_height(pieces: Sequence[Piece], rotation: np.ndarray) -> float:
    """z of the object origin [m] that puts the lowest point of the rotated object on z = 0."""
    return -float(min((p.vertices @ rotation.T)[:, 2].min() for p in pieces))


def yaw_pose(
    x: float, y: float, z: float, yaw: float, base: np.ndarray | None = None
) -> np.ndarray:
    """Pose (4, 4) at (x, y, z) [m]: a rotation `yaw` [rad] about world z applied to `base`."""
    t = se3.rot_z(yaw)
    if base is not None:
        t[:3, :3] = t[:3, :3] @ base[:3, :3]
    t[:3, 3] = (x, y, z)
    return t


def yaw_of(pose: np.ndarray) -> float:
    """Heading [rad] of the object's x axis projected on the table (for upright rotations)."""
    return se3.yaw(pose)
