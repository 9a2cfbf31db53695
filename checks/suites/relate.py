"""The `relate` suite: schema, declared vocabulary, determinism, order and translation invariance.

Scenes come from the domain's instance generator (starts and goals); the invariance properties
draw a scene, a record order or a horizontal translation with hypothesis and shrink towards
the first scene, the identity order and no translation.
"""

from __future__ import annotations

from typing import Any

from hypothesis import strategies as st

from checks.context import SuiteContext
from checks.hypo import Failure, run_property
from checks.registry import register, rules
from checks.report import CheckResult
from checks.rules import Rule
from checks.suites._common import (
    edge_multiset,
    first_difference,
    order_from_keys,
    order_keys,
    permuted,
    raise_first,
    raised,
    same_value,
    scene_spec,
    translated,
)
from contracts.errors import ContractError
from contracts.validate import validate
from sandbox import MESHES


def relations_of(ctx: SuiteContext, records: list[dict], label: str, derived: bool = False) -> Any:
    """relate(records) as a CallResult, cached by label for the checks that share inputs
    (`derived`: a scene already sent, reordered or moved; see `SuiteContext.call`)."""
    key = ("relate", label)
    if key not in ctx.cache:
        ctx.cache[key] = ctx.call(records, MESHES, label=label, derived=derived)
    return ctx.cache[key]


def _schema_problem(graph: Any, records: list[dict]) -> str:
    try:
        validate("relations", graph)
    except ContractError as e:
        return str(e)
    nodes = sorted(str(n["id"]) for n in graph["nodes"])
    ids = sorted(str(r["id"]) for r in records)
    if nodes != ids:
        return f"nodes must be exactly the record ids {ids}, got {nodes}"
    return ""


def _base(ctx: SuiteContext, i: int) -> Any:
    """relate() of the i-th scene as drawn (cached: every check starts from it)."""
    sc = ctx.cases["scenes"][i]
    return relations_of(ctx, sc["records"], f"scene {sc['name']}")


@register(
    "relate",
    "schema.output",
    rule=(
        '`relate` returns `networkx.node_link_data(G, edges="edges")` of a '
        "`networkx.MultiDiGraph` whose nodes are exactly the record ids and each of whose "
        "edges has a `type`."
    ),
    expected="networkx node-link JSON (edges='edges') of a directed multigraph whose "
    "nodes are the record ids, each edge with a 'type'",
)
def schema(ctx: SuiteContext, r: CheckResult) -> None:
    scenes, domain = ctx.cases["scenes"], ctx.spec.name
    found: list[Failure] = []
    for i, sc in enumerate(scenes):
        res = _base(ctx, i)
        ce = scene_spec(domain, sc["records"])
        if not res.ok:
            found.append(raised("relate(records)", res, ce))
            continue
        problem = _schema_problem(res.value, sc["records"])
        if problem:
            found.append(
                Failure(
                    message=f"the graph returned for scene {sc['name']} is not a relation "
                    f"graph: {problem}",
                    actual=problem,
                    counterexample=ce,
                )
            )
    r.examples = len(scenes)
    raise_first(r, found, "scenes")


@register(
    "relate",
    "property.relations_declared",
    rule="The module defines `RELATIONS`, a non-empty dict of strings {edge type: meaning}, "
    "and every edge type `relate` returns is one of its keys.",
)
def declared(ctx: SuiteContext, r: CheckResult) -> None:
    scenes, domain = ctx.cases["scenes"], ctx.spec.name
    got = ctx.draft.attribute("RELATIONS")
    rel = got.value if got.ok else None
    ctx.outputs["RELATIONS"] = rel
    if not isinstance(rel, dict) or not rel:
        raise Failure(
            message="the module must define RELATIONS: a non-empty dict {edge type: meaning}",
            actual=type(rel).__name__ if got.ok else f"not readable ({got.describe()})",
        )
    bad = [k for k, v in rel.items() if not isinstance(k, str) or not isinstance(v, str)]
    if bad:
        raise Failure(message=f"RELATIONS maps str to str; bad entries: {bad!r}")
    for i, sc in enumerate(scenes):
        res = _base(ctx, i)
        if not res.ok or _schema_problem(res.value, sc["records"]):
            continue
        types = sorted({t for (_, _, t) in edge_multiset(res.value)} - set(rel))
        if types:
            raise Failure(
                message=f"edge types {types} are not declared in RELATIONS ({sorted(rel)})",
                expected=sorted(rel),
                actual=types,
                counterexample=scene_spec(domain, sc["records"]),
            )
    r.examples = len(scenes)


