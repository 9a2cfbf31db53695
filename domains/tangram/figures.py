"""Tangram figures: named silhouettes and their tilings by the seven pieces.

Figures are drawn on a lattice of unit `UNIT` (= a quarter of the big square's side): every
silhouette is a union of polygons with integer vertices and edges along the axes or the
diagonals, so it is a union of quarter cells (unit squares cut by both diagonals). An exact
cover search tiles it with the seven pieces, each only *rotated* by multiples of 45° — the
parallelogram keeps its real handedness, because a robot cannot turn it over.

    python -m domains.tangram.make_figures    # solve every silhouette, write figures.json

`figures.json` holds, per figure, each piece's lattice rotation (multiples of 45°) and
centroid [units]; the generator turns them into poses. Goal 1 of the benchmark is `square`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
UNIT = 0.04  # lattice unit [m]: the big square figure is 4 units = 160 mm

# Piece outlines in lattice units, counter-clockwise, in their canonical orientation:
# triangles with the hypotenuse along +x and the right angle toward +y; the square with its
# edges along the axes; the parallelogram with its long edge along +x, leaning right.
R2 = np.sqrt(2.0)
PIECES: dict[str, np.ndarray] = {
    "large_triangle": np.array([(0, 0), (4, 0), (2, 2)], float),
    "medium_triangle": np.array([(0, 0), (2 * R2, 0), (R2, R2)], float),
    "small_triangle": np.array([(0, 0), (2, 0), (1, 1)], float),
    "square": np.array([(0, 0), (R2, 0), (R2, R2), (0, R2)], float),
    "parallelogram": np.array([(0, 0), (2, 0), (3, 1), (1, 1)], float),
}
# object id → mesh key; the two large and the two small triangles are interchangeable
OBJECTS: dict[str, str] = {
    "large_1": "large_triangle",
    "large_2": "large_triangle",
    "medium": "medium_triangle",
    "small_1": "small_triangle",
    "small_2": "small_triangle",
    "square": "square",
    "parallelogram": "parallelogram",
}


def centroid(poly: np.ndarray) -> np.ndarray:
    p, q = poly, np.roll(poly, -1, axis=0)
    c = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    a = c.sum() / 2
    return np.array([((p[:, 0] + q[:, 0]) * c).sum(), ((p[:, 1] + q[:, 1]) * c).sum()]) / (6 * a)


def canonical(mesh: str) -> np.ndarray:
    """The piece outline centred on its area centroid [units]."""
    p = PIECES[mesh]
    return p - centroid(p)


def _rot(k: int) -> np.ndarray:
    t = k * np.pi / 4
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


# -- the quarter-cell lattice -----------------------------------------------------------

_Q = np.array([(0.5, 0.2), (0.8, 0.5), (0.5, 0.8), (0.2, 0.5)])  # centres of the 4 quarters


def _inside(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Points strictly inside a convex or simple polygon (even-odd rule)."""
    x, y = points[:, 0], points[:, 1]
    inside = np.zeros(len(points), bool)
    n = len(poly)
    for i in range(n):
        (x0, y0), (x1, y1) = poly[i], poly[(i + 1) % n]
        cross = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xi = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= cross & (x < xi)
    return inside


def cells(polys: Sequence[np.ndarray]) -> frozenset[tuple[int, int, int]]:
    """Quarter cells (i, j, q) covered by a union of lattice polygons."""
    allp = np.concatenate(polys)
    lo, hi = np.floor(allp.min(axis=0)).astype(int), np.ceil(allp.max(axis=0)).astype(int)
    out = set()
    for i in range(lo[0], hi[0]):
        for j in range(lo[1], hi[1]):
            pts = _Q + np.array([i, j])
            hit = np.zeros(4, bool)
            for p in polys:
                hit |= _inside(pts, p)
            out |= {(i, j, q) for q in range(4) if hit[q]}
    return frozenset(out)


def placements(mesh: str, region: frozenset) -> list[tuple[int, np.ndarray, frozenset]]:
    """Every lattice placement (rotation k, centroid, cells) of a piece inside `region`."""
    base = canonical(mesh)
    ij = np.array([(c[0], c[1]) for c in region])
    lo, hi = ij.min(axis=0), ij.max(axis=0) + 1
    out, seen = [], set()
    for k in range(8):
        poly = base @ _rot(k).T
        rel = poly - poly[0]
        if not np.allclose(rel, np.round(rel), atol=1e-9):
            continue  # this rotation does not put the vertices on the lattice
        for x in range(lo[0], hi[0] + 1):
            for y in range(lo[1], hi[1] + 1):
                placed = np.round(rel) + np.array([x, y])
                cs = cells([placed])
                if len(cs) != round(4 * _area(placed)) or not cs <= region or cs in seen:
                    continue
                seen.add(cs)
                out.append((k, (x, y) - poly[0], cs))
    return out


def _area(p: np.ndarray) -> float:
    q = np.roll(p, -1, axis=0)
    return 0.5 * abs(float((p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]).sum()))


