"""A*/BFS: optimal on small graphs, budgets respected, states hashed by value."""

from __future__ import annotations

import time

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from toolbox.errors import ToolboxError
from toolbox.search import astar, bfs, state_key

PROPS = settings(max_examples=60, deadline=None, derandomize=True)

edges = st.lists(
    st.tuples(st.integers(0, 9), st.integers(0, 9), st.integers(1, 20)),
    min_size=1,
    max_size=40,
)


def digraph(edge_list):
    G = nx.DiGraph()
    G.add_nodes_from(range(10))
    for u, v, w in edge_list:
        if u != v and (not G.has_edge(u, v) or G[u][v]["weight"] > w):
            G.add_edge(u, v, weight=w)
    return G


@PROPS
@given(edges, st.integers(0, 9))
def test_astar_and_bfs_find_optimal_paths(edge_list, goal):
    G = digraph(edge_list)

    def weighted(n):
        return [((n, m), m, G[n][m]["weight"]) for m in sorted(G.successors(n))]

    a = astar(0, lambda n: n == goal, weighted)
    b = bfs(0, lambda n: n == goal, weighted)
    if nx.has_path(G, 0, goal):
        assert a.status == "found" and b.found
        assert a.cost == nx.shortest_path_length(G, 0, goal, weight="weight")
        assert b.cost == len(b.actions) == nx.shortest_path_length(G, 0, goal)
        assert a.states[0] == 0 and a.states[-1] == goal
        assert (
            sum(G[u][v]["weight"] for u, v in zip(a.states, a.states[1:], strict=False)) == a.cost
        )
    else:
        assert a.status == "exhausted" and b.status == "exhausted"
        assert not a.states and a.cost == float("inf")


def test_admissible_heuristic_keeps_optimality_and_expands_less():
    # 4-connected 30×30 grid with a wall; Manhattan distance is admissible.
    wall = {(15, y) for y in range(0, 25)}

    def succ(p):
        x, y = p
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            q = (x + dx, y + dy)
            if 0 <= q[0] < 30 and 0 <= q[1] < 30 and q not in wall:
                yield (dx, dy), q

    goal = (29, 0)
    plain = astar((0, 0), lambda p: p == goal, succ)
    guided = astar(
        (0, 0), lambda p: p == goal, succ, lambda p: abs(p[0] - goal[0]) + abs(p[1] - goal[1])
    )
    assert guided.cost == plain.cost == bfs((0, 0), lambda p: p == goal, succ).cost == 29 + 2 * 25
    assert guided.expanded < plain.expanded


def test_time_budget_and_expansion_limit_are_respected():
    calls: list[float] = []

    def endless(n):
        calls.append(time.monotonic())
        time.sleep(0.001)
        return [("+1", n + 1), ("+2", n + 2)]

    t0 = time.monotonic()
    r = astar(0, lambda n: False, endless, time_budget=0.2)
    assert r.status == "timeout" and r.elapsed >= 0.2
    # the budget is checked before every expansion: none starts once it is spent
    assert sum(t - t0 > 0.2 for t in calls) <= 1
    assert bfs(0, lambda n: False, endless, time_budget=0.1).status == "timeout"
    assert astar(0, lambda n: False, endless, max_expansions=5).expanded == 5


def test_dict_states_with_arrays_are_deduplicated_by_value():
    start = {"poses": {"a": np.eye(4)}, "held": None}

    def succ(s):
        T = s["poses"]["a"].copy()
        yield "noop", {"held": None, "poses": {"a": T + 1e-9}}  # same state up to noise
        if T[0, 3] < 3:
            T2 = T.copy()
            T2[0, 3] += 1
            yield "move", {"poses": {"a": T2}, "held": None}

    r = bfs(start, lambda s: s["poses"]["a"][0, 3] == 3, succ)
    assert r.found and r.actions == ["move"] * 3 and r.expanded == 3
    assert state_key({"x": [1.0, -0.0]}) == state_key({"x": (1.0000000001, 0.0)})
    with pytest.raises(ToolboxError, match="cannot hash"):
        state_key({"x": object.__new__(type("U", (), {"__hash__": None}))})


def test_bad_successors_are_reported():
    with pytest.raises(ToolboxError, match="negative step cost"):
        astar(0, lambda n: False, lambda n: [("x", n + 1, -1)])
    with pytest.raises(ToolboxError, match=r"\(action, state\[, cost\]\)"):
        bfs(0, lambda n: False, lambda n: [n + 1])
