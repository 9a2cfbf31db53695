"""Count limits on what a program returns, and messages that quote an answer cut short
(issue 35, item 4)."""

from __future__ import annotations

import numpy as np
import pytest

from contracts import ContractError, validate
from contracts.limits import (
    CLIP_CHARS,
    MAX_RELATION_TYPES,
    clip,
    count_problem,
    max_edges,
    plan_step_cap,
)

EYE = np.eye(4).tolist()


def _records(n: int) -> list[dict]:
    return [{"id": f"o{i}", "mesh": "cube", "pose": np.eye(4)} for i in range(n)]


def _graph(n: int, edges: list[dict]) -> dict:
    return {
        "directed": True,
        "multigraph": True,
        "nodes": [{"id": f"o{i}"} for i in range(n)],
        "edges": edges,
    }


class Unread(list):
    """A list whose length may be taken but whose items must not be read: a limit that
    refuses on the count alone never touches them (an order, not a wall-clock window)."""

    def __iter__(self):
        raise AssertionError("an item was read")

    def __getitem__(self, index):
        raise AssertionError("an item was read")


def _plan(n: int) -> dict:
    return {"status": "ok", "steps": [{"object": "o0", "target_pose": np.eye(4)}] * n}


def test_the_plan_cap_is_the_plan_schemas():
    assert plan_step_cap() == 1000
    assert count_problem("plan", _plan(1000), objects=None) is None
    assert count_problem("plan", _plan(1001), objects=None) == (
        "1001 plan steps, over the plan contract's cap of 1000"
    )


def test_records_are_bounded_by_the_catalogue():
    assert count_problem("perceive", _records(6), objects=6) is None
    assert count_problem("perceive", _records(4000), objects=6) == (
        "4000 records, but the domain's catalogue holds 6 objects"
    )
    assert count_problem("perceive", _records(4000), objects=None) is None  # no catalogue


def test_edges_are_bounded_by_the_objects_and_their_types():
    every = [
        {"source": f"o{a}", "target": f"o{b}", "type": t}
        for t in ("on", "adjacent")
        for a in range(3)
        for b in range(3)
        if a != b
    ]
    assert len(every) == max_edges(3, 2) == 12
    assert count_problem("relate", _graph(3, every), objects=3) is None
    parallel = [{"source": "o0", "target": "o1", "type": "on", "k": k} for k in range(3)]
    assert count_problem("relate", _graph(2, parallel), objects=2) == (
        "3 edges, over the 2 that 1 edge type(s) can give 2 objects (one per type and ordered pair)"
    )
    many = [{"source": "o0", "target": "o1", "type": f"t{k}"} for k in range(17)]
    assert count_problem("relate", _graph(3, many), objects=3) == (
        "17 edge types in one graph, over the limit of 16"
    )
    flood = Unread([{"source": "o0", "target": "o1", "type": "on"}] * 200_000)
    problem = count_problem("relate", _graph(3, flood), objects=3)  # len() first: none read
    assert problem == (
        f"200000 edges, over the {max_edges(3, MAX_RELATION_TYPES)} that 16 edge types could "
        "give 3 objects (one per type and ordered pair)"
    )
    assert "4 nodes, but the domain's catalogue holds 3" in count_problem(
        "relate", _graph(4, []), objects=3
    )


def test_an_edge_listed_twice_is_refused_but_edges_that_differ_by_an_attribute_are_not():
    twice = [
        {"source": "o0", "target": "o1", "type": "on", "key": 0},
        {"source": "o0", "target": "o1", "type": "on", "key": 1},
    ]
    assert count_problem("relate", _graph(2, twice), objects=2) == (
        "edges[1] repeats edges[0] ('o0' → 'o1', type 'on'): an edge is listed once"
    )
    # tangram: a knob blocked along both axes is two `blocks` edges, told apart by `axis`
    axes = [{"source": "o0", "target": "o1", "type": "blocks", "axis": a} for a in "xy"]
    assert count_problem("relate", _graph(3, axes), objects=3) is None
    assert "edges[2] repeats edges[0]" in count_problem(
        "relate", _graph(3, [*axes, dict(axes[0])]), objects=3
    )


@pytest.mark.parametrize("value", [None, 3, "x", {"steps": "many"}, {"nodes": 5}])
def test_values_of_another_shape_are_left_to_the_schema(value):
    for function in ("perceive", "relate", "plan"):
        assert count_problem(function, value, objects=2) is None


def test_clip_says_how_much_it_cut():
    assert clip("short") == "short"
    cut = clip("x" * 10_000)
    assert cut == "x" * CLIP_CHARS + f"… ({10_000 - CLIP_CHARS} chars cut)"


def test_a_plan_over_the_cap_fails_validation_at_once_with_a_short_message():
    plan = _plan(40_000)
    plan["steps"] = Unread(plan["steps"])  # refused on its length: no step is read
    with pytest.raises(ContractError) as info:
        validate("plan", plan)
    assert str(info.value) == "plan: steps: 40000 plan steps, over the plan contract's cap of 1000"


def test_contract_errors_quoting_a_huge_value_are_cut():
    with pytest.raises(ContractError) as info:
        validate("plan", {"status": "maybe" * 100_000})
    assert len(str(info.value)) < 2 * CLIP_CHARS and "chars cut)" in str(info.value)
    with pytest.raises(ContractError) as info:
        validate(
            "camera", {"width": 1, "height": 1, "K": [[1, 0, 0]] * 5000, "T_world_camera": EYE}
        )
    assert "has 5000 items, where at most 3 belong" in str(info.value)
