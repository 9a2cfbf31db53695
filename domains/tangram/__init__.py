"""The tangram domain: seven knobbed pieces packed edge to edge into named figures."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from functools import cached_property
from pathlib import Path

import numpy as np

from domains import _layout
from domains.base import Domain
from domains.errors import GenerationError
from domains.registry import register
from domains.tangram.figures import OBJECTS, UNIT
from geometry import Workspace, place, yaw_pose

# Benchmark goal k uses the k-th figure (goal 1, the reference, is the square); free draws
# use any figure.
BENCHMARK_FIGURES = 20


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

    @cached_property
    def figures(self) -> dict[str, dict]:
        """Figure name → {"silhouette", "centre", "pieces": {id: {"rotation_45", "centroid"}}}."""
        return json.loads((self.root / "figures.json").read_text())

    def figure_records(self, name: str, pose: np.ndarray) -> list[dict]:
        """The figure `name` built at `pose` (the figure's centre, on the table)."""
        fig = self.figures[name]
        centre = np.asarray(fig["centre"], float)
        out = []
        for oid, p in fig["pieces"].items():
            xy = (np.asarray(p["centroid"], float) - centre) * UNIT
            local = yaw_pose(xy[0], xy[1], 0.0, p["rotation_45"] * np.pi / 4)
            out.append({"id": oid, "mesh": OBJECTS[oid], "pose": pose @ local})
        return sorted(out, key=lambda r: list(OBJECTS).index(r["id"]))

    def make_goal(self, rng: np.random.Generator, index: int | None) -> list[dict]:
        names = list(self.figures)
        if index is not None:
            name = names[(index - 1) % BENCHMARK_FIGURES]
        else:
            name = names[int(rng.integers(len(names)))]
        # drawn upright (+y up) on the lattice; turning by 90° shows it upright to the front camera
        if index == 1:
            return self.figure_records(name, yaw_pose(0.5, 0.0, 0.0, np.pi / 2))
        for _ in range(200):
            x, y = rng.uniform(0.42, 0.58), rng.uniform(-0.12, 0.12)
            recs = self.figure_records(
                name, yaw_pose(x, y, 0.0, np.pi / 2 + rng.uniform(-0.35, 0.35))
            )
            if all(
                self.placement.contains(place(r["id"], self.parts[r["mesh"]], r["pose"]).xy())
                for r in recs
            ):
                return recs
        raise GenerationError(f"figure {name!r} does not fit the workspace")

    def make_start(self, rng: np.random.Generator, goal: Sequence[Mapping]) -> list[dict]:
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
