"""The library of domain properties (see `checks.properties`): one function per property.

Each is ``(ctx: SuiteContext, **params) -> CheckResult`` with category "domain"; it reads the
draft's results the generic suite already obtained (cached in the context) and calls the draft
only for what it alone needs. Geometry is the oracle's (`geometry`), ground truth the cases'.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any

import networkx as nx
import numpy as np

from checks.context import SuiteContext
from checks.report import CheckResult
from checks.suites._common import edge_multiset, scene_spec
from contracts import se3
from geometry import body_separation, scene_problems, supports

LIBRARY: dict[str, Callable[..., CheckResult]] = {}
YAW_ONLY_TOL = np.radians(3.0)  # a turn about the vertical, within this tilt [rad]
RAISED = 0.002  # [m] an object whose lowest point is higher than this stands on something
GOAL_OVERLAP = 0.001  # [m] deepest overlap of a temporary place with a pending goal place


def _register(fn: Callable[..., CheckResult] | None = None, *, rule: str = "") -> Any:
    """Add a property to the library: ``@_register(rule=...)``, where `rule` states what it
    enforces for the model, numbers as placeholders (`checks.rules`: ``{params.gap|mm}``)."""

    def add(f: Callable[..., CheckResult]) -> Callable[..., CheckResult]:
        f.rule = rule  # type: ignore[attr-defined]
        LIBRARY[f.__name__] = f
        return f

    return add(fn) if fn is not None else add


def _result(name: str, expected: str) -> CheckResult:
    return CheckResult(name=f"domain.{name}", category="domain", expected=expected)


# -- relate -------------------------------------------------------------------------------------


def _typed_edges(graph: Any, kind: str) -> set[tuple[str, str]]:
    return {(s, t) for (s, t, k) in edge_multiset(graph) if k == kind}


def _graphs(ctx: SuiteContext) -> list[dict] | None:
    from checks.suites.relate import relations_of

    out = []
    for sc in ctx.cases["scenes"]:
        res = relations_of(ctx, sc["records"], f"scene {sc['name']}")
        if not res.ok or not isinstance(res.value, dict):
            return None
        out.append(res.value)
    return out


def _matching_type(ctx: SuiteContext, kind: str) -> tuple[str | None, str | None, dict]:
    """The draft's edge type whose edges are the reference's `kind` edges on every scene.

    Returns (matching type or None, best candidate type, details of the first mismatch).
    """
    key = ("matching_type", kind)
    if key in ctx.cache:
        return ctx.cache[key]
    graphs = _graphs(ctx)
    if graphs is None:
        ctx.cache[key] = (None, None, {})
        return ctx.cache[key]
    types = sorted({k for g in graphs for (_, _, k) in edge_multiset(g)})
    score: Counter = Counter()
    misses: Counter = Counter()  # scenes on which a type differs from the reference
    first_miss: dict[str, dict] = {}
    for sc, g in zip(ctx.cases["scenes"], graphs, strict=True):
        ref = _typed_edges(sc["reference"], kind)
        for t in types:
            got = _typed_edges(g, t)
            score[t] += len(ref & got) - len(ref ^ got)
            misses[t] += got != ref
            if got != ref and t not in first_miss:
                first_miss[t] = {
                    "scene": sc,
                    "expected": sorted(ref),
                    "actual": sorted(got),
                    "missing": sorted(ref - got),
                    "extra": sorted(got - ref),
                }
    exact = [t for t in types if t not in first_miss]
    if kind in exact:
        found: tuple = (kind, kind, {})
    elif exact:
        found = (exact[0], exact[0], {})
    else:
        best = max(types, key=lambda t: (score[t], t == kind)) if types else None
        found = (None, best, {**first_miss[best], "scenes": misses[best]} if best else {})
    ctx.cache[key] = found
    return found


@_register(
    rule=(
        "One edge type of your `RELATIONS` has, on every checked scene, exactly the edges "
        "{params.meaning}: the domain's reference `{params.kind}` edges (see the relations "
        "in the domain section), for example by calling it `{params.kind}`."
    )
)
def relations_match_geometry(ctx: SuiteContext, kind: str, meaning: str) -> CheckResult:
    """Some declared edge type is exactly the reference's `kind` edges on every scene."""
    r = _result(
        "relations_match_geometry",
        f"one edge type whose edges are exactly {meaning} (the reference's '{kind}' edges), "
        f"e.g. '{kind}'",
    )
    match, best, miss = _matching_type(ctx, kind)
    r.examples = len(ctx.cases["scenes"])
    if match is not None:
        return r
    if best is None:
        return r.fail("relate returned no usable graphs, or no edges at all, on the scenes")
    sc = miss["scene"]
    reversed_ = sorted((t, s) for (s, t) in miss["actual"]) == miss["expected"]
    hint = " (every edge points the wrong way round)" if reversed_ else ""
    return r.fail(
        f"no edge type captures {meaning}; the closest, '{best}', differs on scene {sc['name']}: "
        f"missing {miss['missing']}, extra {miss['extra']}{hint}",
        expected=miss["expected"],
        actual=miss["actual"],
        counterexample=scene_spec(ctx.spec.name, sc["records"]),
        failures=miss["scenes"],
    )


