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
# [px] the depth error of a scored object is judged on at least this many pixels both sides
# show it with depth, else it fails: a render that draws its silhouettes without depth leaves
# nothing to judge. A scored object that keeps IOU_MIN shares 0.6 × MIN_AREA = 48 px or more.
DEPTH_MIN_PX = 20
# [px] the depth error is judged this far in from both silhouettes' outlines (where that
# leaves DEPTH_MIN_PX pixels): along an outline a correct renderer's depth may come from the
# neighbouring surface (a second pass, another rasteriser), which on a sliver of an object
# would decide the median
DEPTH_EDGE_PX = 1


@dataclass(frozen=True, kw_only=True)
class ObjectMatch:
    """One object's agreement between a candidate render and the reference."""

    id: str
    iou: float
    area_candidate: int  # [px]
    area_reference: int  # [px]
    depth_error_median: float | None  # [m]
    depth_pixels: int = 0  # [px] where both show it with depth: what the depth error is over

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
        inner = both & _eroded(ref & cand, DEPTH_EDGE_PX)
        judged = inner if int(inner.sum()) >= DEPTH_MIN_PX else both
        out.append(
            ObjectMatch(
                id=str(oid),
                iou=1.0 if union == 0 else float((ref & cand).sum()) / union,
                area_candidate=int(cand.sum()),
                area_reference=int(ref.sum()),
                depth_error_median=float(np.median(np.abs(cd[judged] - rd[judged])))
                if judged.any()
                else None,
                depth_pixels=int(both.sum()),
            )
        )
    return out


def _eroded(mask: np.ndarray, px: int) -> np.ndarray:
    """`mask` without the pixels within `px` (8-connected) of its outline."""
    from scipy.ndimage import binary_erosion

    return binary_erosion(mask, structure=np.ones((3, 3), bool), iterations=px)


def judge(
    matches: Sequence[ObjectMatch],
    *,
    min_area: int = MIN_AREA,
    iou_min: float = IOU_MIN,
    iou_mean_min: float = IOU_MEAN_MIN,
    depth_max: float = DEPTH_MEDIAN_MAX,
    depth_min_px: int = 0,
) -> list[str]:
    """What is wrong with a set of matches ([] when they pass), worst first.

    Args:
        depth_min_px: a scored object whose silhouette passes but whose depth error is over
            fewer pixels than this fails (`DEPTH_MIN_PX` where the candidate's depth is the
            draft's own output; 0: not required).
    """
    scored = [m for m in matches if m.area_reference >= min_area]
    problems = []
    for m in sorted(scored, key=lambda m: m.iou):
        if m.iou < iou_min:
            problems.append(
                f"'{m.id}': silhouette IoU {m.iou:.2f} < {iou_min} ({m.area_candidate} px rendered, "
                f"{m.area_reference} px in the reference)"
            )
    for m in scored:
        if m.iou >= iou_min and m.depth_pixels < depth_min_px:
            problems.append(
                f"'{m.id}': depth compared on only {m.depth_pixels} px where both show it (at "
                f"least {depth_min_px} needed): its pixels have no depth"
            )
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