def solve(
    polys: Sequence[Sequence[tuple[float, float]]],
) -> dict[str, tuple[int, list[float]]] | None:
    """Tile a silhouette with the seven pieces: {object id: (rotation k, centroid [units])}."""
    region = cells([np.asarray(p, float) for p in polys])
    if len(region) != 64:
        raise ValueError(f"silhouette covers {len(region) / 4} units², the pieces cover 16")
    options = {m: placements(m, region) for m in PIECES}
    need = {m: list(OBJECTS.values()).count(m) for m in PIECES}
    chosen: list[tuple[str, int, np.ndarray, frozenset]] = []

    def search(free: frozenset) -> bool:
        if not free:
            return True
        target = min(free)  # the first uncovered cell must be covered by some piece
        for m in PIECES:
            if need[m] == 0:
                continue
            for k, c, cs in options[m]:
                if target in cs and cs <= free:
                    need[m] -= 1
                    chosen.append((m, k, c, cs))
                    if search(free - cs):
                        return True
                    chosen.pop()
                    need[m] += 1
        return False

    if not search(region):
        return None
    out: dict[str, tuple[int, list[float]]] = {}
    for m, k, c, _ in sorted(chosen, key=lambda t: (t[0], tuple(t[2]))):
        oid = next(i for i, mm in OBJECTS.items() if mm == m and i not in out)
        out[oid] = (int(k), [round(float(v), 9) for v in c])
    return dict(sorted(out.items()))


# Silhouettes: union of lattice polygons [units], drawn upright (+y up). Some were drawn by
# hand, the others found by a seeded random assembly search over the lattice, kept when
# they read as something, and named by a person.
SILHOUETTES: dict[str, list[list[tuple[float, float]]]] = {
    "square": [[(0, 0), (4, 0), (4, 4), (0, 4)]],
    "triangle": [[(0, 0), (8, 0), (4, 4)]],
    "ramp": [[(0, 0), (6, 0), (2, 4), (0, 4)]],
    "arrow": [
        [(0, 0), (2, 0), (4, 2), (2, 4), (0, 4), (2, 2)],
        [(2, 0), (4, 0), (6, 2), (4, 4), (2, 4), (4, 2)],
    ],
    "sailboat": [
        [(2, 0), (6, 0), (8, 2), (0, 2)],
        [(4, 2), (6, 2), (4, 4)],
        [(2, 2), (4, 2), (4, 4)],
    ],
    "bird": [[(0, 2), (4, 2), (6, 0), (8, 2), (6, 4), (2, 4)]],
    "zigzag": [[(0, 0), (4, 0), (6, 2), (2, 2)], [(2, 2), (6, 2), (8, 4), (4, 4)]],
    "rectangle": [[(2, 0), (6, 4), (4, 6), (0, 2)]],
    "house": [[(0, 0), (4, 0), (4, 2), (5, 3), (3, 5), (0, 2)]],
    "boat": [[(1, 0), (7, 0), (6, 1), (6, 3), (2, 3), (0, 1)]],
    "cat": [
        [(0, 0), (4, 0), (3, 1), (4, 2), (4, 4), (3, 5), (2, 4), (1, 5), (0, 4), (0, 2), (1, 1)]
    ],
    "rocket": [
        [
            (0, 1),
            (1, 1),
            (2, 0),
            (3, 1),
            (4, 1),
            (4, 3),
            (3, 4),
            (4, 4),
            (2, 6),
            (0, 4),
            (1, 4),
            (0, 3),
        ]
    ],
    "bone": [
        [
            (1, 0),
            (2, 1),
            (4, 1),
            (5, 0),
            (7, 2),
            (5, 4),
            (4, 3),
            (2, 3),
            (1, 4),
            (0, 3),
            (1, 2),
            (0, 1),
        ]
    ],
    "jet": [[(1, 0), (2, 1), (6, 1), (4, 3), (5, 4), (4, 5), (3, 4), (1, 6), (1, 2), (0, 1)]],
    "shield": [[(1, 0), (3, 0), (5, 2), (2, 5), (0, 3), (0, 1)]],
    "hexagon": [[(2, 0), (4, 2), (4, 4), (2, 6), (0, 4), (0, 2)]],
    "arrowhead": [[(2, 0), (5, 3), (2, 6), (0, 4), (1, 3), (0, 2)]],
    "swan": [[(0, 0), (2, 0), (3, 1), (5, 1), (6, 2), (4, 2), (0, 6)]],
    "duck": [[(1, 0), (5, 0), (7, 2), (5, 2), (2, 5), (2, 3), (0, 1)]],
    "dog": [[(1, 0), (5, 0), (5, 2), (6, 3), (5, 4), (4, 3), (0, 3), (0, 1)]],
    "signpost": [[(2, 0), (4, 2), (5, 1), (6, 2), (2, 6), (1, 5), (2, 4), (0, 2)]],
    "caterpillar": [
        [
            (1, 0),
            (2, 1),
            (3, 0),
            (4, 1),
            (4, 0),
            (6, 2),
            (4, 4),
            (4, 3),
            (3, 4),
            (2, 3),
            (1, 4),
            (0, 3),
            (0, 1),
        ]
    ],
    "parallelogram": [[(0, 0), (4, 0), (7, 3), (5, 5)]],
    "bottle": [[(0, 0), (4, 0), (3, 1), (3, 5), (2, 6), (0, 4)]],
    "bowtie": [[(0, 0), (4, 0), (5, 1), (5, 3), (6, 4), (0, 4), (2, 2)]],
    "anvil": [[(0, 0), (6, 0), (3, 3), (4, 4), (0, 4), (1, 3), (0, 2)]],
    "crown": [[(0, 0), (4, 0), (5, 1), (5, 3), (4, 4), (3, 3), (2, 4), (0, 2)]],
    "tulip": [[(1, 0), (3, 0), (4, 1), (4, 5), (3, 4), (2, 5), (0, 3), (0, 1)]],
    "bathtub": [[(1, 0), (5, 0), (5, 2), (6, 3), (2, 3), (1, 4), (0, 3), (0, 1)]],
    "sail": [[(1, 0), (3, 0), (4, 1), (6, 1), (1, 6), (1, 2), (0, 1)]],
}
