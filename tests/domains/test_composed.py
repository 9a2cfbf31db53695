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
