"""Properties of the cubes domain: support in `relate`, gripper room in `plan`, physically
consistent states from `perceive`."""

from __future__ import annotations

import time
from collections import Counter
from typing import Any

import networkx as nx
import numpy as np

from contracts import se3
from contracts.checks.domain_properties import register
from contracts.checks.physics import body_separation, scene_problems
from contracts.checks.report import CheckResult
from contracts.checks.suite import SuiteContext
from contracts.checks.suites._common import edge_multiset, scene_spec

DOMAIN = "cubes"
TEMPORARY_GAP = 0.005  # a cube put down aside keeps this much room from the others [m]


def _support_edges(graph: Any, kind: str) -> set[tuple[str, str]]:
    return {(s, t) for (s, t, k) in edge_multiset(graph) if k == kind}


def _matching_type(ctx: SuiteContext) -> tuple[str | None, str | None, dict]:
    """The edge type of the draft whose edges are the reference support on every scene.

    Returns (matching type or None, best candidate type, details of the first mismatch).
    """
    from contracts.checks.suites.relate import relations_of

    scenes = ctx.cases["scenes"]
    results = []
    for sc in scenes:
        res = relations_of(ctx, sc["records"], f"scene {sc['name']}")
        if not res.ok or not isinstance(res.value, dict):
            return None, None, {}
        results.append(res.value)
    types = sorted({k for g in results for (_, _, k) in edge_multiset(g)})
    score: Counter = Counter()
    first_miss: dict[str, dict] = {}
    for sc, g in zip(scenes, results, strict=True):
        ref = _support_edges(sc["reference"], "on")
        for t in types:
            got = _support_edges(g, t)
            score[t] += len(ref & got) - len(ref ^ got)
            if got != ref and t not in first_miss:
                first_miss[t] = {
                    "scene": sc,
                    "expected": sorted(ref),
                    "actual": sorted(got),
                    "missing": sorted(ref - got),
                    "extra": sorted(got - ref),
                }
    exact = [t for t in types if t not in first_miss]
    if "on" in exact:
        return "on", "on", {}
    if exact:
        return exact[0], exact[0], {}
    best = max(types, key=lambda t: (score[t], t == "on")) if types else None
    return None, best, first_miss.get(best, {}) if best else {}


@register(DOMAIN, "relate")
def support_matches_geometry(ctx: SuiteContext) -> CheckResult:
    """Some declared edge type is exactly 'source rests on target' on every generated scene."""
    r = CheckResult(
        name="domain.cubes.support_matches_geometry",
        category="domain",
        expected="one edge type whose edges are exactly (upper cube → cube it rests on), e.g. "
        "'on'; a cube on two cubes has two such edges",
    )
    t0 = time.perf_counter()
    match, best, miss = _matching_type(ctx)
    r.examples = len(ctx.cases["scenes"])
    if match is None:
        if best is None:
            r.fail("relate returned no usable graphs, or no edges at all, on the generated scenes")
        else:
            sc = miss["scene"]
            reversed_ = sorted((t, s) for (s, t) in miss["actual"]) == miss["expected"]
            hint = (
                " (every edge points the wrong way: source must be the upper cube)"
                if reversed_
                else ""
            )
            r.fail(
                f"no edge type captures support; the closest, '{best}', differs on scene "
                f"{sc['name']}: missing {miss['missing']}, extra {miss['extra']}{hint}",
                expected=miss["expected"],
                actual=miss["actual"],
                counterexample=scene_spec(ctx.spec.name, sc["records"]),
            )
    r.duration_s = time.perf_counter() - t0
    return r


