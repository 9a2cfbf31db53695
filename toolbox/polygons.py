"""2D shape fitting: rectangles, polygon approximation, and known-polygon pose fitting.

Design rule: 2D points are (N, 2) arrays in one metric plane frame [m] — typically world x, y
of table-top pixels from `pixels_to_plane(mask_contour(mask), camera)[:, :2]` — or pixels when
stated. Angles are counter-clockwise [rad] about the plane normal (world +z for x, y). A
polygon's pose (x, y, angle) maps its template vertices v to `R(angle) @ v + (x, y)`; with
rotational symmetry of order n the angle is reported in [0, 2π/n).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from toolbox.errors import ToolboxError

__all__ = [
    "PolygonFit",
    "Rectangle",
    "approximate_polygon",
    "fit_polygon_pose",
    "fit_rectangle",
    "polygon_symmetry",
]


@dataclass(frozen=True, kw_only=True)
class Rectangle:
    """Minimum-area rectangle: `center` (2,), `size` (long side, short side), and `angle` [rad,
    in [0, π)] of the long side from the +x axis (a rectangle is symmetric under π)."""

    center: tuple[float, float]
    size: tuple[float, float]
    angle: float


@dataclass(frozen=True, kw_only=True)
class PolygonFit:
    """Pose of a known polygon fitted to an observed outline.

    Attributes:
        x, y: position of the template's origin in the plane [m].
        angle: rotation [rad] in [0, 2π/symmetry).
        mirrored: True when the flipped template (y → -y, applied before rotating) fits best.
        rmse: root-mean-square outline distance [same unit as the input].
        iou: area overlap in [0, 1] of the posed template and the observed outline.
    """

    x: float
    y: float
    angle: float
    mirrored: bool
    rmse: float
    iou: float


def fit_rectangle(points: object) -> Rectangle:
    """Minimum-area rectangle around 2D points (N, 2) (N >= 3), or around a bool mask (H, W),
    in which case the result is in pixels (u, v) and the angle is measured towards +v.

    Raises ToolboxError for fewer than 3 points or an empty mask.
    """
    P = _points_or_mask(points)
    if len(P) < 3:
        raise ToolboxError(f"need at least 3 points to fit a rectangle, got {len(P)}")
    (cx, cy), (w, h), deg = cv2.minAreaRect(P.astype(np.float32))
    angle = np.deg2rad(deg)
    if h > w:
        w, h, angle = h, w, angle + np.pi / 2
    return Rectangle(
        center=(float(cx), float(cy)), size=(float(w), float(h)), angle=float(angle % np.pi)
    )


def approximate_polygon(contour: object, tolerance: float) -> np.ndarray:
    """Simplify a closed outline (N, 2) into polygon vertices (M, 2) (Douglas–Peucker): every
    outline point stays within `tolerance` (same unit) of the polygon."""
    C = _points(contour, "contour")
    approx = cv2.approxPolyDP(C.astype(np.float32).reshape(-1, 1, 2), float(tolerance), True)
    return approx.reshape(-1, 2).astype(float)


def polygon_symmetry(vertices: object, *, tolerance: float = 1e-3) -> int:
    """Order n of the polygon's rotational symmetry about its centroid (1 = none, 4 = square).

    `tolerance` is relative to the polygon size. Mirror symmetry is not counted.
    """
    V = _points(vertices, "vertices")
    c = _area_centroid(V)
    Q = V - c
    scale = np.max(np.linalg.norm(Q, axis=1))
    for n in range(len(V), 1, -1):
        if len(V) % n:
            continue
        R = _rot(2 * np.pi / n)
        moved = Q @ R.T
        d = np.linalg.norm(moved[:, None, :] - Q[None, :, :], axis=2).min(axis=1)
        if np.all(d <= tolerance * scale):
            return n
    return 1


def fit_polygon_pose(
    template: object,
    outline: object,
    *,
    symmetry: int | None = None,
    allow_mirror: bool = False,
    n_starts: int = 24,
) -> PolygonFit:
    """Fit a known polygon (e.g. a tangram piece) to the observed outline of its region.

    Args:
        template: polygon vertices (M, 2) in the piece's own frame [m], in order.
        outline: observed boundary points (N, 2) in the plane frame [m], in order around the
            region (e.g. `mask_contour` pixels mapped with `pixels_to_plane`). N >= 3.
        symmetry: rotational symmetry order; None detects it with `polygon_symmetry`.
        allow_mirror: also try the flipped template (for chiral pieces that may lie upside
            down, like the tangram parallelogram).
        n_starts: initial angles tried within one symmetry period.

    For a flat piece lying on the table, map the outline onto the plane of its top face,
    `pixels_to_plane(mask_contour(mask), camera, (0, 0, 1, -thickness))[:, :2]`; if
    `template` is the piece's outline in its object frame (z up), its record pose is
    `pose_from_xyz_yaw(fit.x, fit.y, z, fit.angle)` (mirrored: that pose @ a rotation of π
    about the object's x axis; its z axis then points down, so a frame origin on the bottom
    face goes to z = thickness).

    Returns:
        PolygonFit. Accuracy is sub-degree for outlines of a few hundred pixels; the fit
        minimises the two-sided distance between the outlines, so a uniform half-pixel
        shrinkage of the mask does not bias the pose. A low `iou` (< 0.8) means the region
        is not this polygon (merged with a neighbour, occluded, wrong piece).

    Raises:
        ToolboxError: fewer than 3 template vertices or outline points.
    """
    V = _points(template, "template")
    C = _points(outline, "outline")
    if len(V) < 3 or len(C) < 3:
        raise ToolboxError(
            f"need >= 3 template vertices and outline points, got {len(V)}, {len(C)}"
        )
    n = symmetry or polygon_symmetry(V)
    if n < 1:
        raise ToolboxError(f"symmetry must be >= 1, got {n}")
    if len(C) > 240:
        C = C[np.linspace(0, len(C), 240, endpoint=False).astype(int)]
    period = 2 * np.pi / n
    best: tuple[np.ndarray, float, bool] | None = None
    for mirrored in (False, True) if allow_mirror else (False,):
        T = V * [1.0, -1.0] if mirrored else V
        fit = _fit_one(T, C, period, n_starts)
        # A mirrored fit must be clearly better: for mirror-symmetric pieces both fit equally.
        if best is None or fit[1] < 0.9 * best[1]:
            best = (*fit, mirrored)
    assert best is not None  # at least the plain template was fitted
    (x, y, angle), rmse, mirrored = best
    T = V * [1.0, -1.0] if mirrored else V
    posed = T @ _rot(angle).T + [x, y]
    return PolygonFit(
        x=float(x),
        y=float(y),
        angle=float(angle % period),
        mirrored=mirrored,
        rmse=float(rmse),
        iou=_polygon_iou(posed, C),
    )


def _fit_one(
    T: np.ndarray, C: np.ndarray, period: float, n_starts: int
) -> tuple[np.ndarray, float]:
    """Best ((x, y, angle), rmse) of template T against outline C."""
    samples = _sample_boundary(T, 120)
    c_t, c_o = _area_centroid(T), _area_centroid(C)

    def residuals(p):
        R = _rot(p[2])
        posed_vertices = T @ R.T + p[:2]
        posed_samples = samples @ R.T + p[:2]
        return np.r_[
            _distance_to_polyline(C, posed_vertices), _distance_to_polyline(posed_samples, C)
        ]

    starts = []
    for a in np.linspace(0.0, period, int(n_starts), endpoint=False):
        t = c_o - _rot(a) @ c_t
        p = np.array([t[0], t[1], a])
        starts.append((float(np.mean(residuals(p) ** 2)), p))
    starts.sort(key=lambda s: s[0])
    best: tuple[np.ndarray, float] | None = None
    for _, p0 in starts[:3]:
        sol = least_squares(residuals, p0, method="lm", x_scale="jac")
        rmse = float(np.sqrt(np.mean(sol.fun**2)))
        if best is None or rmse < best[1]:
            best = (sol.x, rmse)
    assert best is not None  # starts is never empty
    return best


def _distance_to_polyline(P: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Distance (N,) from points P (N, 2) to the closed polygon boundary V (M, 2)."""
    A, B = V, np.roll(V, -1, axis=0)
    AB = B - A  # (M, 2)
    AP = P[:, None, :] - A[None, :, :]  # (N, M, 2)
    t = np.clip(
        np.einsum("nmk,mk->nm", AP, AB) / np.maximum(np.einsum("mk,mk->m", AB, AB), 1e-18), 0, 1
    )
    d = AP - t[..., None] * AB[None]
    return np.sqrt(np.min(np.einsum("nmk,nmk->nm", d, d), axis=1))


