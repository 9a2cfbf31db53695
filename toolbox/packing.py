"""Flat parts packed on a table: footprints, gaps, spreading tight layouts, finger room.

Design rule: everything is 2D in the table plane (world x, y [m]). A footprint is a convex
polygon (N, 2), counter-clockwise; gaps are signed (negative: overlap depth). Use it where
parts lie side by side at one height (tangram pieces, tiles, parts in a tray) and a top-down
gripper must reach between them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, QhullError

from toolbox.errors import ToolboxError
from toolbox.robot import FINGER_DEPTH, FINGER_WIDTH, GRASP_MARGINS

__all__ = ["finger_footprints", "footprint", "polygon_gap", "spread_footprints"]


def footprint(mesh, pose: object, *, z_range: tuple[float, float] | None = None) -> np.ndarray:
    """Convex footprint (N, 2) of a posed mesh seen from above [m], counter-clockwise.

    `z_range` (world z [m]) keeps only vertices in that height band, e.g. the knob of a
    tangram piece lying on the table (the piece is 15 mm thick, the knob stands on it):
    `footprint(mesh, pose, z_range=(0.016, 1.0))`.
    """
    T = np.asarray(pose, dtype=float)
    if T.shape != (4, 4):
        raise ToolboxError(f"pose must be (4, 4), got {T.shape}")
    V = np.asarray(mesh.vertices, dtype=float) @ T[:3, :3].T + T[:3, 3]
    if z_range is not None:
        V = V[(V[:, 2] >= z_range[0]) & (V[:, 2] <= z_range[1])]
    try:
        hull = ConvexHull(V[:, :2])
    except (QhullError, ValueError) as e:
        raise ToolboxError(f"no footprint: {len(V)} vertices span no area") from e
    return V[hull.vertices, :2]  # 2D hulls come counter-clockwise


def _poly(p: object, name: str) -> np.ndarray:
    P = np.asarray(p, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or len(P) < 3 or not np.all(np.isfinite(P)):
        raise ToolboxError(f"{name} must be a finite (N >= 3, 2) polygon, got shape {P.shape}")
    return P


def _axes(P: np.ndarray) -> np.ndarray:
    e = np.roll(P, -1, axis=0) - P
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    norm = np.linalg.norm(n, axis=1)
    return n[norm > 1e-12] / norm[norm > 1e-12, None]


def polygon_gap(a: object, b: object) -> tuple[float, np.ndarray]:
    """Signed gap [m] between two convex polygons (N, 2) and its unit axis (2,) from b to a.

    Positive: the distance along the best separating axis (exact for edge-to-edge contacts, a
    lower bound otherwise). Negative: they overlap; minus the depth to push them apart.
    Moving a by d changes the gap along that axis by `axis @ d`.
    """
    A, B = _poly(a, "a"), _poly(b, "b")
    axes = np.concatenate([_axes(A), _axes(B)])
    pa, pb = A @ axes.T, B @ axes.T
    up = pa.min(axis=0) - pb.max(axis=0)  # a beyond b along +axis
    down = pb.min(axis=0) - pa.max(axis=0)
    gaps = np.maximum(up, down)
    i = int(np.argmax(gaps))
    return float(gaps[i]), axes[i] * (1.0 if up[i] >= down[i] else -1.0)


def spread_footprints(
    footprints: Sequence[object],
    *,
    gap: float = 0.002,
    max_shift: float = 0.002,
    fixed: Sequence[int] = (),
    near: float = 0.01,
) -> np.ndarray:
    """Translations (N, 2) [m] that open tight gaps in a packed layout, moving parts little.

    Every pair closer than `near` is pushed towards `gap` apart (overlaps resolved first)
    while no part moves more than `max_shift` and the parts listed in `fixed` do not move.
    Two linear programmes over the pairs' separating axes (which keep each gap a lower
    bound): the smallest gap is made as large as possible, then every other gap as close to
    `gap` as the shift budget allows, with as little movement as possible. Use it to turn a
    perceived figure whose parts touch into placement targets a gripper with ~1 mm error can
    hit; a final check of the result with `polygon_gap` is cheap.
    """
    polys = [_poly(p, f"footprints[{i}]") for i, p in enumerate(footprints)]
    n = len(polys)
    out = np.zeros((n, 2))
    if gap < 0 or max_shift < 0:
        raise ToolboxError(f"gap and max_shift must be >= 0, got {gap}, {max_shift}")
    pairs = []
    for i in range(n):
        for j in range(i + 1, n):
            g, axis = polygon_gap(polys[i], polys[j])
            if g < near and not (i in fixed and j in fixed):
                pairs.append((i, j, g, axis))
    if not pairs:
        return out
    # variables: t (2n), |t| bounds u (2n), smallest gap s, each pair's gap e (capped at gap)
    m = len(pairs)
    s = 4 * n
    e0 = s + 1
    nv = e0 + m
    A, b = [], []
    for k, (i, j, g, axis) in enumerate(pairs):  # e_k <= g + axis·(t_i − t_j), s <= e_k
        row = np.zeros(nv)
        row[2 * i : 2 * i + 2] -= axis
        row[2 * j : 2 * j + 2] += axis
        row[e0 + k] = 1.0
        A.append(row)
        b.append(g)
        row = np.zeros(nv)
        row[s], row[e0 + k] = 1.0, -1.0
        A.append(row)
        b.append(0.0)
    for k in range(2 * n):  # −u <= t <= u
        for sign in (1.0, -1.0):
            row = np.zeros(nv)
            row[k], row[2 * n + k] = sign, -1.0
            A.append(row)
            b.append(0.0)
    # |t_i| <= max_shift: a 16-gon inside the disc
    reach = max_shift * np.cos(np.pi / 16)
    for i in range(n):
        if i in fixed:
            continue
        for a in np.arange(16) * np.pi / 8:
            row = np.zeros(nv)
            row[2 * i : 2 * i + 2] = (np.cos(a), np.sin(a))
            A.append(row)
            b.append(reach)
    bounds: list[tuple[float | None, float | None]] = [
        (0.0, 0.0) if (k // 2) in fixed else (None, None) for k in range(2 * n)
    ]
    bounds += [(0.0, None)] * (2 * n)
    lowest = min(p[2] for p in pairs)
    bounds.append((min(lowest, gap), gap))
    bounds += [(None, gap)] * m
    A_ub, b_ub = np.array(A), np.array(b)
    c = np.zeros(nv)
    c[s] = -1.0
    first = linprog(c, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs")
    if first.status != 0:
        return out
    bounds[s] = (first.x[s] - 1e-7, gap)
    c = np.zeros(nv)
    c[e0:] = -1.0
    c[2 * n : 4 * n] = 1e-3  # movement matters only between equally good spreads
    second = linprog(c, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs")
    x = second.x if second.status == 0 else first.x
    return x[: 2 * n].reshape(n, 2)


def finger_footprints(
    centre: object,
    closing: object,
    opening: float,
    *,
    finger_depth: float = FINGER_DEPTH,
    finger_width: float = FINGER_WIDTH,
    margin: float = GRASP_MARGINS[-1],
) -> list[np.ndarray]:
    """Footprints (two (4, 2) rectangles [m]) of a parallel gripper's open fingers, from above.

    Args:
        centre: (2,) the point between the jaws (e.g. a knob's centre).
        closing: (2,) the direction the jaws close along (need not be unit).
        opening: distance between the pads' inner faces [m].
        finger_depth, finger_width: each finger's extent outwards from its pad face and
            across the closing direction; the defaults are the 2F-85's
            (`toolbox.robot.FINGER_DEPTH`, `FINGER_WIDTH`).
        margin: clearance added on every side [m]; the default is the least the executor
            keeps (`toolbox.robot.GRASP_MARGINS`).
    Whatever overlaps a rectangle at the fingers' height (`polygon_gap(...) < 0`) is in the
    way of that grasp; try the other closing direction (a square knob has two).
    """
    c = np.asarray(centre, dtype=float).reshape(2)
    d = np.asarray(closing, dtype=float).reshape(2)
    norm = float(np.linalg.norm(d))
    if norm < 1e-12 or opening < 0:
        raise ToolboxError("closing must be a non-zero direction and opening >= 0")
    d = d / norm
    across = np.array([-d[1], d[0]])
    half = finger_width / 2 + margin
    out = []
    for side in (1.0, -1.0):
        lo, hi = opening / 2 - margin, opening / 2 + finger_depth + margin
        corners = [(lo, -half), (hi, -half), (hi, half), (lo, half)]
        rect = np.array([c + side * a * d + w * across for a, w in corners])
        out.append(rect if side > 0 else rect[::-1])  # keep counter-clockwise
    return out
