"""`Domain.compose` / `composed_instance`: the goals the plan checks meet beyond the generator's
catalogue (docs/checks.md, "Inputs, seeds and budgets")."""

from __future__ import annotations

import pytest

import domains


@pytest.mark.parametrize("name", ["cubes", "assembly"])
def test_composed_instances_carry_an_executable_order(name):
    """`Domain.composed_instance`: the plan checks' composed goals come with an order the
    robot's hand model accepts step by step; domains without a composer give none."""
    from benchmarks.compositions_bench import hand_problem
    from checks.inputs import composed

    domain = domains.load(name)
    got = composed(domain, tuple(range(1, 41)), 2)
    assert [i.name.split("/")[0] for i in got] == ["composed", "composed"]
    for inst in got:
        assert inst.order and hand_problem(domain, inst.start["objects"], inst.order) is None
    assert domains.load("tangram").composed_instance(1) is None
    assert composed(domains.load("tangram"), (1, 2, 3), 2) == []


def test_composed_cubes_goals_are_never_a_test_family():
    """The test split stays held out: a drawn structure shaped like a test family (turned,
    mirrored or shifted) gives no composed goal."""
    import numpy as np

    from domains.cubes import TEST_FAMILIES, TEST_SHAPES, shape_key, task_structure

    cubes = domains.load("cubes")
    ell = TEST_FAMILIES["ell"][0]
    turned = [(-j + 3, i - 1.5, lv) for i, j, lv in ell]  # a quarter turn and a shift
    assert shape_key(turned) in TEST_SHAPES
    assert shape_key([(i, -j, lv) for i, j, lv in ell]) in TEST_SHAPES  # mirrored
    test_shaped = [
        s
        for s in range(1, 41)
        if (c := task_structure(np.random.default_rng(s))) is not None
        and shape_key(c) in TEST_SHAPES
    ]
    assert test_shaped  # the draw does produce them ...
    assert all(cubes.compose(s) is None for s in test_shaped)  # ... and compose drops them
