"""Planar (seen from above) helpers: convex hulls of 2D points, clipping, inside margins.

Design rule: shared by the resting-pose analysis and the support tests, so that "the centre of
mass lies inside the support" means one thing everywhere.
"""

from __future__ import annotations

import cv2
import numpy as np


def hull2(pts: np.ndarray) -> np.ndarray:
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


def clip(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Vertices of the intersection of the convex hulls of two 2D point sets."""
    ha, hb = hull2(a), hull2(b)
    if len(ha) < 3 or len(hb) < 3:
        small, big = (ha, hb) if len(ha) < 3 else (hb, ha)
        if len(big) < 3:
            return np.zeros((0, 2))
        return np.array([p for p in small if inside_margin(big, p) > -1e-4]).reshape(-1, 2)
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


def inside_margin(poly_pts: np.ndarray, p: np.ndarray) -> float:
    """Signed distance of p inside the convex hull of 2D points (< 0 outside)."""
    h = hull2(poly_pts)
    if len(h) < 3:
        return -np.inf
    e = np.roll(h, -1, axis=0) - h
    cross = e[:, 0] * (p[1] - h[:, 1]) - e[:, 1] * (p[0] - h[:, 0])
    return float((cross / np.linalg.norm(e, axis=1)).min())


def segment_margin(pts: np.ndarray, p: np.ndarray) -> float:
    h = hull2(pts)
    if len(h) == 0:
        return -np.inf
    a, b = h[0], h[-1]
    ab = b - a
    t = 0.0 if not ab.any() else float(np.clip((p - a) @ ab / (ab @ ab), 0, 1))
    return -float(np.linalg.norm(p - (a + t * ab)))
