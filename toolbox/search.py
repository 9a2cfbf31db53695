"""Graph search over planning states: A*, uniform-cost and breadth-first, with a time budget.

Design rule: the caller supplies states and a `successors(state)` function yielding
`(action, next_state, step_cost)` (or `(action, next_state)` for unit cost); the search never
mutates states, detects repeats through a hashable `key(state)` (default `state_key`), and
always returns a `SearchResult` whose `status` says whether a plan was found, the space was
exhausted (no plan exists), or the time/expansion budget ran out. Deterministic for
deterministic successors.
"""

from __future__ import annotations

import heapq
import itertools
import time
from collections import deque
from collections.abc import Callable, Hashable, Iterable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from toolbox.errors import ToolboxError

__all__ = ["SearchResult", "astar", "bfs", "state_key"]

Successors = Callable[[Any], Iterable[tuple]]


@dataclass(frozen=True, kw_only=True)
class SearchResult:
    """Outcome of a search.

    Attributes:
        status: "found"; "exhausted" (every reachable state seen: no plan exists); "timeout"
            (time_budget spent); "limit" (max_expansions reached).
        states: states from start to goal inclusive (empty unless found).
        actions: actions taken, len(states) - 1 of them.
        cost: total step cost of the plan (inf unless found).
        expanded: number of states expanded.
        elapsed: wall time [s].
    """

    status: Literal["found", "exhausted", "timeout", "limit"]
    states: list = field(default_factory=list)
    actions: list = field(default_factory=list)
    cost: float = float("inf")
    expanded: int = 0
    elapsed: float = 0.0

    @property
    def found(self) -> bool:
        return self.status == "found"


def state_key(state: Any, decimals: int = 6) -> Hashable:
    """A hashable, order-independent fingerprint of a state built from dicts, lists, tuples,
    sets, numpy arrays, numbers and strings; floats are rounded to `decimals` so that poses
    equal up to numerical noise give the same key."""
    if isinstance(state, dict):
        return ("d", tuple(sorted((str(k), state_key(v, decimals)) for k, v in state.items())))
    if isinstance(state, list | tuple):
        return ("l", tuple(state_key(v, decimals) for v in state))
    if isinstance(state, set | frozenset):
        return ("s", frozenset(state_key(v, decimals) for v in state))
    if isinstance(state, np.ndarray):
        a = np.round(state.astype(float), decimals) + 0.0 if state.dtype.kind == "f" else state
        return ("a", state.shape, tuple(a.reshape(-1).tolist()))
    if isinstance(state, float | np.floating):
        return round(float(state), decimals) + 0.0  # + 0.0 folds -0.0 into 0.0
    if isinstance(state, Hashable):
        return state
    raise ToolboxError(f"cannot hash a state part of type {type(state).__name__}; pass key=")


def astar(
    start: Any,
    is_goal: Callable[[Any], bool],
    successors: Successors,
    heuristic: Callable[[Any], float] | None = None,
    *,
    key: Callable[[Any], Hashable] = state_key,
    time_budget: float = 10.0,
    max_expansions: int = 1_000_000,
) -> SearchResult:
    """A* search for a cheapest plan from `start` to a state satisfying `is_goal`.

    Args:
        successors: state → iterable of (action, next_state, step_cost >= 0).
        heuristic: state → lower bound on the remaining cost; the plan is optimal when it
            never overestimates. None gives uniform-cost search (Dijkstra).
        key: state → hashable identity for duplicate detection.
        time_budget: wall-clock limit [s]; max_expansions: limit on expanded states.

    Returns:
        SearchResult (check `.found` / `.status`). Raises ToolboxError on a negative cost.
    """
    h = heuristic or (lambda _s: 0.0)
    t0 = time.monotonic()
    tie = itertools.count()
    k0 = key(start)
    best_g = {k0: 0.0}
    parent: dict[Hashable, tuple[Hashable, Any] | None] = {k0: None}
    states = {k0: start}
    frontier = [(h(start), next(tie), 0.0, k0)]
    expanded = 0
    while frontier:
        _, _, g, k = heapq.heappop(frontier)
        if g > best_g[k]:
            continue  # stale entry
        state = states[k]
        if is_goal(state):
            return _result("found", k, parent, states, g, expanded, t0)
        if time.monotonic() - t0 > time_budget:
            return _result("timeout", None, parent, states, g, expanded, t0)
        if expanded >= max_expansions:
            return _result("limit", None, parent, states, g, expanded, t0)
        expanded += 1
        for item in successors(state):
            action, nxt, cost = _unpack(item)
            if cost < 0:
                raise ToolboxError(f"negative step cost {cost} for action {action!r}")
            nk, ng = key(nxt), g + cost
            if ng < best_g.get(nk, float("inf")):
                best_g[nk], parent[nk], states[nk] = ng, (k, action), nxt
                heapq.heappush(frontier, (ng + h(nxt), next(tie), ng, nk))
    return _result("exhausted", None, parent, states, 0.0, expanded, t0)


def bfs(
    start: Any,
    is_goal: Callable[[Any], bool],
    successors: Successors,
    *,
    key: Callable[[Any], Hashable] = state_key,
    time_budget: float = 10.0,
    max_expansions: int = 1_000_000,
) -> SearchResult:
    """Breadth-first search: a plan with the fewest actions (step costs are ignored; `cost` is
    the number of actions). Arguments and result as in `astar`."""
    t0 = time.monotonic()
    k0 = key(start)
    parent: dict[Hashable, tuple[Hashable, Any] | None] = {k0: None}
    states = {k0: start}
    depth = {k0: 0}
    queue = deque([k0])
    expanded = 0
    while queue:
        k = queue.popleft()
        if is_goal(states[k]):
            return _result("found", k, parent, states, float(depth[k]), expanded, t0)
        if time.monotonic() - t0 > time_budget:
            return _result("timeout", None, parent, states, 0.0, expanded, t0)
        if expanded >= max_expansions:
            return _result("limit", None, parent, states, 0.0, expanded, t0)
        expanded += 1
        for item in successors(states[k]):
            action, nxt, _ = _unpack(item)
            nk = key(nxt)
            if nk not in parent:
                parent[nk], states[nk], depth[nk] = (k, action), nxt, depth[k] + 1
                queue.append(nk)
    return _result("exhausted", None, parent, states, 0.0, expanded, t0)


def _unpack(item: tuple) -> tuple[Any, Any, float]:
    if isinstance(item, tuple) and len(item) == 3:
        return item[0], item[1], float(item[2])
    if isinstance(item, tuple) and len(item) == 2:
        return item[0], item[1], 1.0
    raise ToolboxError(f"successors must yield (action, state[, cost]) tuples, got {item!r}")


def _result(status, goal_key, parent, states, cost, expanded, t0) -> SearchResult:
    elapsed = time.monotonic() - t0
    if goal_key is None:
        return SearchResult(status=status, expanded=expanded, elapsed=elapsed)
    keys, actions = [goal_key], []
    while parent[keys[-1]] is not None:
        prev, action = parent[keys[-1]]
        keys.append(prev)
        actions.append(action)
    return SearchResult(
        status=status,
        states=[states[k] for k in reversed(keys)],
        actions=actions[::-1],
        cost=cost,
        expanded=expanded,
        elapsed=elapsed,
    )
