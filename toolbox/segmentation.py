"""Image segmentation: colour (HSV) and depth (height above a plane), masks and regions.

Design rule: masks are boolean (H, W) arrays aligned with the image; a `Region` is one
connected blob with its pixel statistics. Hue is in degrees [0, 360), saturation and value in
[0, 1] (not OpenCV's 0–180 / 0–255). Pixel coordinates are (u, v) = (column, row).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from toolbox._common import check_image
from toolbox.errors import ToolboxError
from toolbox.vision import depth_to_points, distance_to_plane

__all__ = [
    "Region",
    "clean_mask",
    "connected_components",
    "mask_contour",
    "mask_iou",
    "rgb_to_hsv",
    "segment_above_plane",
    "segment_colored_objects",
    "segment_hue",
]


@dataclass(frozen=True, kw_only=True)
class Region:
    """One connected image region.

    Attributes:
        mask: (H, W) bool.
        area: number of pixels.
        centroid: (u, v) mean pixel coordinate.
        bbox: (u_min, v_min, u_max, v_max) inclusive.
        mean_rgb: (3,) mean colour 0–255.
        hue: circular mean hue [deg] of its pixels.
    """

    mask: np.ndarray
    area: int
    centroid: tuple[float, float]
    bbox: tuple[int, int, int, int]
    mean_rgb: tuple[float, float, float]
    hue: float


def rgb_to_hsv(rgb: object) -> np.ndarray:
    """HSV image (H, W, 3) float32 from rgb (H, W, 3) uint8: hue [deg, 0–360), sat and val [0, 1]."""
    img = _rgb(rgb)
    hsv = cv2.cvtColor(img.astype(np.float32) / 255.0, cv2.COLOR_RGB2HSV)
    return hsv.astype(np.float32)


def segment_hue(
    rgb: object,
    hue_min: float,
    hue_max: float,
    *,
    sat_min: float = 0.3,
    val_min: float = 0.15,
) -> np.ndarray:
    """Mask (H, W) bool of pixels whose hue [deg] lies in [hue_min, hue_max].

    The range wraps through 0 when hue_min > hue_max (red: `segment_hue(rgb, 340, 20)`).
    Pixels below `sat_min` or `val_min` (greys, shadows) are excluded.
    """
    hsv = rgb_to_hsv(rgb)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    lo, hi = hue_min % 360.0, hue_max % 360.0
    in_hue = (h >= lo) & (h <= hi) if lo <= hi else (h >= lo) | (h <= hi)
    return in_hue & (s >= sat_min) & (v >= val_min)


def segment_colored_objects(
    rgb: object,
    *,
    mask: object = None,
    sat_min: float = 0.35,
    val_min: float = 0.15,
    hue_tolerance: float = 15.0,
    min_area: int = 50,
) -> list[Region]:
    """Find saturated-colour objects (e.g. coloured cubes on a grey table) by hue clustering.

    Pixels with saturation >= `sat_min` and value >= `val_min` are grouped by hue peaks (peaks
    closer than `hue_tolerance` [deg] merge), each hue group is split into connected
    components, and components smaller than `min_area` pixels are dropped.

    Args:
        rgb: (H, W, 3) uint8.
        mask: optional (H, W) bool limiting the search (e.g. pixels above the table).

    Returns:
        Regions sorted by decreasing area; empty when nothing is coloured. Two touching objects
        of the same hue come back as one region; grey, white or black objects are not found
        (use `segment_above_plane` for those).
    """
    hsv = rgb_to_hsv(rgb)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    colored = (s >= sat_min) & (v >= val_min)
    if mask is not None:
        colored &= check_image(mask, None, "mask", ndim=2).astype(bool)
    if not colored.any():
        return []
    peaks = _hue_peaks(h[colored], s[colored], hue_tolerance)
    diff = np.abs((h[colored][:, None] - peaks[None, :] + 180.0) % 360.0 - 180.0)  # (n, peaks)
    label = np.full(h.shape, -1)
    label[colored] = np.where(diff.min(axis=1) <= 2.0 * hue_tolerance, diff.argmin(axis=1), -1)
    regions: list[Region] = []
    for k in range(len(peaks)):
        for comp in connected_components(label == k, min_area=min_area):
            regions.append(_region(comp, rgb, h))
    regions.sort(key=lambda r: -r.area)
    return regions


def segment_above_plane(
    depth: object,
    camera: dict,
    plane: object,
    *,
    min_height: float = 0.005,
    max_height: float = np.inf,
) -> np.ndarray:
    """Mask (H, W) bool of pixels whose 3D point is between `min_height` and `max_height` [m]
    above the plane (a, b, c, d) (e.g. from `estimate_table_plane`); invalid depth is False."""
    D = check_image(depth, camera, "depth", ndim=2)
    pts, pix = depth_to_points(D, camera, return_pixels=True)
    height = distance_to_plane(pts, plane)
    keep = (height > min_height) & (height < max_height)
    out = np.zeros(D.shape, dtype=bool)
    out[pix[keep, 1], pix[keep, 0]] = True
    return out


def connected_components(mask: object, *, min_area: int = 1) -> list[np.ndarray]:
    """Split a bool mask (H, W) into 8-connected components of at least `min_area` pixels.

    Returns a list of bool masks (H, W), largest first.
    """
    m = check_image(mask, None, "mask", ndim=2).astype(np.uint8)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    order = [i for i in np.argsort(-stats[:, cv2.CC_STAT_AREA], kind="stable") if i != 0]
    return [labels == i for i in order if stats[i, cv2.CC_STAT_AREA] >= min_area]


def clean_mask(
    mask: object, *, open_px: int = 1, close_px: int = 1, fill_holes: bool = False
) -> np.ndarray:
    """Morphological clean-up of a bool mask (H, W): opening removes specks up to `open_px`
    pixels wide, closing bridges gaps up to `close_px`; `fill_holes` fills enclosed holes."""
    m: np.ndarray = check_image(mask, None, "mask", ndim=2).astype(np.uint8)
    if open_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * open_px + 1,) * 2)
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, k)
    if close_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * close_px + 1,) * 2)
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, k)
    if fill_holes:
        contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        m = cv2.drawContours(np.zeros_like(m), contours, -1, 1, thickness=cv2.FILLED)
    return m.astype(bool)


def mask_contour(mask: object) -> np.ndarray:
    """Outer boundary (N, 2) float (u, v) of the largest blob of a bool mask, in order around
    the blob (the centres of its boundary pixels); (0, 2) for an empty mask."""
    m = check_image(mask, None, "mask", ndim=2).astype(np.uint8)
    contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return np.zeros((0, 2))
    best = max(contours, key=cv2.contourArea)
    return best.reshape(-1, 2).astype(float)


def mask_iou(a: object, b: object) -> float:
    """Intersection over union of two bool masks of equal shape; 1.0 when both are empty."""
    A, B = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    if A.shape != B.shape:
        raise ToolboxError(f"mask shapes differ: {A.shape} vs {B.shape}")
    union = np.count_nonzero(A | B)
    return float(np.count_nonzero(A & B) / union) if union else 1.0


def _rgb(rgb: object) -> np.ndarray:
    img = check_image(rgb, None, "rgb", ndim=3)
    if img.shape[2] not in (3, 4):
        raise ToolboxError(f"rgb must have 3 channels, got shape {img.shape}")
    if img.dtype != np.uint8:
        raise ToolboxError(f"rgb must be uint8, got {img.dtype}")
    return img[..., :3]


def _hue_peaks(hue: np.ndarray, weight: np.ndarray, tolerance: float) -> np.ndarray:
    """Centres [deg] of the modes of a circular hue histogram, at least `tolerance` apart."""
    hist = np.bincount(hue.astype(int) % 360, weights=weight, minlength=360)
    width = max(1, round(tolerance / 3))
    kernel = np.exp(-0.5 * (np.arange(-3 * width, 3 * width + 1) / width) ** 2)
    smooth = np.convolve(np.r_[hist[-3 * width :], hist, hist[: 3 * width]], kernel, "valid")
    floor = 0.02 * smooth.max()
    peaks: list[int] = []
    for i in np.argsort(-smooth):
        if smooth[i] < floor:
            break
        if smooth[i] < smooth[(i - 1) % 360] or smooth[i] < smooth[(i + 1) % 360]:
            continue
        if all(abs((i - p + 180) % 360 - 180) >= tolerance for p in peaks):
            peaks.append(int(i))
    return np.asarray(peaks, dtype=float) + 0.5


def _region(mask: np.ndarray, rgb: object, hue: np.ndarray) -> Region:
    v, u = np.nonzero(mask)
    mean = _rgb(rgb)[mask].mean(axis=0)
    h = np.deg2rad(hue[mask])
    mean_hue = float(np.rad2deg(np.arctan2(np.sin(h).mean(), np.cos(h).mean())) % 360.0)
    return Region(
        mask=mask,
        area=len(u),
        centroid=(float(u.mean()), float(v.mean())),
        bbox=(int(u.min()), int(v.min()), int(u.max()), int(v.max())),
        mean_rgb=(float(mean[0]), float(mean[1]), float(mean[2])),
        hue=mean_hue,
    )