@_register(
    rule=(
        "The support edges (of the type that matches the reference's support relation) form "
        "no cycle, and every object whose lowest point is more than "
        "{checks.properties.library:RAISED|mm} above the table has one to what it rests on."
    )
)
def support_acyclic(ctx: SuiteContext, kind: str = "on") -> CheckResult:
    """The support edges form no cycle, and every object off the table rests on something."""
    from checks.suites.relate import relations_of

    r = _result(
        "support_acyclic",
        "support edges without cycles; every object that does not touch the table rests on one",
    )
    _, found, _ = _matching_type(ctx, kind)
    found = found or kind
    for sc in ctx.cases["scenes"]:
        res = relations_of(ctx, sc["records"], f"scene {sc['name']}")
        if not res.ok or not isinstance(res.value, dict):
            continue
        edges = _typed_edges(res.value, found)
        g = nx.DiGraph(list(edges))
        if not nx.is_directed_acyclic_graph(g):
            cycle = nx.find_cycle(g)
            return r.fail(
                f"the '{found}' edges contain a cycle {cycle} on scene {sc['name']}",
                counterexample=scene_spec(ctx.spec.name, sc["records"]),
            )
        for body in ctx.spec.geometry.bodies(sc["records"]):
            if body.lowest > RAISED and not any(s == body.id for (s, _) in edges):
                return r.fail(
                    f"'{body.id}' stands {1000 * body.lowest:.0f} mm above the table on scene "
                    f"{sc['name']} but has no '{found}' edge to what it rests on",
                    counterexample=scene_spec(ctx.spec.name, sc["records"]),
                )
    r.examples = len(ctx.cases["scenes"])
    return r


# -- plan ---------------------------------------------------------------------------------------


def _plans(ctx: SuiteContext):
    """(instance, start, goal, steps) for every instance whose plan came back ok."""
    from checks.suites.plan import plan_of

    for i, inst in enumerate(ctx.cases["instances"]):
        got = plan_of(ctx, (i, "as_generated", 0, 0))
        if got is None:
            continue
        res, (s, g, *_rest) = got
        if not res.ok or not isinstance(res.value, dict) or res.value.get("status") != "ok":
            continue
        steps = res.value.get("steps")
        if isinstance(steps, list):
            yield inst, s, g, steps


def _states(start: list[dict], steps: list) -> list[tuple[int, Any, dict[str, dict]]]:
    """(step, moved object, state after it) for the steps that name known objects."""
    state = {o["id"]: dict(o, pose=np.asarray(o["pose"], float)) for o in start}
    out = []
    for k, step in enumerate(steps):
        oid = step.get("object") if isinstance(step, dict) else None
        if oid not in state:
            break
        try:
            T = se3.as_matrix(step["target_pose"])
        except (KeyError, TypeError, ValueError):
            break
        state = {**state, oid: dict(state[oid], pose=T)}
        out.append((k, oid, state))
    return out


def _at_goal(ctx: SuiteContext, record: dict, goal: dict[str, np.ndarray]) -> bool:
    oid = record["id"]
    return oid in goal and se3.within_tolerance(
        record["pose"],
        goal[oid],
        trans_tol=ctx.spec.trans_tol,
        rot_tol=ctx.spec.rot_tol,
        symmetries=ctx.spec.symmetries.get(record["mesh"]),
    )


