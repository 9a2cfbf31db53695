"""Cubes specifics: starts that force unstacking and temporary placements."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import domains
from geometry import bodies_of
from geometry import resting_on as supports


@pytest.fixture(scope="module")
def cubes():
    return domains.load("cubes")


def _columns(domain, records):
    sup = supports(bodies_of(records, domain.parts))
    above = {next(iter(s)): i for i, s in sup.items() if len(s) == 1}
    cols = []
    for base in (i for i, s in sup.items() if not s):
        col = [base]
        while col[-1] in above:
            col.append(above[col[-1]])
        cols.append(col)
    return cols


def test_goal_types(cubes):
    bench = cubes.benchmark()
    heights = [max(r["pose"][2, 3] for r in i.goal["objects"]) for i in bench[::3]]
    assert max(heights) > 0.2  # a tower of six
    assert sum(h < 0.03 for h in heights) >= 2  # rows only


def test_starts_need_unstacking_and_temporary_places(cubes):
    wrong_order = squatters = temporary = 0
    for inst in cubes.benchmark():
        goal = {r["id"]: r["pose"] for r in inst.goal["objects"]}
        goal_pairs = {
            (c[k], c[k + 1])
            for c in _columns(cubes, inst.goal["objects"])
            for k in range(len(c) - 1)
        }
        start_cols = [c for c in _columns(cubes, inst.start["objects"]) if len(c) > 1]
        wrong_order += any(
            (b, a) in goal_pairs for c in start_cols for a, b in itertools.pairwise(c)
        )
        for r in inst.start["objects"]:
            others = [g for i, g in goal.items() if i != r["id"] and g[2, 3] < 0.03]
            squatters += any(np.linalg.norm(g[:2, 3] - r["pose"][:2, 3]) < 0.015 for g in others)
        temporary += any(
            not np.allclose(s["target_pose"][:3, 3], goal[s["object"]][:3, 3]) for s in inst.order
        )
    assert wrong_order >= 15
    assert squatters >= 15
    assert temporary >= 20
