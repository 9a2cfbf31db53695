"""Assembly specifics: resting poses, stacked starts, structures that support each other."""

from __future__ import annotations

import numpy as np
import pytest

import domains
from geometry import bodies_of
from geometry import resting_on as supports


@pytest.fixture(scope="module")
def assembly():
    return domains.load("assembly")


def test_at_least_six_shapes_all_graspable(assembly):
    assert len(assembly.mesh_specs) >= 6
    for key in assembly.mesh_specs:
        ext = np.ptp(assembly.mesh(key).vertices, axis=0)
        assert 0.03 <= ext.max() <= 0.16 and ext[1] <= 0.04, key


def test_starts_keep_the_goal_resting_pose(assembly):
    for inst in assembly.benchmark():
        goal = {r["id"]: r["pose"] for r in inst.goal["objects"]}
        for r in inst.start["objects"]:
            # same up axis: the start differs from the goal by a turn about the vertical
            assert np.allclose(r["pose"][:3, 2], goal[r["id"]][:3, 2], atol=1e-9), (
                inst.name,
                r["id"],
            )


def test_goals_stack_and_starts_sometimes_do(assembly):
    bench = assembly.benchmark()
    stacked_starts = 0
    for inst in bench:
        goal_sup = supports(bodies_of(inst.goal["objects"], assembly.parts))
        assert sum(bool(s) for s in goal_sup.values()) >= 2, inst.name  # parts carry parts
        start_sup = supports(bodies_of(inst.start["objects"], assembly.parts))
        stacked_starts += any(start_sup.values())
    assert 15 <= stacked_starts < len(bench)
    # some goal part rests on two others (a bridge)
    assert any(
        any(len(s) == 2 for s in supports(bodies_of(i.goal["objects"], assembly.parts)).values())
        for i in bench
    )