def _plan_failure(r: CheckResult, ctx: SuiteContext, inst, s, g, steps, k, message) -> CheckResult:
    from checks.suites._plan_view import step_picture

    _, pictures = step_picture(
        ctx, s, steps, k, name=f"{r.name}_{inst['name']}", what=f"{r.name} on {inst['name']}"
    )
    return r.fail(
        f"step {k}: {message} (instance {inst['name']})",
        actual=steps[: k + 1],
        counterexample={
            "start": scene_spec(ctx.spec.name, s),
            "goal": scene_spec(ctx.spec.name, g),
        },
        images=pictures,
    )


@_register(
    rule=(
        "An object put down anywhere but its goal pose stays at least {params.gap|mm} from "
        "every other object (the fingers must reach it again)."
    )
)
def temporary_places_clear(ctx: SuiteContext, gap: float) -> CheckResult:
    """An object put down anywhere but its goal keeps `gap` [m] from every other object."""
    r = _result(
        "temporary_places_clear",
        f"an object put down aside is at least {gap * 1000:.0f} mm from every other (the fingers "
        "must reach it later)",
    )
    n = 0
    for inst, s, g, steps in _plans(ctx):
        n += 1
        goal = {o["id"]: np.asarray(o["pose"], float) for o in g}
        for k, oid, state in _states(s, steps):
            if _at_goal(ctx, state[oid], goal):
                continue  # a goal placement may touch its neighbours
            body = ctx.spec.geometry.body(state[oid])
            for j, other in state.items():
                if j == oid:
                    continue
                d, _ = body_separation(body, ctx.spec.geometry.body(other), cutoff=gap)
                if d < gap:
                    return _plan_failure(
                        r, ctx, inst, s, g, steps, k,
                        f"puts '{oid}' down aside only {max(d, 0) * 1000:.1f} mm from '{j}'",
                    )  # fmt: skip
    r.examples = n
    return r


@_register(
    rule=(
        "Every step's target pose is the object's current pose turned about the vertical "
        "only (tilted by at most {checks.properties.library:YAW_ONLY_TOL|deg}, modulo its "
        "symmetry)."
    )
)
def turns_about_vertical(ctx: SuiteContext) -> CheckResult:
    """Every step turns its object about the vertical only (top-down grasps keep its tilt)."""
    r = _result(
        "turns_about_vertical",
        "each target pose is the object's current pose turned about the vertical (modulo its "
        f"symmetry), within {np.degrees(YAW_ONLY_TOL):.0f}°",
    )
    n = 0
    for inst, s, g, steps in _plans(ctx):
        n += 1
        before = {o["id"]: np.asarray(o["pose"], float) for o in s}
        for k, oid, state in _states(s, steps):
            R_from, R_to = before[oid][:3, :3], state[oid]["pose"][:3, :3]
            syms = ctx.spec.symmetries.get(state[oid]["mesh"], [np.eye(4)])
            tilt = min(
                float(np.arccos(np.clip((R_to @ S[:3, :3] @ R_from.T)[2, 2], -1, 1))) for S in syms
            )
            if tilt > YAW_ONLY_TOL:
                return _plan_failure(
                    r, ctx, inst, s, g, steps, k,
                    f"tilts '{oid}' by {np.degrees(tilt):.1f}° (a top-down grasp can only turn "
                    "it about the vertical)",
                )  # fmt: skip
            before[oid] = state[oid]["pose"]
    r.examples = n
    return r


@_register(
    rule=(
        "After every step each object rests on the table alone: no object ever goes on top "
        "of another."
    )
)
def no_stacking(ctx: SuiteContext) -> CheckResult:
    """No object ever rests on another: every state lies flat on the table."""
    r = _result("no_stacking", "after every step each object rests on the table alone")
    n = 0
    for inst, s, g, steps in _plans(ctx):
        n += 1
        for k, _oid, state in _states(s, steps):
            sup = supports(list(state.values()), ctx.spec.geometry)
            for who, on in sup.items():
                others = [x for x in on if x != "table"]
                if others:
                    return _plan_failure(
                        r, ctx, inst, s, g, steps, k,
                        f"puts '{who}' on {others} (pieces never go on top of each other)",
                    )  # fmt: skip
    r.examples = n
    return r


