"""Image comparison for the image checks: per-object silhouette IoU and depth error, overlays.

Design rule: pure numpy on arrays (no simulator; `write_png` is the one function that writes,
and only under the folder it is given). Two renders of the same objects are
compared object by object, matched by record id (each side's mask holds indices into its own
id list). The overlay is an RGB array people read in reports and the model receives: the
reference image, the candidate's silhouettes over it, and where the silhouettes disagree.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

MIN_AREA = 80  # [px] objects the reference shows smaller than this are not scored
IOU_MIN = 0.6  # per object
IOU_MEAN_MIN = 0.8  # over the scored objects
DEPTH_MEDIAN_MAX = 0.006  # [m] per object, on pixels both sides show it


@dataclass(frozen=True, kw_only=True)
class ObjectMatch:
    """One object's agreement between a candidate render and the reference."""

    id: str
    iou: float
    area_candidate: int  # [px]
    area_reference: int  # [px]
    depth_error_median: float | None  # [m]

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "iou": round(self.iou, 4),
            "area_candidate": self.area_candidate,
            "area_reference": self.area_reference,
            "depth_error_median_m": None
            if self.depth_error_median is None
            else round(self.depth_error_median, 5),
        }


def compare(
    candidate: Mapping[str, np.ndarray],
    candidate_ids: Sequence[str],
    reference: Mapping[str, np.ndarray],
    reference_ids: Sequence[str],
) -> list[ObjectMatch]:
    """Per-object matches for every id of the reference, in reference order.

    Args:
        candidate, reference: {"mask": (H, W) int index into the ids (-1 none), "depth": (H, W)}.
    """
    cm, rm = np.asarray(candidate["mask"]), np.asarray(reference["mask"])
    cd, rd = np.asarray(candidate["depth"], float), np.asarray(reference["depth"], float)
    if cm.shape != rm.shape or cd.shape != rm.shape or rd.shape != rm.shape:
        raise ValueError(
            f"image shapes differ: mask {cm.shape}, depth {cd.shape} vs the reference's {rm.shape}"
        )
    index = {str(i): k for k, i in enumerate(candidate_ids)}
    out = []
    for k, oid in enumerate(reference_ids):
        ref = rm == k
        cand = cm == index[oid] if oid in index else np.zeros_like(ref)
        union = int((ref | cand).sum())
        both = ref & cand & (rd > 0) & (cd > 0)
        out.append(
            ObjectMatch(
                id=str(oid),
                iou=1.0 if union == 0 else float((ref & cand).sum()) / union,
                area_candidate=int(cand.sum()),
                area_reference=int(ref.sum()),
                depth_error_median=float(np.median(np.abs(cd[both] - rd[both])))
                if both.any()
                else None,
            )
        )
    return out


def judge(
    matches: Sequence[ObjectMatch],
    *,
    min_area: int = MIN_AREA,
    iou_min: float = IOU_MIN,
    iou_mean_min: float = IOU_MEAN_MIN,
    depth_max: float = DEPTH_MEDIAN_MAX,
) -> list[str]:
    """What is wrong with a set of matches ([] when they pass), worst first."""
    scored = [m for m in matches if m.area_reference >= min_area]
    problems = []
    for m in sorted(scored, key=lambda m: m.iou):
        if m.iou < iou_min:
            problems.append(
                f"'{m.id}': silhouette IoU {m.iou:.2f} < {iou_min} ({m.area_candidate} px rendered, "
                f"{m.area_reference} px in the reference)"
            )
    for m in scored:
        if m.depth_error_median is not None and m.depth_error_median > depth_max:
            problems.append(
                f"'{m.id}': median depth error {1000 * m.depth_error_median:.1f} mm > "
                f"{1000 * depth_max:.0f} mm where both show it"
            )
    if scored:
        mean = float(np.mean([m.iou for m in scored]))
        if mean < iou_mean_min:
            problems.append(f"mean silhouette IoU {mean:.2f} < {iou_mean_min}")
    return problems