@register(DOMAIN, "relate")
def support_acyclic(ctx: SuiteContext) -> CheckResult:
    """The support edges form no cycle, and every raised cube rests on something."""
    from contracts.checks.suites.relate import relations_of

    r = CheckResult(
        name="domain.cubes.support_acyclic",
        category="domain",
        expected="support edges without cycles; every cube above the table rests on a cube",
    )
    _, kind, _ = _matching_type(ctx)
    kind = kind or "on"
    for sc in ctx.cases["scenes"]:
        res = relations_of(ctx, sc["records"], f"scene {sc['name']}")
        if not res.ok or not isinstance(res.value, dict):
            continue
        edges = _support_edges(res.value, kind)
        g = nx.DiGraph(list(edges))
        if not nx.is_directed_acyclic_graph(g):
            cycle = nx.find_cycle(g)
            return r.fail(
                f"the '{kind}' edges contain a cycle {cycle} on scene {sc['name']}",
                counterexample=scene_spec(ctx.spec.name, sc["records"]),
            )
        for rec in sc["records"]:
            z = float(np.asarray(rec["pose"])[2, 3])
            if z > 0.03 and not any(s == rec["id"] for (s, _) in edges):
                return r.fail(
                    f"'{rec['id']}' stands {1000 * z:.0f} mm up on scene {sc['name']} but has no "
                    f"'{kind}' edge to what it rests on",
                    counterexample=scene_spec(ctx.spec.name, sc["records"]),
                )
    r.examples = len(ctx.cases["scenes"])
    return r


@register(DOMAIN, "plan")
def temporary_places_clear(ctx: SuiteContext) -> CheckResult:
    """A cube put down anywhere but its goal keeps room for the gripper around it."""
    from contracts.checks.suites.plan import plan_of

    r = CheckResult(
        name="domain.cubes.temporary_places_clear",
        category="domain",
        expected=f"a cube put down aside is at least {TEMPORARY_GAP * 1000:.0f} mm from every "
        "other cube (the gripper's fingers must reach it later)",
    )
    spec = ctx.spec
    n = len(ctx.cases["instances"])
    for i in range(n):
        got = plan_of(ctx, (i, "as_generated", 0, 0))
        if got is None:
            continue
        res, (s, g, *_rest) = got
        if not res.ok or not isinstance(res.value, dict) or res.value.get("status") != "ok":
            continue
        goal = {o["id"]: np.asarray(o["pose"], float) for o in g}
        state = {o["id"]: dict(o, pose=np.asarray(o["pose"], float)) for o in s}
        for k, step in enumerate(res.value.get("steps", [])):
            oid = step["object"]
            if oid not in state:
                break
            T = se3.as_matrix(step["target_pose"])
            state[oid] = dict(state[oid], pose=T)
            syms = spec.symmetries.get(state[oid]["mesh"])
            if oid in goal and se3.within_tolerance(
                T, goal[oid], trans_tol=spec.trans_tol, symmetries=syms
            ):
                continue  # a goal placement may touch its neighbours
            body = spec.geometry.body(state[oid])
            for j, other in state.items():
                if j == oid:
                    continue
                gap, _ = body_separation(body, spec.geometry.body(other), cutoff=TEMPORARY_GAP)
                if gap < TEMPORARY_GAP:
                    return r.fail(
                        f"step {k} puts '{oid}' down aside only {max(gap, 0) * 1000:.1f} mm from "
                        f"'{j}' (instance {ctx.cases['instances'][i]['name']})",
                        actual=res.value["steps"][: k + 1],
                        counterexample={
                            "start": scene_spec(spec.name, s),
                            "goal": scene_spec(spec.name, g),
                        },
                    )
    r.examples = n
    return r


@register(DOMAIN, "perceive")
def physically_valid(ctx: SuiteContext) -> CheckResult:
    """The perceived cubes do not interpenetrate and each rests on the table or on cubes."""
    from contracts.checks.suites.perceive import perceived

    r = CheckResult(
        name="domain.cubes.physically_valid",
        category="domain",
        expected="perceived cubes that rest on the table or on each other, interpenetrating by "
        "at most 3 mm",
    )
    cases = ctx.cases["observations"]
    for i, case in enumerate(cases):
        res = perceived(ctx, i)
        if not res.ok or not isinstance(res.value, list):
            continue
        try:
            recs = [
                {"id": str(o["id"]), "mesh": str(o["mesh"]), "pose": se3.as_matrix(o["pose"])}
                for o in res.value
            ]
            problems = scene_problems(ctx.spec.geometry, recs, pen_tol=0.003, contact_tol=0.004)
        except (KeyError, TypeError, ValueError):
            continue  # the schema check reports malformed records
        if problems:
            return r.fail(
                f"the state perceived in {case['name']} is not physically possible: "
                + "; ".join(problems[:3]),
                actual=problems[:5],
                counterexample={"observation": case["name"], "scene": case["truth_scene"]},
            )
    r.examples = len(cases)
    return r
