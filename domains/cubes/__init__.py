"""The cubes domain: six coloured 40 mm cubes built into stacks, towers, pyramids and rows.

Two splits of goals and starts (docs/domains.md, "Splits"): the dev split draws the
compositions of `COMPOSITIONS` (linear structures standing 50 mm apart); the test split
draws the families of `TEST_FAMILIES` — rows that meet (a cube with neighbours on two, three
or four sides), towers side by side, towers bridged — that no dev composition contains, and
starts every cube in tall stacks of clutter close together, one squatting on a goal spot.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from domains import _layout
from domains._layout import Unit, unit
from domains.base import Domain
from domains.errors import GenerationError
from domains.generation import retry
from domains.registry import register
from geometry import bodies_of, place, yaw_pose
from geometry import resting_on as supports
from geometry.tolerances import TOLERANCES

SIDE = 0.04  # cube edge [m]
PITCH = 0.046  # centre distance of neighbours in rows and pyramid bases: 6 mm gap [m]
COLOURS = ("red", "green", "blue", "yellow", "purple", "cyan")
# `Cubes.hidden_scene`: the cube behind a tower stands this far behind its centre and at most
# this far to the side; the other cubes keep their centres this far apart [m]
HIDDEN_BEHIND = (0.045, 0.075)
HIDDEN_ASIDE = 0.03
HIDDEN_APART = 0.075

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


# Test goal families: cells (i, j, level) of a 6-cube structure on the 46 mm grid (half
# integers i: a cube bridging two below, as in a pyramid), each family with variants (where
# the sixth cube stands). Test goal k uses TEST_FAMILIES[(k - 1) % 7], a variant and a
# mirror image drawn from its seed.
TEST_FAMILIES: dict[str, tuple[tuple[tuple[float, float, int], ...], ...]] = {
    # two rows of three meeting at a corner cube (neighbours on two sides), a cube on top
    "ell": (
        ((0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (0, 2, 0), (0, 0, 1)),
        ((0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (0, 2, 0), (2, 0, 1)),
    ),
    # a row of three with a row of two against its middle (neighbours on three sides)
    "tee": (
        ((0, 0, 0), (1, 0, 0), (2, 0, 0), (1, 1, 0), (1, 2, 0), (1, 0, 1)),
        ((0, 0, 0), (1, 0, 0), (2, 0, 0), (1, 1, 0), (1, 2, 0), (1, 2, 1)),
    ),
    # two rows of three crossing at their middle (neighbours on four sides)
    "plus": (
        ((1, 1, 0), (0, 1, 0), (2, 1, 0), (1, 0, 0), (1, 2, 0), (1, 1, 1)),
        ((1, 1, 0), (0, 1, 0), (2, 1, 0), (1, 0, 0), (1, 2, 0), (2, 1, 1)),
    ),
    # three towers of two standing in an L (the corner tower has neighbours on two sides at
    # both levels)
    "corner": (((0, 0, 0), (0, 0, 1), (1, 0, 0), (1, 0, 1), (0, 1, 0), (0, 1, 1)),),
    # two towers of two bridged by a cube carrying a cube: support four deep, on two towers
    "gate": (((0, 0, 0), (0, 0, 1), (1, 0, 0), (1, 0, 1), (0.5, 0, 2), (0.5, 0, 3)),),
    # a stack of four on a 2-1 pyramid's top: support five deep, 200 mm tall
    "spire": (((0, 0, 0), (1, 0, 0), (0.5, 0, 1), (0.5, 0, 2), (0.5, 0, 3), (0.5, 0, 4)),),
    # towers of three, two and one in a row: a staircase, the middle tower between two
    "stairs": (
        ((0, 0, 0), (0, 0, 1), (0, 0, 2), (1, 0, 0), (1, 0, 1), (2, 0, 0)),
        ((0, 0, 0), (0, 0, 1), (1, 0, 0), (1, 0, 1), (1, 0, 2), (2, 0, 0)),
    ),
}
# Test starts: every cube in a stack, of these heights (random order inside a stack).
TEST_START_STACKS = ((3, 3), (4, 2), (3, 2, 1), (4, 1, 1), (5, 1))
TEST_START_CLEARANCE = 0.012  # between start stacks in the test split [m] (dev: 0.03)


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


def cells_structure(cells: Sequence[tuple[float, float, int]], ids: Sequence[str]) -> Unit:
    """A structure of grid cells (i, j, level) [46 mm, 46 mm, 40 mm], centred in its frame."""
    c = np.asarray(cells, float)
    mid = (c[:, :2].min(axis=0) + c[:, :2].max(axis=0)) / 2
    return unit(
        *(
            (i, "cube", _at((x - mid[0]) * PITCH, (y - mid[1]) * PITCH, SIDE / 2 + SIDE * lv))
            for i, (x, y, lv) in zip(ids, cells, strict=True)
        )
    )


GRID_STEPS = ((1, 0), (-1, 0), (0, 1), (0, -1))


def task_structure(rng: np.random.Generator, n: int = 6) -> list[tuple[float, float, int]] | None:
    """Grid cells (i, j, level) of any structure the task text allows ("stacks, towers,
    pyramids and rows", 6 mm apart): a connected base on the table, then cubes on a cube or
    across two side-by-side cubes of one level (a pyramid's step); None when the draw runs out
    of places. Neither the dev catalogue nor the test families: the property tests and
    `benchmarks.compositions_bench` draw goals from it (`cells_structure` builds them)."""
    cells: list[tuple[float, float, int]] = [(0.0, 0.0, 0)]
    base = int(rng.integers(2, n + 1))
    while len(cells) < base:
        i, j, _ = cells[int(rng.integers(len(cells)))]
        di, dj = GRID_STEPS[int(rng.integers(4))]
        if (i + di, j + dj, 0) not in cells:
            cells.append((i + di, j + dj, 0))
    for _ in range(200):
        if len(cells) == n:
            return cells
        a = cells[int(rng.integers(len(cells)))]
        if rng.random() < 0.5:
            cell = (a[0], a[1], a[2] + 1)
        else:
            side = [b for b in cells if b[2] == a[2] and abs(b[0] - a[0]) + abs(b[1] - a[1]) == 1]
            if not side:
                continue
            b = side[int(rng.integers(len(side)))]
            cell = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2, a[2] + 1)
        if not any(
            c[2] == cell[2] and abs(c[0] - cell[0]) < 1 and abs(c[1] - cell[1]) < 1 for c in cells
        ):
            cells.append(cell)
    return cells if len(cells) == n else None


def shape_key(cells: Sequence[tuple[float, float, int]]) -> tuple:
    """The cells' shape up to turns by 90°, mirroring and shifts on the grid (a sorted tuple)."""
    keys = []
    for mirror in (1, -1):
        for turn in range(4):
            pts = [(i, mirror * j, lv) for i, j, lv in cells]
            for _ in range(turn):
                pts = [(-j, i, lv) for i, j, lv in pts]
            i0, j0 = min(p[0] for p in pts), min(p[1] for p in pts)
            keys.append(tuple(sorted((i - i0, j - j0, lv) for i, j, lv in pts)))
    return min(keys)


# the test split's goal shapes, which composed goals (`Cubes.compose`) never take
TEST_SHAPES = frozenset(shape_key(v) for vs in TEST_FAMILIES.values() for v in vs)


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
    properties = {  # noqa: RUF012
        "relate": [
            (
                "relations_match_geometry",
                {"kind": "on", "meaning": "(upper cube → cube it rests on)"},
            ),
            ("support_acyclic", {"kind": "on"}),
        ],
        "plan": [("temporary_places_clear", {"gap": 0.005})],
        "perceive": [
            (
                "physically_valid",
                {
                    "penetration": TOLERANCES.perceived_penetration,
                    "contact": TOLERANCES.perceived_contact,
                },
            )
        ],
    }
    composed_goals = (
        "any structure of the six cubes the task text allows: rows, stacks, towers and "
        "pyramids joined in any shape, each cube on the table, on one cube or across two"
    )

    def make_goal(
        self, rng: np.random.Generator, index: int | None, split: str = "dev"
    ) -> list[dict]:
        if split == "test":
            return retry(lambda: self._test_goal(rng, index))
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

    def compose(self, seed: int) -> tuple[list[dict], list[dict]] | None:
        """A structure of `task_structure` (any six-cube stack, tower, pyramid or row on the
        46 mm grid), placed and started as dev goals are; never one of the test split's
        families (up to turns and mirroring: those stay held out)."""
        rng = np.random.default_rng(seed)
        cells = task_structure(rng)
        if cells is None or shape_key(cells) in TEST_SHAPES:
            return None
        ids = [str(i) for i in rng.permutation(COLOURS)]
        try:
            goal = _layout.scatter(
                rng,
                [cells_structure(cells, ids)],
                self.parts,
                self.placement,
                clearance=0.05,
                yaws=(-np.pi / 2, np.pi / 2),
            )
            return self.make_start(rng, goal), goal
        except GenerationError:
            return None

    def hidden_scene(self, seed: int) -> tuple[list[dict], str] | None:
        """A tower of two or three cubes anywhere in the placement region, turned any way, and
        a cube behind it (farther from the front camera: less x), `HIDDEN_BEHIND` behind and up
        to `HIDDEN_ASIDE` to the side, turned like the tower or not; the other cubes apart on
        the table. The task text's "a cube behind a tower may not show at all"."""
        rng = np.random.default_rng(seed)
        ids = [str(i) for i in rng.permutation(COLOURS)]
        region, half = self.placement, SIDE / 2
        k = int(rng.integers(2, 4))
        x0 = rng.uniform(region.x[0] + HIDDEN_BEHIND[1] + half, region.x[1] - half)
        y0 = rng.uniform(region.y[0] + HIDDEN_ASIDE + half, region.y[1] - HIDDEN_ASIDE - half)
        yaw = rng.uniform(0.0, np.pi / 2)
        recs = [
            self.record(ids[j], yaw_pose(x0, y0, half * (2 * j + 1), yaw + rng.normal(0, 0.02)))
            for j in range(k)
        ]
        dx, dy = rng.uniform(*HIDDEN_BEHIND), rng.uniform(-HIDDEN_ASIDE, HIDDEN_ASIDE)
        turned = yaw if rng.random() < 0.5 else rng.uniform(0.0, np.pi / 2)
        recs.append(self.record(ids[k], yaw_pose(x0 - dx, y0 + dy, half, turned)))
        taken = [(x0, y0), (x0 - dx, y0 + dy)]
        for oid in ids[k + 1 :]:
            for _ in range(200):
                x, y = rng.uniform(*region.x), rng.uniform(*region.y)
                if all(np.hypot(x - a, y - b) > HIDDEN_APART for a, b in taken):
                    break
            else:
                return None
            taken.append((x, y))
            recs.append(self.record(oid, yaw_pose(x, y, half, rng.uniform(0.0, np.pi / 2))))
        return recs, ids[k]

    def _test_goal(self, rng: np.random.Generator, index: int | None) -> list[dict]:
        names = list(TEST_FAMILIES)
        if index is None:
            family = names[int(rng.integers(len(names)))]
        else:
            family = names[(index - 1) % len(names)]
        variants = TEST_FAMILIES[family]
        cells = variants[int(rng.integers(len(variants)))]
        if rng.random() < 0.5:  # the mirror image
            cells = tuple((i, -j, lv) for i, j, lv in cells)
        ids = [str(i) for i in rng.permutation(COLOURS)]
        u = cells_structure(cells, ids)
        return _layout.scatter(
            rng, [u], self.parts, self.placement, clearance=0.05, yaws=(-np.pi / 2, np.pi / 2)
        )

    def make_start(
        self, rng: np.random.Generator, goal: Sequence[Mapping], split: str = "dev"
    ) -> list[dict]:
        if split == "test":
            return retry(lambda: self._test_start(rng, goal))
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

    def _test_start(self, rng: np.random.Generator, goal: Sequence[Mapping]) -> list[dict]:
        """Stacked clutter: every cube in a stack (one of three or more), the first stack
        standing on the goal spot of a cube on the table, the others close around."""
        pose = {r["id"]: np.asarray(r["pose"]) for r in goal}
        sup = supports(bodies_of(goal, self.parts))
        ids = [str(i) for i in rng.permutation(COLOURS)]
        sizes = TEST_START_STACKS[int(rng.integers(len(TEST_START_STACKS)))]
        stacks, k = [], 0
        for n in sizes:
            stacks.append(ids[k : k + n])
            k += n
        ground = [i for i in COLOURS if not sup[i]]
        spot = ground[int(rng.integers(len(ground)))]
        x, y = pose[spot][:2, 3] + rng.uniform(-0.01, 0.01, 2)
        first = _layout.records(
            structure("stack", stacks[0]),
            yaw_pose(float(x), float(y), 0.0, rng.uniform(-np.pi, np.pi)),
        )
        placed = [place(f["id"], self.parts["cube"], f["pose"]) for f in first]
        rest = [structure("stack", s) for s in stacks[1:]]
        return first + _layout.scatter(
            rng,
            rest,
            self.parts,
            self.placement,
            placed=placed,
            clearance=TEST_START_CLEARANCE,
        )


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