@_register(
    rule=(
        "An object put down anywhere but its goal never overlaps, by more than "
        "{checks.properties.library:GOAL_OVERLAP|mm}, the goal place of an object not yet "
        "there."
    )
)
def temporary_clear_of_goals(ctx: SuiteContext) -> CheckResult:
    """An object put down aside never takes the goal place of an object still to be placed."""
    r = _result(
        "temporary_clear_of_goals",
        "an object put down anywhere but its goal does not overlap the goal place of any object "
        "not yet there",
    )
    n = 0
    geometry = ctx.spec.geometry
    for inst, s, g, steps in _plans(ctx):
        n += 1
        goal = {o["id"]: np.asarray(o["pose"], float) for o in g}
        meshes = {o["id"]: o["mesh"] for o in g}
        for k, oid, state in _states(s, steps):
            if _at_goal(ctx, state[oid], goal):
                continue
            body = geometry.body(state[oid])
            for j, T in goal.items():
                if j == oid or _at_goal(ctx, state[j], goal):
                    continue
                d, _ = body_separation(
                    body, geometry.body({"id": j, "mesh": meshes[j], "pose": T}), cutoff=0.0
                )
                if d < -GOAL_OVERLAP:
                    return _plan_failure(
                        r, ctx, inst, s, g, steps, k,
                        f"puts '{oid}' down aside where '{j}' must go ({-d * 1000:.0f} mm into "
                        "its goal place)",
                    )  # fmt: skip
    r.examples = n
    return r


# -- perceive -----------------------------------------------------------------------------------


def _perceived(ctx: SuiteContext):
    """(case, records) for every observation whose records passed the schema."""
    perceived = ctx.outputs.get("perceived", {})
    for case in ctx.cases["observations"]:
        recs = perceived.get(case["name"])
        if recs is not None:
            yield case, recs


@_register(
    rule=(
        "The perceived objects form a state that could stand: they interpenetrate by at "
        "most {params.penetration|mm}, and each rests on the table or on others (gap at "
        "most {params.contact|mm}) with its centre of mass over its support."
    )
)
def physically_valid(ctx: SuiteContext, penetration: float, contact: float) -> CheckResult:
    """The perceived objects do not interpenetrate and each rests on the table or on others."""
    from checks.suites.perceive import where

    r = _result(
        "physically_valid",
        f"perceived objects that rest on the table or on each other (within "
        f"{contact * 1000:.0f} mm), interpenetrating by at most {penetration * 1000:.0f} mm, "
        "each with its centre of mass over its support",
    )
    n = 0
    for case, recs in _perceived(ctx):
        n += 1
        known = [o for o in recs if o["mesh"] in ctx.spec.geometry]
        problems = scene_problems(
            known, ctx.spec.geometry, penetration=penetration, contact=contact
        )
        if problems:
            return r.fail(
                f"the state perceived in {case['name']} is not physically possible: "
                + "; ".join(problems[:3]),
                actual=problems[:5],
                counterexample=where(ctx, case),
            )
    r.examples = n
    return r


@_register(
    rule=(
        "Every perceived object stands in its canonical resting pose, turned only about the "
        "vertical: its up axis within {params.tolerance_deg}° of the vertical, modulo its "
        "symmetry."
    )
)
def upright(ctx: SuiteContext, tolerance_deg: float) -> CheckResult:
    """Every perceived object stands in its canonical resting pose (turned about the vertical,
    modulo its symmetry): flat pieces lie flat, nothing is mirrored or on its side."""
    from checks.suites.perceive import where

    tol = np.radians(tolerance_deg)
    r = _result(
        "upright",
        f"each perceived object's up axis within {tolerance_deg:g}° of the vertical (modulo its "
        "symmetry)",
    )
    n = 0
    for case, recs in _perceived(ctx):
        n += 1
        for o in recs:
            R = np.asarray(o["pose"], float)[:3, :3]
            syms = ctx.spec.symmetries.get(o["mesh"], [np.eye(4)])
            tilt = min(float(np.arccos(np.clip((R @ S[:3, :3])[2, 2], -1, 1))) for S in syms)
            if tilt > tol:
                return r.fail(
                    f"'{o['id']}' is perceived tilted by {np.degrees(tilt):.0f}° in {case['name']}",
                    counterexample=where(ctx, case),
                )
    r.examples = n
    return r


