"""Rigid shapes as convex pieces: decomposition of a mesh, mass properties, resting poses.

Design rule: a `Shape` is an object's geometry in its own frame — convex pieces whose union is
the object, uniform density — made from a domain's collision parts (`Shape.from_pieces`) or
from a watertight mesh (`Shape.from_mesh`, exact for extruded profiles). Posed pieces are
cached per pose: planners ask about the same poses again and again.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from geometry.convex import DegenerateError, Piece
from geometry.planar import inside_margin


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
            raise DegenerateError("a Shape needs at least one convex piece")
        self._pieces = [Piece.of(p) for p in pieces]
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
            raise DegenerateError("Shape.from_mesh needs a closed mesh with volume")
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
        margin = inside_margin(flat[:, :2], c[:2])
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