def tint(rgb: np.ndarray, mask: np.ndarray, alpha: float = 0.55) -> np.ndarray:
    """`rgb` with each object index of `mask` (-1: none) tinted in its palette colour."""
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
        middle = tint(ref_rgb // 2 + 64, cand)
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


# -- feedback pictures: per-object tiles, plan states -----------------------------------------

TILE = 112  # [px] side of one object's tile
_BOTH, _REF_ONLY, _CAND_ONLY = (235, 235, 235), (220, 40, 40), (40, 90, 230)


def _text(img: np.ndarray, lines: Sequence[str], origin: tuple[int, int], scale: float = 0.36,
          colour: tuple[int, int, int] = (255, 255, 255)) -> None:  # fmt: skip
    """Draw ASCII lines of text into `img` (in place)."""
    import cv2

    x, y = origin
    for line in lines:
        safe = "".join(c if 32 <= ord(c) < 127 else "?" for c in line)
        cv2.putText(img, safe, (x, y), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv2.LINE_AA)
        y += int(30 * scale) + 2


def object_tiles(
    rgb: np.ndarray,
    reference_mask: np.ndarray,
    reference_ids: Sequence[str],
    candidate_mask: np.ndarray | None,
    candidate_ids: Sequence[str],
    rows: Sequence[Mapping[str, Any]],
    *,
    columns: int = 4,
) -> np.ndarray:
    """A grid of one tile per object (H, W, 3) uint8: the object's neighbourhood in the image,
    its reference silhouette against the candidate's (white both, red only the reference,
    blue only the candidate), a red frame when it is wrong, and text lines under it.

    Args:
        rows: per tile, in the order shown: {"id", "ok": bool, "lines": [str, ...]}.
    """
    ref = np.asarray(reference_mask)
    base = _resize_nearest(np.asarray(rgb, np.uint8), ref.shape).astype(np.float32) * 0.45
    cand = np.full(ref.shape, -1) if candidate_mask is None else np.asarray(candidate_mask)
    index_ref = {str(i): k for k, i in enumerate(reference_ids)}
    index_cand = {str(i): k for k, i in enumerate(candidate_ids)}
    label_h = 40
    tiles = []
    for row in rows:
        oid = str(row["id"])
        r = ref == index_ref[oid] if oid in index_ref else np.zeros(ref.shape, bool)
        c = cand == index_cand[oid] if oid in index_cand else np.zeros(ref.shape, bool)
        tile = np.full((TILE + label_h, TILE, 3), 30, np.uint8)
        both = r | c
        if both.any():
            vs, us = np.nonzero(both)
            cy, cx = (vs.min() + vs.max()) / 2, (us.min() + us.max()) / 2
            half = max(vs.max() - vs.min(), us.max() - us.min(), 24) / 2 + 6
            v0, v1 = int(cy - half), int(cy + half) + 1
            u0, u1 = int(cx - half), int(cx + half) + 1
            canvas = base.copy()
            canvas[r & c] = 0.4 * canvas[r & c] + 0.6 * np.array(_BOTH)
            canvas[r & ~c] = 0.3 * canvas[r & ~c] + 0.7 * np.array(_REF_ONLY)
            canvas[c & ~r] = 0.3 * canvas[c & ~r] + 0.7 * np.array(_CAND_ONLY)
            pad = np.zeros((v1 - v0, u1 - u0, 3), np.float32) + 30
            sv0, su0 = max(v0, 0), max(u0, 0)
            sv1, su1 = min(v1, ref.shape[0]), min(u1, ref.shape[1])
            pad[sv0 - v0 : sv1 - v0, su0 - u0 : su1 - u0] = canvas[sv0:sv1, su0:su1]
            tile[:TILE] = _resize_nearest(pad.clip(0, 255).astype(np.uint8), (TILE, TILE))
        else:
            _text(tile, ["not in view", "on either side"], (6, TILE // 2 - 6))
        frame = (60, 190, 90) if row.get("ok") else (230, 50, 50)
        tile[:2], tile[TILE - 2 : TILE], tile[:TILE, :2], tile[:TILE, -2:] = (frame,) * 4
        _text(tile, [str(row["id"])[:18], *[str(x)[:22] for x in row.get("lines", [])]],
              (4, TILE + 11), scale=0.33)  # fmt: skip
        tiles.append(tile)
    if not tiles:
        return np.full((TILE, TILE, 3), 30, np.uint8)
    columns = max(1, min(columns, len(tiles)))
    while len(tiles) % columns:
        tiles.append(np.full_like(tiles[0], 20))
    sep_v = np.full((tiles[0].shape[0], 3, 3), 255, np.uint8)
    lines = []
    for i in range(0, len(tiles), columns):
        parts = []
        for t in tiles[i : i + columns]:
            parts += [t, sep_v]
        lines.append(np.concatenate(parts[:-1], axis=1))
        lines.append(np.full((3, lines[-1].shape[1], 3), 255, np.uint8))
    return np.concatenate(lines[:-1], axis=0)


# Plan states: every object as the convex hulls of its pieces, seen from above (x up, y to the
# left, as the robot faces the table) and from behind the robot (z up, the same left-right).
_ROLE_COLOURS = {
    "other": (150, 150, 150),
    "moved": (60, 120, 235),
    "blocker": (225, 55, 55),
    "goal": (60, 200, 90),
}


def state_views(
    objects: Sequence[Mapping[str, Any]],
    *,
    boxes: Sequence[Mapping[str, Any]] = (),
    title: str = "",
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    size: int = 260,
) -> np.ndarray:
    """Two panels (H, 2W, 3) uint8: the top view and the view from behind the robot.

    Args:
        objects: {"id", "pieces": [(n, 3) world vertices], "role": "other" | "moved" |
            "blocker" | "goal" (drawn as an outline)}, in any order.
        boxes: gripper parts {"corners": (8, 3) world, "hit": bool}: outlined, filled when hit.
        bounds: (lo (3,), hi (3,)) world box to show; default: everything drawn, padded.
    """
    import cv2

    pts = [p for o in objects for p in o["pieces"]] + [b["corners"] for b in boxes]
    allp = np.concatenate([np.asarray(p, float).reshape(-1, 3) for p in pts]) if pts else None
    if bounds is None:
        lo = allp.min(axis=0) - 0.03 if allp is not None else np.array([0.3, -0.2, 0.0])
        hi = allp.max(axis=0) + 0.03 if allp is not None else np.array([0.7, 0.2, 0.2])
        lo[2] = min(lo[2], 0.0)
    else:
        lo, hi = (np.asarray(b, float) for b in bounds)
    span = max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-3)
    scale = (size - 20) / span  # [px / m]

    def top(p: np.ndarray) -> np.ndarray:  # (n, 3) → (n, 2) px: column −y, row −x
        return np.c_[10 + (hi[1] - p[:, 1]) * scale, 10 + (hi[0] - p[:, 0]) * scale]

    def side(p: np.ndarray) -> np.ndarray:  # column −y, row −z
        return np.c_[10 + (hi[1] - p[:, 1]) * scale, size - 10 - (p[:, 2] - lo[2]) * scale]

    panels = []
    for project, depth in ((top, lambda p: p[:, 2].max()), (side, lambda p: -p[:, 0].min())):
        img = np.full((size, size, 3), 245, np.uint8)
        if project is side:  # the table top
            y0 = int(size - 10 - (0.0 - lo[2]) * scale)
            img[max(0, y0) :, :] = (225, 215, 195)
        order = sorted(
            ((depth(np.asarray(p, float).reshape(-1, 3)), k, p, o) for k, o in enumerate(objects)
             for p in o["pieces"]),
            key=lambda t: (t[0], t[1]),
        )  # fmt: skip
        for _, _, piece, o in order:
            hull = cv2.convexHull(project(np.asarray(piece, float)).astype(np.int32))
            colour = _ROLE_COLOURS.get(o.get("role", "other"), _ROLE_COLOURS["other"])
            if o.get("role") == "goal":
                cv2.polylines(img, [hull], True, colour, 2, cv2.LINE_AA)
            else:
                cv2.fillConvexPoly(img, hull, colour, cv2.LINE_AA)
                cv2.polylines(img, [hull], True, (40, 40, 40), 1, cv2.LINE_AA)
        for o in objects:  # the moved object stays visible behind others
            if o.get("role") == "moved":
                for piece in o["pieces"]:
                    hull = cv2.convexHull(project(np.asarray(piece, float)).astype(np.int32))
                    cv2.polylines(img, [hull], True, _ROLE_COLOURS["moved"], 2, cv2.LINE_AA)
        for b in boxes:
            hull = cv2.convexHull(project(np.asarray(b["corners"], float)).astype(np.int32))
            if b.get("hit"):
                cv2.fillConvexPoly(img, hull, (250, 160, 30), cv2.LINE_AA)
            cv2.polylines(img, [hull], True, (200, 150, 0), 1, cv2.LINE_AA)
        if project is top:
            for o in objects:
                if o.get("role") == "goal" or not o["pieces"]:
                    continue
                c = project(np.concatenate([np.asarray(p, float) for p in o["pieces"]])).mean(0)
                _text(img, [str(o["id"])[:12]], (int(c[0]) - 12, int(c[1]) + 4), 0.32, (0, 0, 0))
        _text(img, ["from above" if project is top else "from behind the robot"], (6, 14), 0.35,
              (0, 0, 0))  # fmt: skip
        panels.append(img)
    sep = np.full((size, 3, 3), 255, np.uint8)
    out = np.concatenate([panels[0], sep, panels[1]], axis=1)
    if title:
        strip = np.full((18, out.shape[1], 3), 255, np.uint8)
        _text(strip, [title[:90]], (4, 13), 0.38, (0, 0, 0))
        out = np.concatenate([strip, out], axis=0)
    return out


def stack_rows(rows: Sequence[np.ndarray]) -> np.ndarray:
    """Images (h_i, w_i, 3) one under another, padded white to the widest."""
    width = max(r.shape[1] for r in rows)
    out = []
    for r in rows:
        pad = np.full((r.shape[0], width - r.shape[1], 3), 255, np.uint8)
        out += [np.concatenate([r, pad], axis=1), np.full((4, width, 3), 255, np.uint8)]
    return np.concatenate(out[:-1], axis=0)
