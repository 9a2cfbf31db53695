"""The four generated functions, declared once: names, signatures, and the DAG between them.

Design rule: the runtime, the authoring loop, the checks and the command line all read the
functions from here (DESIGN's table); nobody spells the list or the dependencies again.

- `CODE_DEPS`: whose frozen source a function's prompt carries and whose module its program
  may import (the checks load them beside the draft).
- `CONTRACT_DEPS`: whose output contract it consumes (described in the prompt, no code).
"""

from __future__ import annotations

from dataclasses import dataclass
from graphlib import TopologicalSorter


@dataclass(frozen=True, kw_only=True)
class Signature:
    """A generated function's contract: its parameters and what it returns."""

    name: str
    params: tuple[str, ...]
    returns: str

    def __str__(self) -> str:
        return f"{self.name}({', '.join(self.params)}) -> {self.returns}"


FUNCTIONS: tuple[str, ...] = ("render", "perceive", "relate", "plan")

SIGNATURES: dict[str, Signature] = {
    "render": Signature(
        name="render", params=("records", "meshes", "camera"), returns="{'rgb', 'depth', 'mask'}"
    ),
    "perceive": Signature(
        name="perceive", params=("observation", "meshes", "camera"), returns="records"
    ),
    "relate": Signature(name="relate", params=("records", "meshes"), returns="graph"),
    "plan": Signature(name="plan", params=("start_state", "goal_state", "meshes"), returns="plan"),
}

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
