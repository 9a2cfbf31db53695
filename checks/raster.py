"""Where two correct rasterisers may disagree, and where they may not: the edge band.

Design rule: two renderers drawing the same triangles with the same camera agree everywhere but
along silhouettes, where pixel-centre conventions (half a pixel), multisample resolves and
separate passes for colour, depth and mask each decide a pixel's owner differently. So the
checks that compare images pixel by pixel leave out the pixels within `band` pixels of a
silhouette edge (the edge band) and judge the rest exactly: a render shifted by two pixels or
more, mirrored or wrongly scaled puts whole strips of pixels beyond the band, a correct one
none. Pure numpy on (H, W) integer masks (-1 background, else an object index).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


def _shifts(a: np.ndarray) -> list[np.ndarray]:
    """The 8 neighbours of every pixel (edge-replicated at the border), one array each."""
    p = np.pad(a, 1, mode="edge")
    h, w = a.shape
    return [
        p[1 + dv : 1 + dv + h, 1 + du : 1 + du + w]
        for dv in (-1, 0, 1)
        for du in (-1, 0, 1)
        if dv or du
    ]


def dilate(sil: np.ndarray, band: int) -> np.ndarray:
    """`sil` (bool) grown by `band` pixels (8-connected: a (2 band + 1)² square)."""
    out = np.asarray(sil, bool)
    for _ in range(int(band)):
        grown = out.copy()
        for s in _shifts(out):
            grown |= s
        out = grown
    return out


def erode(sil: np.ndarray, band: int) -> np.ndarray:
    """`sil` (bool) shrunk by `band` pixels (the image border does not erode)."""
    return ~dilate(~np.asarray(sil, bool), band)


def edge_band(mask: np.ndarray, band: int) -> np.ndarray:
    """Pixels (bool (H, W)) within `band` pixels of a silhouette edge: of a pixel whose mask
    value (object index or background) differs from their own."""
    m = np.asarray(mask)
    if band <= 0 or m.size == 0:
        return np.zeros(m.shape, bool)
    edge = np.zeros(m.shape, bool)
    for s in _shifts(m):
        edge |= s != m
    return dilate(edge, band - 1)


@dataclass(frozen=True, kw_only=True)
class OutlineMatch:
    """How far one object's candidate silhouette strays from its reference silhouette."""

    id: str
    beyond: int  # [px] disagreeing pixels farther than the band from the reference's edge
    outline: int  # [px] length of the reference silhouette's edge (its boundary pixels)
    area_reference: int  # [px]

    @property
    def share(self) -> float:
        """`beyond` per pixel of the reference outline (a 2 px shift: ~0.2 to 1)."""
        return self.beyond / max(self.outline, 1)

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "pixels_beyond_edge_band": self.beyond,
            "outline_px": self.outline,
            "share_of_outline": round(self.share, 4),
        }


def outline_matches(
    candidate_mask: np.ndarray,
    candidate_ids: Sequence[str],
    reference_mask: np.ndarray,
    reference_ids: Sequence[str],
    band: int,
) -> list[OutlineMatch]:
    """Per reference object: the pixels where the candidate's silhouette and the reference's
    disagree by more than `band` pixels — shown by the candidate beyond `band` px outside the
    reference silhouette, or missing more than `band` px inside it."""
    cm, rm = np.asarray(candidate_mask), np.asarray(reference_mask)
    if cm.shape != rm.shape:
        raise ValueError(f"mask shapes differ: {cm.shape} vs the reference's {rm.shape}")
    index = {str(i): k for k, i in enumerate(candidate_ids)}
    out = []
    for k, oid in enumerate(reference_ids):
        ref = rm == k
        cand = cm == index[str(oid)] if str(oid) in index else np.zeros_like(ref)
        beyond = (cand & ~dilate(ref, band)) | (erode(ref, band) & ~cand)
        outline = ref & ~erode(ref, 1)
        out.append(
            OutlineMatch(
                id=str(oid),
                beyond=int(beyond.sum()),
                outline=int(outline.sum()),
                area_reference=int(ref.sum()),
            )
        )
    return out


def outline_problems(
    matches: Sequence[OutlineMatch], *, band: int, max_share: float, min_area: int
) -> list[str]:
    """What is wrong with the outlines ([] when every scored object keeps within the band along
    all but `max_share` of its outline), worst first."""
    scored = [m for m in matches if m.area_reference >= min_area]
    return [
        f"'{m.id}': its silhouette strays more than {band} px from the reference's along "
        f"{100 * m.share:.0f}% of its outline ({m.beyond} px beyond the edge band, outline "
        f"{m.outline} px; at most {100 * max_share:g}%): shifted, scaled or mirrored"
        for m in sorted(scored, key=lambda m: -m.share)
        if m.share > max_share
    ]


__all__ = ["OutlineMatch", "dilate", "edge_band", "erode", "outline_matches", "outline_problems"]