@_register(
    rule=(
        "Objects of the same shape keep their own ids: each record of such an object lies on "
        "the object of that id, not on another of its shape (it is nearer its own object's "
        "place than any other's of that shape)."
    )
)
def ids_follow_the_image(ctx: SuiteContext) -> CheckResult:
    """Objects of the same shape keep their own ids: each perceived record of such an object
    is nearer (its centre to the true centre) its own object than any other object of its
    shape. (Judged on the true scene rather than by projecting into the image, which from an
    oblique camera lands a low piece's centre on a neighbour that hides part of it.)"""
    from checks.suites.perceive import where

    r = _result(
        "ids_follow_the_image",
        "a perceived object of a shape several objects share lies on that object, not on "
        "another of its shape",
    )
    same_shape = {
        oid
        for oid, mesh in ctx.spec.catalogue.items()
        if sum(m == mesh for m in ctx.spec.catalogue.values()) > 1
    }
    n = 0
    for case, recs in _perceived(ctx):
        n += 1
        truth = {o["id"]: ctx.spec.geometry.body(o).com for o in case["truth"]}
        for o in recs:
            if o["id"] not in same_shape or o["id"] not in truth:
                continue
            centre = ctx.spec.geometry.body(o).com
            own = float(np.linalg.norm(centre - truth[o["id"]]))
            for other, c in truth.items():
                if other == o["id"] or ctx.spec.catalogue.get(other) != o["mesh"]:
                    continue
                if float(np.linalg.norm(centre - c)) < own:
                    return r.fail(
                        f"'{o['id']}' is perceived where '{other}' is (same shape, other "
                        f"object) in {case['name']}",
                        counterexample=where(ctx, case),
                    )
    r.examples = n
    return r


# -- tangram and assembly: handedness, footprints, resting poses, building order, loads ---------


def _mirrored(R: np.ndarray) -> bool:
    """Whether an orientation shows the object's mirror image seen from above: the object's
    x and y axes, projected on the table, turn the other way round (a flat piece turned over,
    or an improper rotation)."""
    return float(np.linalg.det(np.asarray(R, float)[:2, :2])) < 0


@_register(
    rule=(
        "A {params.meshes|names} is never mirrored: every perceived pose of it shows it from "
        "above the way round the scene holds it, and every target pose a plan gives it keeps "
        "the handedness of its start pose (turned over it would show its mirror image, which "
        "no turn about the vertical undoes)."
    )
)
def never_mirrored(ctx: SuiteContext, meshes: list[str]) -> CheckResult:
    """A chiral piece (its mirror image is another shape) keeps its handedness: perceived
    the way round the image shows it, and moved by turns about the vertical only."""
    from checks.suites.perceive import where

    r = _result(
        "never_mirrored",
        f"every {', '.join(meshes)} shown from above the way round it lies (never turned over)",
    )
    chiral = set(meshes)
    n = 0
    if ctx.function == "perceive":
        for case, recs in _perceived(ctx):
            n += 1
            truth = {o["id"]: np.asarray(o["pose"], float) for o in case["truth"]}
            for o in recs:
                if o["mesh"] not in chiral:
                    continue
                R = np.asarray(o["pose"], float)[:3, :3]
                true = truth.get(o["id"])
                expected = _mirrored(true[:3, :3]) if true is not None else False
                if _mirrored(R) != expected:
                    up = float(np.degrees(np.arccos(np.clip(R[2, 2], -1, 1))))
                    return r.fail(
                        f"'{o['id']}' ({o['mesh']}) is perceived mirrored in {case['name']}: its "
                        f"up axis is {up:.0f}° from the vertical (det of its pose's x-y block "
                        f"{np.linalg.det(R[:2, :2]):+.2f}), so seen from above it is the mirror "
                        "image of the piece in the image",
                        actual={"id": o["id"], "pose": o["pose"]},
                        counterexample=where(ctx, case),
                    )
    else:
        for inst, s, g, steps in _plans(ctx):
            n += 1
            start = {o["id"]: _mirrored(np.asarray(o["pose"], float)[:3, :3]) for o in s}
            for k, oid, state in _states(s, steps):
                if state[oid]["mesh"] not in chiral:
                    continue
                R = state[oid]["pose"][:3, :3]
                if _mirrored(R) != start[oid]:
                    up = float(np.degrees(np.arccos(np.clip(R[2, 2], -1, 1))))
                    return _plan_failure(
                        r, ctx, inst, s, g, steps, k,
                        f"puts '{oid}' ({state[oid]['mesh']}) down mirrored: its up axis "
                        f"{up:.0f}° from the vertical, the other way round than at the start "
                        "(a top-down grasp only turns it about the vertical)",
                    )  # fmt: skip
    r.examples = n
    return r