@register(
    "relate",
    "property.deterministic",
    rule="Two calls on the same records return the same graph.",
)
def deterministic(ctx: SuiteContext, r: CheckResult) -> None:
    scenes, domain = ctx.cases["scenes"], ctx.spec.name
    n = min(len(scenes), ctx.examples("determinism"))
    for i in range(n):
        again = ctx.call(scenes[i]["records"], MESHES, label="again")
        first = _base(ctx, i)
        if not (first.ok and again.ok):
            continue
        if not same_value(first.value, again.value):
            raise Failure(
                message="relate gave two different graphs for the same records (at "
                f"{first_difference(first.value, again.value)})",
                counterexample=scene_spec(domain, scenes[i]["records"]),
            )
    r.examples = n


def _same_edges(ctx: SuiteContext, i: int, changed: list[dict], label: str, ce: dict) -> Any:
    """The first call that failed, or the edge multisets of the scene and its changed copy."""
    a = _base(ctx, i)
    b = relations_of(ctx, changed, label, derived=True)
    for res in (a, b):
        if not res.ok:
            return raised("relate(records)", res, ce)
    return edge_multiset(a.value), edge_multiset(b.value)


@register(
    "relate",
    "property.record_order_invariant",
    rule="The same records in another order give the same edges.",
    seeded=True,
    needs_schema=True,
)
def record_order_invariant(ctx: SuiteContext, r: CheckResult) -> None:
    scenes, domain = ctx.cases["scenes"], ctx.spec.name

    def prop(x: tuple) -> Failure | None:
        i, keys = x
        recs = scenes[i]["records"]
        order = order_from_keys(keys, len(recs))
        shuffled = permuted(recs, order)
        ce = {"scene": scene_spec(domain, shuffled), "order": [recs[k]["id"] for k in order]}
        got = _same_edges(ctx, i, shuffled, f"scene {scenes[i]['name']} order {order}", ce)
        if isinstance(got, Failure):
            return got
        ea, eb = got
        if ea != eb:
            return Failure(
                message="relate depends on the order of the records: the same scene with its "
                "records reordered gives other edges",
                expected=sorted(ea.elements()),
                actual=sorted(eb.elements()),
                counterexample=ce,
            )
        return None

    strategy = st.tuples(
        st.integers(0, len(scenes) - 1), order_keys(max(len(s["records"]) for s in scenes))
    )
    outcome = run_property(prop, strategy, max_examples=ctx.examples("order"), seed=ctx.seed)
    r.examples = outcome.examples
    if outcome.failure:
        raise outcome.failure


@register(
    "relate",
    "property.translation_invariant",
    rule=(
        "Moving every record by one common horizontal shift (up to "
        "{checks.budget:DEFAULT.translation_mm} mm along x and along y) gives the same edges."
    ),
    seeded=True,
    needs_schema=True,
)
def translation_invariant(ctx: SuiteContext, r: CheckResult) -> None:
    scenes, domain = ctx.cases["scenes"], ctx.spec.name

    def prop(x: tuple) -> Failure | None:
        i, dx, dy = x
        if dx == 0 and dy == 0:
            return None
        moved = translated(scenes[i]["records"], dx / 1000, dy / 1000)
        ce = {"scene": scene_spec(domain, moved), "translation_m": [dx / 1000, dy / 1000, 0.0]}
        label = f"scene {scenes[i]['name']} moved by ({dx}, {dy}) mm"
        got = _same_edges(ctx, i, moved, label, ce)
        if isinstance(got, Failure):
            return got
        ea, eb = got
        if ea != eb:
            return Failure(
                message=f"relate is not invariant to a common horizontal translation: moving "
                f"every record by ({dx}, {dy}) mm changes the edges",
                expected=sorted(ea.elements()),
                actual=sorted(eb.elements()),
                counterexample=ce,
            )
        return None

    reach = int(ctx.budget.translation_mm)
    strategy = st.tuples(
        st.integers(0, len(scenes) - 1), st.integers(-reach, reach), st.integers(-reach, reach)
    )
    outcome = run_property(
        prop,
        strategy,
        max_examples=ctx.examples("translation"),
        seed=ctx.seed,
        examples=[(0, 97, -61)],
    )
    r.examples = outcome.examples
    if outcome.failure:
        raise outcome.failure


RULES: tuple[Rule, ...] = rules("relate")
