"""The function DAG, declared once (DESIGN.md's table).

`CODE_DEPS`: whose frozen source a function's prompt carries and whose module its checks import.
`CONTRACT_DEPS`: whose output contract it consumes (described in the prompt, no code).
"""

from __future__ import annotations

from graphlib import TopologicalSorter

FUNCTIONS = ("render", "perceive", "relate", "plan")

CODE_DEPS: dict[str, tuple[str, ...]] = {
    "render": (),
    "perceive": ("render",),
    "relate": ("render",),
    "plan": ("relate",),
}
CONTRACT_DEPS: dict[str, tuple[str, ...]] = {
    "render": (),
    "perceive": (),
    "relate": ("perceive",),
    "plan": ("perceive",),
}

SIGNATURES = {
    "render": "render(records, meshes, camera) -> {'rgb', 'depth', 'mask'}",
    "perceive": "perceive(observation, meshes, camera) -> records",
    "relate": "relate(records, meshes) -> graph",
    "plan": "plan(start_state, goal_state) -> plan",
}


def dependencies(function: str) -> tuple[str, ...]:
    """Every function `function` depends on (code or contract), without duplicates."""
    return tuple(dict.fromkeys(CODE_DEPS[function] + CONTRACT_DEPS[function]))


def authoring_order() -> tuple[str, ...]:
    """The functions in a topological order of the DAG, ties broken by FUNCTIONS' order."""
    sorter = TopologicalSorter({f: dependencies(f) for f in FUNCTIONS})
    sorter.prepare()
    order: list[str] = []
    while sorter.is_active():
        ready = sorted(sorter.get_ready(), key=FUNCTIONS.index)
        order.extend(ready)
        sorter.done(*ready)
    return tuple(order)