def _sample_boundary(V: np.ndarray, n: int) -> np.ndarray:
    """n points evenly spaced along the closed polygon V."""
    B = np.roll(V, -1, axis=0)
    lengths = np.linalg.norm(B - V, axis=1)
    s = np.linspace(0.0, lengths.sum(), n, endpoint=False)
    edge = np.minimum(np.searchsorted(np.cumsum(lengths), s, side="right"), len(V) - 1)
    start = np.r_[0.0, np.cumsum(lengths)[:-1]][edge]
    frac = (s - start) / np.maximum(lengths[edge], 1e-18)
    return V[edge] + frac[:, None] * (B[edge] - V[edge])


def _area_centroid(V: np.ndarray) -> np.ndarray:
    x, y = V[:, 0], V[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2.0
    if abs(area) < 1e-18:
        return V.mean(axis=0)
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)


def _polygon_iou(A: np.ndarray, B: np.ndarray, resolution: int = 512) -> float:
    """IoU of two polygons by rasterising both on a common grid."""
    lo = np.minimum(A.min(axis=0), B.min(axis=0))
    span = float(np.max(np.maximum(A.max(axis=0), B.max(axis=0)) - lo))
    if span <= 0:
        return 0.0
    scale = (resolution - 1) / span
    masks = []
    for P in (A, B):
        m = np.zeros((resolution, resolution), np.uint8)
        cv2.fillPoly(m, [np.round((P - lo) * scale * 16).astype(np.int32)], 1, shift=4)
        masks.append(m.astype(bool))
    union = np.count_nonzero(masks[0] | masks[1])
    return float(np.count_nonzero(masks[0] & masks[1]) / union) if union else 0.0


def _rot(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s], [s, c]])


def _points(P: object, name: str) -> np.ndarray:
    A = np.asarray(P, dtype=float)
    if A.ndim != 2 or A.shape[1] != 2 or not np.all(np.isfinite(A)):
        raise ToolboxError(f"{name} must be a finite (N, 2) array, got shape {A.shape}")
    return A


def _points_or_mask(P: object) -> np.ndarray:
    A = np.asarray(P)
    if A.dtype == bool:
        if A.ndim != 2:
            raise ToolboxError(f"mask must be (H, W), got shape {A.shape}")
        v, u = np.nonzero(A)
        return np.stack([u, v], axis=1).astype(float)
    return _points(A, "points")
