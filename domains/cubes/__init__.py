"""The cubes domain: six coloured 40 mm cubes built into stacks, towers, pyramids and rows."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from domains import _layout
from domains._layout import Unit, unit
from domains.base import Domain
from domains.registry import register
from geometry import bodies_of, place, yaw_pose
from geometry import resting_on as supports

SIDE = 0.04  # cube edge [m]
PITCH = 0.046  # centre distance of neighbours in rows and pyramid bases: 6 mm gap [m]
COLOURS = ("red", "green", "blue", "yellow", "purple", "cyan")

# Goal compositions: ("stack", n) a column, ("row", n) a row, ("pyramid", 3|6) 2-1 or 3-2-1.
# Benchmark goal k ≥ 2 uses COMPOSITIONS[k - 2]; goal 1 is the reference pyramid.
COMPOSITIONS: tuple[tuple[tuple[str, int], ...], ...] = (
    (("stack", 6),),
    (("stack", 4), ("stack", 2)),
    (("stack", 3), ("stack", 3)),
    (("stack", 5), ("stack", 1)),
    (("stack", 2), ("stack", 2), ("stack", 2)),
    (("stack", 4), ("row", 2)),
    (("stack", 3), ("stack", 1), ("stack", 1), ("stack", 1)),
    (("pyramid", 6),),
    (("pyramid", 3), ("pyramid", 3)),
    (("pyramid", 3), ("stack", 3)),
    (("pyramid", 3), ("row", 3)),
    (("pyramid", 3), ("stack", 2), ("stack", 1)),
    (("row", 6),),
    (("row", 3), ("row", 3)),
    (("row", 4), ("stack", 2)),
    (("row", 3), ("stack", 3)),
    (("row", 2), ("row", 2), ("row", 2)),
    (("pyramid", 3), ("row", 2), ("stack", 1)),
    (("stack", 3), ("stack", 2), ("stack", 1)),
)


def _at(x: float, y: float, z: float) -> np.ndarray:
    return yaw_pose(x, y, z, 0.0)


def structure(kind: str, ids: Sequence[str]) -> Unit:
    """A goal structure in its own frame (origin on the table under its centre)."""
    n = len(ids)
    if kind == "stack":
        return unit(*((i, "cube", _at(0, 0, SIDE / 2 + SIDE * k)) for k, i in enumerate(ids)))
    if kind == "row":
        return unit(
            *((i, "cube", _at((k - (n - 1) / 2) * PITCH, 0, SIDE / 2)) for k, i in enumerate(ids))
        )
    if kind == "pyramid":
        levels = (3, 2, 1) if n == 6 else (2, 1)
        members, k = [], 0
        for level, count in enumerate(levels):
            for j in range(count):
                x = (j - (count - 1) / 2) * PITCH
                members.append((ids[k], "cube", _at(x, 0, SIDE / 2 + SIDE * level)))
                k += 1
        return unit(*members)
    raise ValueError(f"unknown structure {kind!r}")


@register("cubes")
class Cubes(Domain):
    name = "cubes"
    root = Path(__file__).parent
    REFERENCE_RELATIONS = {  # noqa: RUF012
        "on": "the source cube rests on the target cube",
        "adjacent": "the two cubes stand side by side at the same level, at most 12 mm apart",
    }
    on_gap = 0.008
    adjacent_gap = 0.012
    properties = {
        "relate": [
            (
                "relations_match_geometry",
                {"kind": "on", "meaning": "(upper cube → cube it rests on)"},
            ),
            ("support_acyclic", {"kind": "on"}),
        ],
        "plan": [("temporary_places_clear", {"gap": 0.005})],
        "perceive": [("physically_valid", {"penetration": 0.003, "contact": 0.004})],
    }

    def make_goal(self, rng: np.random.Generator, index: int | None) -> list[dict]:
        if index == 1:  # the authoring reference: a 3-2-1 pyramid facing the camera
            u = structure("pyramid", COLOURS)
            return _layout.records(u, yaw_pose(0.5, 0.0, 0.0, np.pi / 2))
        if index is None:
            comp = COMPOSITIONS[int(rng.integers(len(COMPOSITIONS)))]
        else:
            comp = COMPOSITIONS[(index - 2) % len(COMPOSITIONS)]
        ids = [str(i) for i in rng.permutation(COLOURS)]
        units, k = [], 0
        for kind, n in comp:
            units.append(structure(kind, ids[k : k + n]))
            k += n
        return _layout.scatter(
            rng, units, self.parts, self.placement, clearance=0.05, yaws=(-np.pi / 2, np.pi / 2)
        )

    def make_start(self, rng: np.random.Generator, goal: Sequence[Mapping]) -> list[dict]:
        pose = {r["id"]: np.asarray(r["pose"]) for r in goal}
        sup = supports(bodies_of(goal, self.parts))
        free = [str(i) for i in rng.permutation(COLOURS)]
        units: list[Unit] = []
        fixed: list[dict] = []

        # a goal column rebuilt in a wrong order
        columns = _columns(sup)
        if columns and rng.random() < 0.7:
            col = columns[int(rng.integers(len(columns)))]
            col = col[: int(rng.integers(2, min(3, len(col)) + 1))]
            order = list(col)
            while order == col:
                order = [str(i) for i in rng.permutation(col)]
            units.append(structure("stack", order))
            free = [i for i in free if i not in order]

        # cubes squatting on other cubes' goal spots on the table
        ground = [i for i in COLOURS if not sup[i]]
        for _ in range(int(rng.integers(0, 3))):
            spots = [
                g
                for g in ground
                if not any(
                    np.linalg.norm(pose[g][:2, 3] - f["pose"][:2, 3]) < 2 * SIDE for f in fixed
                )
            ]
            if not spots:
                break
            spot = spots[int(rng.integers(len(spots)))]
            movers = [i for i in free if i != spot]
            if not movers:
                break
            who = movers[int(rng.integers(len(movers)))]
            x, y = pose[spot][:2, 3] + rng.uniform(-0.01, 0.01, 2)
            at = yaw_pose(float(x), float(y), SIDE / 2, rng.uniform(-np.pi, np.pi))
            rec = {"id": who, "mesh": "cube", "pose": at}
            body = place(who, self.parts["cube"], at)
            placed = [place(f["id"], self.parts["cube"], f["pose"]) for f in fixed]
            if _layout.fits([body], placed, self.placement, 0.03):
                fixed.append(rec)
                free.remove(who)

        # an extra random pair stacked, then the rest alone
        if len(free) >= 2 and rng.random() < 0.4:
            units.append(structure("stack", free[:2]))
            free = free[2:]
        units += [structure("stack", [i]) for i in free]
        placed = [place(f["id"], self.parts["cube"], f["pose"]) for f in fixed]
        return fixed + _layout.scatter(rng, units, self.parts, self.placement, placed=placed)


def _columns(sup: Mapping[str, set[str]]) -> list[list[str]]:
    """Goal columns (bottom to top) of ≥ 2 cubes each resting on exactly one cube."""
    above = {}
    for i, s in sup.items():
        if len(s) == 1:
            above[next(iter(s))] = i
    cols = []
    for base in sorted(i for i, s in sup.items() if not s):
        col = [base]
        while col[-1] in above:
            col.append(above[col[-1]])
        if len(col) >= 2:
            cols.append(col)
    return cols