def summary(matches: Sequence[ObjectMatch], *, min_area: int = MIN_AREA) -> dict[str, float | None]:
    """Metrics for the report: min/mean IoU and worst median depth error of scored objects."""
    scored = [m for m in matches if m.area_reference >= min_area]
    depths = [m.depth_error_median for m in scored if m.depth_error_median is not None]
    return {
        "iou_min": min((m.iou for m in scored), default=None),
        "iou_mean": float(np.mean([m.iou for m in scored])) if scored else None,
        "depth_error_median_max_m": max(depths, default=None),
        "objects_scored": float(len(scored)),
    }


_PALETTE = np.array(
    [
        [230, 25, 75],
        [60, 180, 75],
        [255, 225, 25],
        [0, 130, 200],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
        [210, 245, 60],
        [250, 190, 212],
    ],
    dtype=np.float32,
)


def _tint(rgb: np.ndarray, mask: np.ndarray, alpha: float = 0.55) -> np.ndarray:
    out = rgb.astype(np.float32).copy()
    for k in np.unique(mask):
        if k < 0:
            continue
        sel = mask == k
        out[sel] = (1 - alpha) * out[sel] + alpha * _PALETTE[int(k) % len(_PALETTE)]
    return out.clip(0, 255).astype(np.uint8)


def _resize_nearest(a: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    h, w = shape
    rows = (np.arange(h) * a.shape[0] / h).astype(int)
    cols = (np.arange(w) * a.shape[1] / w).astype(int)
    return a[rows][:, cols]


def overlay(
    reference_rgb: np.ndarray,
    reference_mask: np.ndarray,
    candidate_rgb: np.ndarray | None,
    candidate_mask: np.ndarray,
    candidate_ids: Sequence[str],
    reference_ids: Sequence[str],
) -> np.ndarray:
    """Three panels side by side (H, 3W, 3) uint8: the reference image; the candidate (its own
    image, or its silhouettes tinted over the reference); the disagreement — white where both
    show the same object, red where only the reference does, blue where only the candidate
    does, yellow where both show different objects."""
    shape = reference_mask.shape
    ref_rgb = _resize_nearest(np.asarray(reference_rgb, np.uint8), shape)
    index = {str(i): k for k, i in enumerate(reference_ids)}
    # candidate indices → reference indices, so both panels use the same colour per object
    lut = np.array([index.get(str(i), -2) for i in candidate_ids] + [-1], dtype=int)
    cm = np.asarray(candidate_mask)
    cand = np.where(cm >= 0, lut[np.clip(cm, 0, len(candidate_ids))], -1)
    if candidate_rgb is not None:
        middle = _resize_nearest(np.asarray(candidate_rgb, np.uint8), shape)
    else:
        middle = _tint(ref_rgb // 2 + 64, cand)
    diff = np.full((*shape, 3), 40, np.uint8)
    ref = np.asarray(reference_mask)
    diff[(ref >= 0) & (ref == cand)] = (235, 235, 235)
    diff[(ref >= 0) & (cand == -1)] = (220, 40, 40)
    diff[(ref == -1) & (cand != -1)] = (40, 90, 230)
    diff[(ref >= 0) & (cand != -1) & (ref != cand)] = (240, 210, 40)
    sep = np.full((shape[0], 4, 3), 255, np.uint8)
    return np.concatenate([ref_rgb, sep, middle, sep, diff], axis=1)


def write_png(out_dir: Any, name: str, rgb: np.ndarray, caption: str) -> list[dict[str, str]]:
    """Write an overlay PNG under `out_dir` (nothing without one); its image entry for a check.

    The name is reduced to letters, digits, '-' and '_': paths in a report always point into
    the folder the checks were given.
    """
    if out_dir is None:
        return []
    import cv2

    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{safe_name(name)}.png"
    cv2.imwrite(str(path), cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))
    return [{"path": str(path), "caption": caption}]


def safe_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)[:120]
