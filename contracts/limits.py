"""How much of a program's answer anyone works on: counts checked before any geometry.

Design rule: a generated program's answer is judged (`checks`) and run (`artifacts.runtime`,
the trials) on the host, where work grows with the answer — pairs of records, edges compared
as multisets, plan steps executed by the robot. Its counts are therefore checked first, here
and only here, with nothing but `len()` and one pass over at most the limit's worth of items:

- records (what `perceive` returns): no more than the domain's catalogue holds objects (ids
  are unique and from the catalogue, so more cannot be right);
- a relation graph (what `relate` returns): no more nodes than objects; at most
  `MAX_RELATION_TYPES` edge types; at most types × n × (n − 1) edges for n objects; no edge
  twice (the same source, target, type and further attributes: tangram's `blocks` edges
  differ by their `axis` only, so the attributes count);
- a plan (what `plan` returns): no more steps than the plan contract's `maxItems`.

A value over a limit is a bad answer (the checks' ``bad_output`` verdict, the runtime's
failed program) with a one-line reason naming the count and the limit. `clip` bounds any text
that quotes an answer (error messages, reasons) to `CLIP_CHARS`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from functools import cache
from importlib import resources
from typing import Any

MAX_RELATION_TYPES = 16  # edge types in one graph (the domains' vocabularies hold 2 or 3)
CLIP_CHARS = 300  # [chars] of an answer quoted in a message


@cache
def plan_step_cap() -> int:
    """The most steps a plan may have: `maxItems` of `steps` in `plan.schema.json`."""
    schema = json.loads((resources.files("contracts") / "schemas" / "plan.schema.json").read_text())
    return int(schema["then"]["properties"]["steps"]["maxItems"])


def max_edges(objects: int, types: int) -> int:
    """The most edges a relation graph of `objects` objects with `types` edge types may have:
    one of each type per ordered pair of distinct objects."""
    return types * objects * max(objects - 1, 0)


def count_problem(function: str, value: Any, *, objects: int | None) -> str | None:
    """Why `value`, returned by the generated `function`, is over a count limit (one line), or
    None when it is within them (or is not the shape the limits read: the schema says so).

    Args:
        function: "perceive", "relate" or "plan" (any other: no limits).
        value: what the function returned (JSON-like; numpy arrays count by their first axis).
        objects: the domain's catalogue size; None: only the plan's cap is checked.
    """
    if function == "plan":
        return plan_problem(value)
    if objects is None:
        return None
    if function == "perceive":
        return records_problem(value, objects)
    if function == "relate":
        return relations_problem(value, objects)
    return None


def records_problem(records: Any, objects: int) -> str | None:
    """Records over the catalogue's size."""
    n = _length(records)
    if n is not None and n > objects:
        return f"{n} records, but the domain's catalogue holds {objects} objects"
    return None


def relations_problem(graph: Any, objects: int) -> str | None:
    """A relation graph over its node, type or edge limits, or with an edge twice."""
    if not isinstance(graph, Mapping):
        return None
    nodes, edges = _length(graph.get("nodes")), _length(graph.get("edges"))
    if nodes is not None and nodes > objects:
        return f"{nodes} nodes, but the domain's catalogue holds {objects} objects"
    if edges is None:
        return None
    most = max_edges(objects, MAX_RELATION_TYPES)
    if edges > most:
        return (
            f"{edges} edges, over the {most} that {MAX_RELATION_TYPES} edge types could give "
            f"{objects} objects (one per type and ordered pair)"
        )
    listed = list(graph["edges"])
    types = {str(e.get("type")) for e in listed if isinstance(e, Mapping)}
    if len(types) > MAX_RELATION_TYPES:
        return f"{len(types)} edge types in one graph, over the limit of {MAX_RELATION_TYPES}"
    allowed = max_edges(objects, len(types))
    if edges > allowed:
        return (
            f"{edges} edges, over the {allowed} that {len(types)} edge type(s) can give "
            f"{objects} objects (one per type and ordered pair)"
        )
    seen: dict[str, int] = {}
    for i, e in enumerate(listed):
        if not isinstance(e, Mapping):
            continue
        key = _edge_key(e)
        if key in seen:
            return clip(
                f"edges[{i}] repeats edges[{seen[key]}] ({e.get('source')!r} → "
                f"{e.get('target')!r}, type {e.get('type')!r}): an edge is listed once"
            )
        seen[key] = i
    return None


def plan_problem(plan: Any) -> str | None:
    """A plan with more steps than the contract's cap."""
    if not isinstance(plan, Mapping):
        return None
    n, cap = _length(plan.get("steps")), plan_step_cap()
    if n is not None and n > cap:
        return f"{n} plan steps, over the plan contract's cap of {cap}"
    return None


def clip(text: str, limit: int = CLIP_CHARS) -> str:
    """`text` cut to about `limit` characters, saying how many were cut."""
    text = str(text)
    if len(text) <= limit:
        return text
    return f"{text[:limit]}… ({len(text) - limit} chars cut)"


def _length(value: Any) -> int | None:
    """len() of a list, tuple or array (its first axis); None for anything else."""
    if isinstance(value, list | tuple):
        return len(value)
    shape = getattr(value, "shape", None)
    if isinstance(shape, tuple) and shape:
        return int(shape[0])
    return None


def _edge_key(edge: Mapping[str, Any]) -> str:
    """What makes an edge itself: every field but networkx's `key` (which only tells parallel
    edges apart)."""
    fields = {str(k): v for k, v in edge.items() if k != "key"}
    return json.dumps(fields, sort_keys=True, default=_plain)


def _plain(value: Any) -> Any:
    """The JSON form of an attribute json cannot write (arrays as lists: their repr elides)."""
    return value.tolist() if hasattr(value, "tolist") else repr(value)