@_register(
    rule=(
        "No two perceived objects overlap seen from above: laid flat on the table, any two "
        "interpenetrate by at most {params.penetration|mm} (pieces lie side by side, never "
        "on or in each other)."
    )
)
def no_overlap(ctx: SuiteContext, penetration: float) -> CheckResult:
    """The perceived objects' footprints do not overlap: each laid on the table (its lowest
    point at z = 0), no two interpenetrate by more than `penetration` [m]."""
    from checks.suites.perceive import where
    from geometry import collisions

    r = _result(
        "no_overlap",
        f"perceived footprints overlapping by at most {penetration * 1000:.0f} mm (laid flat)",
    )
    geometry = ctx.spec.geometry
    n = 0
    for case, recs in _perceived(ctx):
        n += 1
        flat = []
        for o in recs:
            if o["mesh"] not in geometry:
                continue
            T = np.array(o["pose"], float)
            T[2, 3] -= geometry.body(o).lowest
            flat.append({"id": o["id"], "mesh": o["mesh"], "pose": T})
        hits = [h for h in collisions(flat, geometry, tolerance=penetration) if h[1] != "table"]
        if hits:
            a, b, depth = max(hits, key=lambda h: h[2])
            z = {o["id"]: geometry.body(o).lowest for o in recs if o["mesh"] in geometry}
            return r.fail(
                f"'{a}' and '{b}' are perceived overlapping in {case['name']}: seen from above "
                f"their footprints overlap by {depth * 1000:.1f} mm (more than "
                f"{penetration * 1000:.0f} mm; their lowest points at {z[a] * 1000:.0f} and "
                f"{z[b] * 1000:.0f} mm)",
                actual=[{"a": x, "b": y, "overlap_mm": round(d * 1000, 1)} for x, y, d in hits[:5]],
                counterexample=where(ctx, case),
            )
    r.examples = n
    return r


def _resting_ups(ctx: SuiteContext, mesh: str) -> list[np.ndarray]:
    """The object-frame directions that point up in each of a shape's resting poses."""
    key = ("resting_ups", mesh)
    if key not in ctx.cache:
        from geometry import stable_poses

        rests = stable_poses(ctx.spec.geometry[mesh])
        ctx.cache[key] = [p.rotation.T @ np.array([0.0, 0.0, 1.0]) for p in rests] or [
            np.array([0.0, 0.0, 1.0])
        ]
    return ctx.cache[key]


