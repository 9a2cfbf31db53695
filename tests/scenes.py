"""Hand-built scenes several test packages judge (not a fixture: plain records)."""

from __future__ import annotations

import numpy as np

H, X0 = 0.02, 0.55  # a cube's half size [m]; where the tower stands (x) [m]
BEHIND = X0 - 2 * H - 0.012  # 12 mm behind the tower, seen from the front camera


def upright(dom, oid: str, x: float, y: float, z: float) -> dict:
    """`oid`'s record, unturned, its frame at (x, y, z)."""
    return dom.record(oid, np.array([[1, 0, 0, x], [0, 1, 0, y], [0, 0, 1, z], [0, 0, 0, 1]]))


def cube_behind_tower(cubes) -> list[dict]:
    """Cubes: red, green and blue in a tower, yellow 12 mm behind it, hidden from the front
    camera; purple and cyan beside."""
    return [
        upright(cubes, "red", X0, 0, H),
        upright(cubes, "green", X0, 0, 3 * H),
        upright(cubes, "blue", X0, 0, 5 * H),
        upright(cubes, "yellow", BEHIND, 0, H),
        upright(cubes, "purple", 0.45, 0.2, H),
        upright(cubes, "cyan", 0.45, -0.2, H),
    ]
