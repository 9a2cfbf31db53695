"""The tangram domain: seven knobbed pieces packed edge to edge into named figures.

Two splits (docs/domains.md, "Splits"): the dev split draws the 30 figures of figures.json
(the benchmark the first 20), upright ±20°, from starts with the pieces 20 mm apart; the
test split draws the 20 figures of test_figures.json (outlines no dev figure has: a compact
family drawn upright and a spread-out family drawn turned 34–180° away from upright), from
starts where every piece must turn far, the pieces lie 8 mm apart and two to four of them
lie inside the figure's area.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from functools import cached_property
from pathlib import Path

import numpy as np

from domains import _layout
from domains.base import Domain
from domains.errors import GenerationError
from domains.generation import retry
from domains.registry import register
from domains.tangram.figures import OBJECTS, UNIT, catalogue_keys, compose_figure, shape_key
from geometry import PLACEMENT_SPREAD, TOLERANCES, Body, Workspace, place, yaw_of, yaw_pose

# Benchmark goal k uses the k-th figure (goal 1, the reference, is the square); free draws
# use any figure. Test goal k uses the k-th test figure; free test draws any test figure.
BENCHMARK_FIGURES = 20
# Test starts: the least and most turn [rad] from a piece's start to its goal, modulo the
# piece's symmetry (triangles none, parallelogram a half turn, square a quarter turn), and
# the gap between start pieces [m] (dev: any turn, 20 mm).
TEST_TURNS = {
    "large_triangle": (2 * np.pi / 3, np.pi),
    "medium_triangle": (2 * np.pi / 3, np.pi),
    "small_triangle": (2 * np.pi / 3, np.pi),
    "parallelogram": (np.pi / 3, np.pi / 2),
    "square": (np.pi / 6, np.pi / 4),
}
TEST_START_CLEARANCE = 0.008
TEST_TURNED = (0.6, np.pi)  # a turned figure's heading away from upright [rad] (dev ≤ 0.35)
_CATALOGUE = catalogue_keys()  # the dev and test figures' outlines: never composed


@register("tangram")
class Tangram(Domain):
    name = "tangram"
    root = Path(__file__).parent
    REFERENCE_RELATIONS = {  # noqa: RUF012
        "adjacent": "the two pieces touch edge to edge or corner to corner (at most 8 mm apart)",
        "on": "the source piece lies on the target piece",
    }
    on_gap = 0.005
    adjacent_gap = 0.008
    temp_clearance = 0.03
    placement_spread = PLACEMENT_SPREAD
    properties = {  # noqa: RUF012
        "perceive": [
            ("never_mirrored", {"meshes": ["parallelogram"]}),
            ("ids_follow_the_image", {}),
            ("no_overlap", {"penetration": TOLERANCES.perceived_penetration}),
        ],
        "relate": [
            (
                "relations_match_geometry",
                {
                    "kind": "adjacent",
                    "meaning": "(two pieces touching edge to edge or corner to corner, both ways)",
                },
            ),
        ],
        "plan": [
            ("turns_about_vertical", {}),
            ("no_stacking", {}),
            ("never_mirrored", {"meshes": ["parallelogram"]}),
            ("temporary_clear_of_goals", {}),
        ],
    }
    composed_goals = (
        "any figure of the seven pieces joined edge to edge on the figures' lattice (each piece "
        "turned by a multiple of 45°), at any heading on the table"
    )

    @cached_property
    def figures(self) -> dict[str, dict]:
        """Figure name → {"silhouette", "centre", "pieces": {id: {"rotation_45", "centroid"}}}."""
        return json.loads((self.root / "figures.json").read_text())

    @cached_property
    def test_figures(self) -> dict[str, dict]:
        """The test split's figures, as `figures` plus each one's "family"."""
        return json.loads((self.root / "test_figures.json").read_text())

    def figure_records(self, name: str, pose: np.ndarray) -> list[dict]:
        """The figure `name` (a dev or a test figure) built at `pose` (the figure's centre,
        on the table)."""
        fig = self.figures[name] if name in self.figures else self.test_figures[name]
        return _records(fig, pose)

    def compose(self, seed: int) -> tuple[list[dict], list[dict]] | None:
        """A figure of `compose_figure` (the seven pieces joined edge to edge on the figures'
        lattice) at any heading (the task text leaves it free), started as dev goals are;
        never a dev or a test figure's outline, turned or mirrored (the test figures stay held
        out)."""
        rng = np.random.default_rng(seed)
        fig = compose_figure(rng)
        if fig is None or shape_key(fig["silhouette"]) in _CATALOGUE:
            return None
        goal = self._fit(fig, rng, tries=50, away=lambda rng: rng.uniform(-np.pi, np.pi))
        if goal is None:
            return None
        try:
            return self.make_start(rng, goal), goal
        except GenerationError:
            return None

    def _fit(
        self,
        fig: Mapping,
        rng: np.random.Generator,
        tries: int = 200,
        away: Callable[[np.random.Generator], float] = lambda rng: rng.uniform(-0.35, 0.35),
    ) -> list[dict] | None:
        """Figure `fig` at a random centre, turned `away(rng)` from upright (dev: ±0.35 rad),
        wholly inside the placement region; None after `tries` draws. Each draw takes the
        centre, then the heading, from `rng` (the committed benchmark files rest on that
        order)."""
        for _ in range(tries):
            x, y = rng.uniform(0.42, 0.58), rng.uniform(-0.12, 0.12)
            recs = _records(fig, yaw_pose(x, y, 0.0, np.pi / 2 + away(rng)))
            if self._inside(recs):
                return recs
        return None

    def _inside(self, records: Sequence[Mapping]) -> bool:
        """Every piece of `records` wholly inside the placement region."""
        return all(
            self.placement.contains(place(r["id"], self.parts[r["mesh"]], r["pose"]).xy())
            for r in records
        )

    def make_goal(
        self, rng: np.random.Generator, index: int | None, split: str = "dev"
    ) -> list[dict]:
        if split == "test":
            return self._test_goal(rng, index)
        names = list(self.figures)
        if index is not None:
            name = names[(index - 1) % BENCHMARK_FIGURES]
        else:
            name = names[int(rng.integers(len(names)))]
        # drawn upright (+y up) on the lattice; turning by 90° shows it upright to the front camera
        if index == 1:
            return self.figure_records(name, yaw_pose(0.5, 0.0, 0.0, np.pi / 2))
        recs = self._fit(self.figures[name], rng)
        if recs is not None:
            return recs
        raise GenerationError(f"figure {name!r} does not fit the workspace")

    def _test_goal(self, rng: np.random.Generator, index: int | None) -> list[dict]:
        names = list(self.test_figures)
        if index is not None:
            name = names[(index - 1) % len(names)]
        else:
            name = names[int(rng.integers(len(names)))]
        fig = self.test_figures[name]
        if fig["family"] == "limbs":  # turned far from upright
            recs = self._fit(
                fig, rng, away=lambda rng: rng.choice([-1.0, 1.0]) * rng.uniform(*TEST_TURNED)
            )
        else:
            recs = self._fit(fig, rng)
        if recs is not None:
            return recs
        raise GenerationError(f"figure {name!r} does not fit the workspace")

    def make_start(
        self, rng: np.random.Generator, goal: Sequence[Mapping], split: str = "dev"
    ) -> list[dict]:
        if split == "test":
            return retry(lambda: self._test_start(rng, goal))
        ids = [str(i) for i in rng.permutation(list(OBJECTS))]
        inside = int(rng.choice([0, 1, 2, 3], p=[0.3, 0.3, 0.25, 0.15]))
        xy = np.concatenate([place(r["id"], self.parts[r["mesh"]], r["pose"]).xy() for r in goal])
        area = Workspace(
            x=(float(xy[:, 0].min()), float(xy[:, 0].max())),
            y=(float(xy[:, 1].min()), float(xy[:, 1].max())),
            reach=self.placement.reach,
        )
        units = [_layout.unit((i, OBJECTS[i], np.eye(4))) for i in ids]
        placed = _layout.scatter(
            rng, units[:inside], self.parts, self.placement, clearance=0.02, area=area
        )
        bodies = [place(r["id"], self.parts[r["mesh"]], r["pose"]) for r in placed]
        return placed + _layout.scatter(
            rng, units[inside:], self.parts, self.placement, placed=bodies, clearance=0.02
        )

    def _test_start(self, rng: np.random.Generator, goal: Sequence[Mapping]) -> list[dict]:
        """Every piece turned far from its goal heading, the pieces 8 mm apart, two to four
        of them inside the figure's area."""
        yaw = {r["id"]: yaw_of(np.asarray(r["pose"], float)) for r in goal}
        ids = [str(i) for i in rng.permutation(list(OBJECTS))]
        inside = int(rng.integers(2, 5))
        xy = np.concatenate([place(r["id"], self.parts[r["mesh"]], r["pose"]).xy() for r in goal])
        area = Workspace(
            x=(float(xy[:, 0].min()), float(xy[:, 0].max())),
            y=(float(xy[:, 1].min()), float(xy[:, 1].max())),
            reach=self.placement.reach,
        )
        out: list[dict] = []
        bodies: list[Body] = []
        for k, i in enumerate(ids):
            lo, hi = TEST_TURNS[OBJECTS[i]]
            turn = rng.choice([-1.0, 1.0]) * np.array([lo, hi])
            recs = _layout.scatter(
                rng,
                [_layout.unit((i, OBJECTS[i], np.eye(4)))],
                self.parts,
                self.placement,
                placed=bodies,
                clearance=TEST_START_CLEARANCE,
                yaws=tuple(sorted(yaw[i] + turn)),
                area=area if k < inside else None,
            )
            out += recs
            bodies += [place(r["id"], self.parts[r["mesh"]], r["pose"]) for r in recs]
        return out


def _records(fig: Mapping, pose: np.ndarray) -> list[dict]:
    """The records of figure `fig` (as `figures.json` holds one) built at `pose`."""
    centre = np.asarray(fig["centre"], float)
    out = []
    for oid, p in fig["pieces"].items():
        xy = (np.asarray(p["centroid"], float) - centre) * UNIT
        local = yaw_pose(xy[0], xy[1], 0.0, p["rotation_45"] * np.pi / 4)
        out.append({"id": oid, "mesh": OBJECTS[oid], "pose": pose @ local})
    return sorted(out, key=lambda r: list(OBJECTS).index(r["id"]))