@_register(
    rule=(
        "Every perceived object is in one of its resting poses (a face of its hull it can "
        "stand on, down), turned only about the vertical: its up axis within "
        "{params.tolerance_deg}° of a resting pose's."
    )
)
def resting_pose(ctx: SuiteContext, tolerance_deg: float) -> CheckResult:
    """Every perceived object rests on one of its stable faces (`geometry.stable_poses`),
    turned about the vertical: a part perceived on an edge or a corner could not stand so."""
    from checks.suites.perceive import where

    tol = np.radians(tolerance_deg)
    r = _result(
        "resting_pose",
        f"each perceived object within {tolerance_deg:g}° of one of its resting poses (turned "
        "about the vertical)",
    )
    geometry = ctx.spec.geometry
    n = 0
    for case, recs in _perceived(ctx):
        n += 1
        for o in recs:
            if o["mesh"] not in geometry:
                continue
            up = np.asarray(o["pose"], float)[:3, :3].T @ np.array([0.0, 0.0, 1.0])
            tilt = min(
                float(np.arccos(np.clip(up @ u, -1.0, 1.0))) for u in _resting_ups(ctx, o["mesh"])
            )
            if tilt > tol:
                return r.fail(
                    f"'{o['id']}' ({o['mesh']}) is perceived {np.degrees(tilt):.0f}° away from "
                    f"every resting pose in {case['name']} (more than {tolerance_deg:g}°): it "
                    "could not stand so",
                    actual={"id": o["id"], "pose": o["pose"]},
                    counterexample=where(ctx, case),
                )
    r.examples = n
    return r


@_register(
    rule=(
        "A plan puts an object at its goal pose only once every object it rests on in the "
        "goal is at its own goal pose (within {domain.tolerance.translation|mm}[? and "
        "{domain.tolerance.rotation|deg}?]): supporters before the parts they carry."
    )
)
def supporters_first(ctx: SuiteContext) -> CheckResult:
    """Supporters before the parts they carry: when a step puts an object at its goal pose,
    every object it rests on in the goal (the oracle's support, `geometry.supports`) is at its
    goal pose already."""
    from geometry import supports

    r = _result(
        "supporters_first",
        "an object goes to its goal only after every object it rests on in the goal is there",
    )
    geometry = ctx.spec.geometry
    n = 0
    for inst, s, g, steps in _plans(ctx):
        n += 1
        goal = {o["id"]: np.asarray(o["pose"], float) for o in g}
        carried_by = {i: [j for j in on if j != "table"] for i, on in supports(g, geometry).items()}
        for k, oid, state in _states(s, steps):
            if not _at_goal(ctx, state[oid], goal):
                continue
            early = [j for j in carried_by.get(oid, []) if not _at_goal(ctx, state[j], goal)]
            if early:
                j = early[0]
                far = float(np.linalg.norm(state[j]["pose"][:3, 3] - goal[j][:3, 3]))
                return _plan_failure(
                    r, ctx, inst, s, g, steps, k,
                    f"puts '{oid}' at its goal before '{j}', which carries it in the goal "
                    f"('{j}' is still {far * 1000:.0f} mm from its goal pose)",
                )  # fmt: skip
    r.examples = n
    return r


@_register(
    rule=(
        "Every intermediate structure stands with its loads: while a step's object is "
        "carried (the others as they are without it) and after it is put down, every object "
        "rests on the table or on others (gap at most "
        "{geometry.tolerances:TOLERANCES.contact|mm}) and its centre of mass, together with "
        "everything resting only on it, lies over its support (to within "
        "{geometry.tolerances:TOLERANCES.com_margin|mm})."
    )
)
def stable_with_loads(ctx: SuiteContext) -> CheckResult:
    """Every intermediate structure is stable with its loads (`geometry.unstable_objects`):
    the state while the step's object is in the air, and the state after it is put down."""
    from geometry import TOLERANCES, unstable_objects

    r = _result(
        "stable_with_loads",
        "every object supported and stable with its load while each step's object is carried "
        "and after it is put down",
    )
    geometry = ctx.spec.geometry

    def falling(records: list[dict]) -> dict[str, str]:
        return unstable_objects(
            records, geometry, contact_tol=TOLERANCES.contact, margin=-TOLERANCES.com_margin
        )

    n = 0
    for inst, s, g, steps in _plans(ctx):
        n += 1
        before = {o["id"]: dict(o, pose=np.asarray(o["pose"], float)) for o in s}
        for k, oid, state in _states(s, steps):
            lifted = [o for i, o in before.items() if i != oid]
            after = list(state.values())
            for when, records in (("while it is carried", lifted), ("after it", after)):
                bad = falling(records)
                if bad:
                    who = sorted(bad)[0]
                    return _plan_failure(
                        r, ctx, inst, s, g, steps, k,
                        f"moves '{oid}': {when}, '{who}' {bad[who]}",
                    )  # fmt: skip
            before = state
    r.examples = n
    return r
