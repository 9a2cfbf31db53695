"""The `plan` suite: schema, reaching the goal physically, length, identity, determinism,
explicit infeasibility.

Instances come from the domain's instance generator, and from its composer where it has one
(goals no catalogue holds, `Domain.compose`); hypothesis varies them — both scenes moved
together, or the goal made a translation of the start (every object must move, often onto
another's spot) — and shrinks towards the first instance as generated. A plan is applied
with `geometry.apply_plan` (what the trials score plans with too): every step must pick a clear object and leave a collision-free,
supported state inside the workspace, and the last state must match the goal within the
domain's tolerance. The states' relations come from the frozen `relate` when the draft has one
(run by `checks.run` in a session of its own before the draft's: relations depend on the
records only up to a common translation, which `relate`'s own checks hold it to), else from
the domain's reference relations.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from hypothesis import strategies as st

from checks.context import SuiteContext
from checks.hypo import Failure, run_property
from checks.registry import register, rules
from checks.report import CheckResult
from checks.rules import Rule
from checks.suites import _plan_view
from checks.suites._common import (
    copy_records,
    first_difference,
    raise_first,
    raised,
    same_value,
    scene_spec,
    translated,
)
from contracts import se3
from contracts.errors import ContractError
from contracts.validate import validate
from geometry import apply_plan
from geometry.robot import ROBOT
from sandbox import MESHES

VARIANTS = ("as_generated", "both_moved", "goal_is_moved_start")
SHIFT_MM = 60  # [mm] largest shift along x and along y of a moved variant
STEPS_PER_OBJECT = 3  # a plan may have this many steps per object ...
STEPS_PER_REFERENCE_STEP = 2  # ... or this many per step of the reference order, if more


@dataclass(frozen=True, kw_only=True)
class Unrelated:
    """Stands for the relations of a state on which the frozen `relate` failed."""

    why: str
    traceback: str = ""


def _state(ctx: SuiteContext, records: list[dict], relations: Any) -> dict[str, Any]:
    if isinstance(relations, Unrelated):
        raise Failure(
            message=f"the frozen relate {relations.why} on this state, so plan could not be "
            "checked on it",
            traceback=relations.traceback,
            error=True,
        )
    return {"objects": copy_records(records), "relations": relations}


def variant(ctx: SuiteContext, x: tuple) -> tuple[list, list, Any, Any, str] | None:
    """(start, goal, start relations, goal relations, description) for a drawn input, or None
    when the variant leaves the workspace."""
    i, kind, dx, dy = x
    inst = ctx.cases["instances"][i]
    s, g = inst["start"], inst["goal"]
    if kind == "as_generated":
        return s, g, inst["start_relations"], inst["goal_relations"], f"instance {inst['name']}"
    if kind == "both_moved":
        s, g = translated(s, dx / 1000, dy / 1000), translated(g, dx / 1000, dy / 1000)
        what = f"instance {inst['name']} with both scenes moved by ({dx}, {dy}) mm"
        rs, rg = inst["start_relations"], inst["goal_relations"]
    else:
        if dx == 0 and dy == 0:
            dx = 25
        g = translated(s, dx / 1000, dy / 1000)
        what = f"the start of instance {inst['name']} as start, moved by ({dx}, {dy}) mm as goal"
        rs = rg = inst["start_relations"]
    ws = ctx.spec.workspace
    for recs in (s, g):
        for b in ctx.spec.geometry.bodies(recs):
            if ws.outside(b.vertices) is not None:
                return None
    return s, g, rs, rg, what


def plan_of(ctx: SuiteContext, x: tuple) -> tuple[Any, Any] | None:
    """(CallResult of plan, the variant) for a drawn input, cached; None outside the workspace."""
    key = ("plan", x)
    if key not in ctx.cache:
        v = variant(ctx, x)
        if v is None:
            ctx.cache[key] = None
        else:
            s, g, rs, rg, what = v
            start, goal = _state(ctx, s, rs), _state(ctx, g, rg)
            moved = x[1] == "both_moved"  # a case already sent, moved: not timed
            ctx.cache[key] = (ctx.call(start, goal, MESHES, label=what, derived=moved), v)
    return ctx.cache[key]


def _problem_picture(ctx: SuiteContext, extra: dict[str, Any]) -> list[dict[str, str]]:
    """The state where `apply_plan` found its problem, drawn (feedback only)."""
    from geometry import collisions, supports

    p, start, steps, goal = extra["problem"], extra["start"], extra["steps"], extra["goal"]
    k = len(steps) if p.step is None else p.step
    after = _plan_view.state_before(start, steps, min(k + 1, len(steps)))
    shapes = ctx.spec.geometry
    if p.kind == "not_clear":
        before = _plan_view.state_before(start, steps, k)
        blockers = sorted(i for i, on in supports(before, shapes).items() if p.object in on)
    elif p.kind == "collision":
        hits = collisions(after, shapes)
        blockers = sorted({i for a, b, _ in hits for i in (a, b) if i != "table"})
    elif p.kind == "goal":
        target = {o["id"]: o for o in goal}
        blockers = [
            str(o["id"])
            for o in after
            if o["id"] in target
            and not se3.within_tolerance(
                o["pose"],
                np.asarray(target[o["id"]]["pose"], float),
                trans_tol=ctx.spec.trans_tol,
                rot_tol=ctx.spec.rot_tol,
                symmetries=ctx.spec.symmetries.get(o["mesh"]),
            )
        ]
    else:
        blockers = [p.object] if p.object else []
    blockers = [b for b in blockers if b != (None if p.step is None else steps[k]["object"])]
    _, pictures = _plan_view.step_picture(
        ctx,
        start,
        steps,
        k,
        blockers=blockers,
        goal=goal if p.kind == "goal" else None,
        name=f"reaches_goal_{p.kind}",
        what=f"property.reaches_goal ({p.kind})",
    )
    return pictures


def _counterexample(ctx: SuiteContext, start: list, goal: list) -> dict[str, Any]:
    return {"start": scene_spec(ctx.spec.name, start), "goal": scene_spec(ctx.spec.name, goal)}


def _schema_problem(ctx: SuiteContext, value: Any, ids: set[str]) -> str:
    try:
        data = validate("plan", value)
    except ContractError as e:
        return str(e)
    for k, step in enumerate(data.get("steps", [])):
        if step["object"] not in ids:
            return f"steps[{k}].object: unknown object '{step['object']}'; known: {sorted(ids)}"
    return ""


@register(
    "plan",
    "schema.output",
    rule='`plan` returns `{"status": "ok", "steps": [{"object": id, '
    '"target_pose": (4, 4)}, ...]}` or `{"status": "infeasible", "reason": str}`, '
    "each step naming an object of the start state.",
    expected='{"status": "ok", "steps": [{"object": id, "target_pose": 4x4}]} or '
    '{"status": "infeasible", "reason": str}',
)
def schema(ctx: SuiteContext, r: CheckResult) -> None:
    pool = _pool(ctx)
    found: list[Failure] = []
    for x in pool:
        got = plan_of(ctx, x)
        if got is None:
            continue  # an instance outside the workspace: nothing to check
        res, (s, g, *_rest) = got
        ce = _counterexample(ctx, s, g)
        if not res.ok:
            found.append(raised("plan(start, goal)", res, ce))
            continue
        problem = _schema_problem(ctx, res.value, {str(o["id"]) for o in s})
        if problem:
            found.append(
                Failure(
                    message=f"the plan returned is not a plan: {problem}",
                    actual=problem,
                    counterexample=ce,
                )
            )
    r.examples = len(pool)
    raise_first(r, found, "instances")


def _reaches(ctx: SuiteContext, x: tuple) -> Failure | None:
    """The failure of the plan for case `x` (an instance, a variant, a shift), if any."""
    spec = ctx.spec
    got = plan_of(ctx, x)
    if got is None:
        return None  # the drawn variant leaves the workspace: nothing to check
    res, (s, g, _, _, what) = got
    ce = _counterexample(ctx, s, g)
    if not res.ok:
        return raised(f"plan on {what}", res, ce)
    problem = _schema_problem(ctx, res.value, {str(o["id"]) for o in s})
    if problem:
        return Failure(message=f"on {what}: not a plan: {problem}", counterexample=ce)
    value = res.value
    if value["status"] != "ok":
        return Failure(
            message=f"plan says infeasible on {what} ({value.get('reason', '')!r}), but the "
            "goal is reachable",
            expected="status ok",
            actual=value,
            counterexample=ce,
        )
    outcome = apply_plan(
        spec.geometry,
        s,
        value["steps"],
        g,
        trans_tol=spec.trans_tol,
        rot_tol=spec.rot_tol,
        symmetries=spec.symmetries,
        workspace=spec.workspace,
    )
    if outcome.problem is not None:
        p = outcome.problem
        shown = value["steps"][: (p.step + 1) if p.step is not None else None]
        return Failure(
            message=f"on {what}: {p.message}",
            expected="every step picks a clear object and leaves a collision-free, "
            "supported state inside the workspace; the last state matches the goal",
            actual={"problem": p.kind, "steps": shown},
            counterexample=ce,
            extra={"start": s, "goal": g, "steps": value["steps"], "problem": p},
        )
    return None


@register(
    "plan",
    "property.reaches_goal",
    rule="On generated start/goal pairs[? — among them goals composed beyond any "
    "catalogue, from {domain.composed_goals} —?] (as generated, both scenes shifted together "
    "by up to {checks.suites.plan:SHIFT_MM} mm along x and y, or the goal a shifted copy of "
    "the start) your steps, applied in order, pick only objects nothing rests on, leave after "
    "every step no two objects interpenetrating by more than "
    "{geometry.tolerances:TOLERANCES.penetration|mm}, every object resting on the table or "
    "on others (gap at most {geometry.tolerances:TOLERANCES.contact|mm}) with its centre of "
    "mass, and that of its load, over its support (to within "
    "{geometry.tolerances:TOLERANCES.com_margin|mm}), and the moved object with every point "
    "inside the workspace ({domain.workspace|region}), and end with every object within "
    "{domain.tolerance.translation|mm}[? and {domain.tolerance.rotation|deg}?] of its goal "
    "pose modulo its symmetry; answering infeasible on these reachable goals fails.",
    seeded=True,
)
def reaches_goal(ctx: SuiteContext, r: CheckResult) -> None:
    n = len(ctx.cases["instances"])
    pool = _pool(ctx)
    strategy = st.tuples(
        st.integers(0, n - 1),
        st.sampled_from(VARIANTS),
        st.integers(-SHIFT_MM, SHIFT_MM),
        st.integers(-SHIFT_MM, SHIFT_MM),
    )
    outcome = run_property(
        partial(_reaches, ctx),
        strategy,
        max_examples=ctx.examples("plan") + len(pool),
        seed=ctx.seed,
        examples=[*pool, (0, "goal_is_moved_start", 25, 0)],
        shrink_calls=int(ctx.budget.shrink_calls),
    )
    r.examples = outcome.examples
    if outcome.failure:
        f = outcome.failure
        generated = [x for x in pool if plan_of(ctx, x) is not None]
        failing = sum(_reaches(ctx, x) is not None for x in generated)
        r.metrics = {
            "generated_instances": float(len(generated)),
            "generated_instances_failing": float(failing),
        }
        f.message += (
            f" (the plans fail on {failing} of the {len(generated)} instances as generated)"
        )
        if "problem" in f.extra:
            r.images = _problem_picture(ctx, f.extra)
        raise f


@register(
    "plan",
    "property.plan_length_bounded",
    rule="A plan has at most {checks.suites.plan:STEPS_PER_OBJECT} steps per object, or "
    "{checks.suites.plan:STEPS_PER_REFERENCE_STEP} per step of the domain's reference "
    "construction order when that allows more: the order the generator found for the "
    "instance, one object at a time, each put at its goal once what carries it there is in "
    "place, a blocking object moved aside when none can be.",
)
def plan_length_bounded(ctx: SuiteContext, r: CheckResult) -> None:
    instances = ctx.cases["instances"]
    pool = _pool(ctx)
    found: list[Failure] = []
    for x in pool:
        got = plan_of(ctx, x)
        if got is None:
            continue
        res, (s, g, *_rest) = got
        if not res.ok or not isinstance(res.value, dict) or res.value.get("status") != "ok":
            continue
        steps = res.value.get("steps", [])
        order = instances[x[0]].get("order_len")
        bound = max(STEPS_PER_OBJECT * len(s), STEPS_PER_REFERENCE_STEP * int(order or 0))
        if len(steps) > bound:
            found.append(
                Failure(
                    message=f"the plan has {len(steps)} steps for {len(s)} objects; at most "
                    f"{bound} are allowed (the domain's reference order has {order})",
                    expected=f"<= {bound} steps",
                    actual=f"{len(steps)} steps",
                    counterexample=_counterexample(ctx, s, g),
                )
            )
    r.examples = len(pool)
    raise_first(r, found, "instances")


@register(
    "plan",
    "property.identity_plan_empty",
    rule='`plan(s, s)` returns `{"status": "ok", "steps": []}`: objects already '
    "within tolerance of their goal pose need no step.",
)
def identity_plan_empty(ctx: SuiteContext, r: CheckResult) -> None:
    instances = ctx.cases["instances"]
    n = len(ctx.cases["instances"])
    spec = ctx.spec
    k = min(n, ctx.examples("identity"))
    for i in range(k):
        inst = instances[i]
        for side in ("start", "goal"):
            recs, rel = inst[side], inst[f"{side}_relations"]
            res = ctx.call(
                _state(ctx, recs, rel), _state(ctx, recs, rel), MESHES, label="plan(s, s)"
            )
            ce = {"start": scene_spec(spec.name, recs), "goal": "the same scene"}
            if not res.ok:
                raise raised("plan(s, s)", res, ce)
            v = res.value
            if not (isinstance(v, dict) and v.get("status") == "ok" and not v.get("steps")):
                raise Failure(
                    message="plan(s, s) must be {'status': 'ok', 'steps': []}: the goal is "
                    "already reached",
                    expected={"status": "ok", "steps": []},
                    actual=v,
                    counterexample=ce,
                )
    r.examples = 2 * k


@register(
    "plan",
    "property.deterministic",
    rule="Two calls on the same start and goal return the same plan.",
)
def deterministic(ctx: SuiteContext, r: CheckResult) -> None:
    instances = ctx.cases["instances"]
    n = len(ctx.cases["instances"])
    k = min(n, ctx.examples("determinism"))
    for i in range(k):
        inst = instances[i]
        a, b = (
            ctx.call(
                _state(ctx, inst["start"], inst["start_relations"]),
                _state(ctx, inst["goal"], inst["goal_relations"]),
                MESHES,
                label=f"instance {inst['name']}",
            )
            for _ in range(2)
        )
        if a.ok and b.ok and not same_value(a.value, b.value):
            raise Failure(
                message="plan gave two different plans for the same start and goal (first "
                f"difference at {first_difference(a.value, b.value)})",
                counterexample=_counterexample(ctx, inst["start"], inst["goal"]),
            )
    r.examples = k


@register(
    "plan",
    "property.infeasible_explicit",
    rule='A goal no plan can reach gets `{"status": "infeasible", "reason": str}`, never '
    "an exception or steps. The checks draw such goals afresh each time from the task's "
    "goals: an object floating at some height above where it would rest, two objects "
    "sunk into each other by some depth, a stack whose support was moved away, an object "
    "out of the robot's reach.",
)
def infeasible_explicit(ctx: SuiteContext, r: CheckResult) -> None:
    for case in ctx.cases.get("infeasible", []):
        start = _state(ctx, case["start"], case["start_relations"])
        goal = _state(ctx, case["goal"], case["goal_relations"])
        res = ctx.call(start, goal, MESHES, label=f"infeasible case {case['name']}")
        ce = _counterexample(ctx, case["start"], case["goal"])
        ce["why_no_plan_exists"] = case["why"]
        if not res.ok:
            raise raised(
                "plan must return {'status': 'infeasible', 'reason': ...} when no plan "
                "exists, but it",
                res,
                ce,
            )
        v = res.value
        if not (isinstance(v, dict) and v.get("status") == "infeasible"):
            raise Failure(
                message=f"no plan can reach this goal ({case['why']}), yet plan did not say "
                "infeasible",
                expected={"status": "infeasible", "reason": "..."},
                actual=v if not isinstance(v, dict) else {**v, "steps": v.get("steps", [])[:3]},
                counterexample=ce,
            )
    r.examples = len(ctx.cases.get("infeasible", []))


@register(
    "plan",
    "property.gripper_room",
    rule="Every step is one the robot can make as `toolbox.robot.Hand(meshes, "
    "symmetries).can_move` models it: a top-down {geometry.robot:ROBOT.gripper.name} grasp "
    "across two opposite vertical "
    "faces at most {toolbox.robot:MAX_GRASP_WIDTH|mm} apart (the "
    "jaws open at most {toolbox.robot:MAX_OPENING|mm} and need room on both sides) whose "
    "fingers, finger linkages, gripper base and wrist clear every other object by at least "
    "{geometry.tolerances:TOLERANCES.grasp_margins[-1]|mm} at the pick (the objects as "
    "they are before the step) and at the place (as they are after it), nothing above the "
    "object at either end (it rises straight up and comes straight down: a part overhanging "
    "its way keeps {geometry.tolerances:TOLERANCES.sweep_clearance|mm} from it), a target "
    "turned from the current pose only about the vertical "
    "(to within {geometry.tolerances:TOLERANCES.yaw_only|deg}, modulo its symmetry), and "
    "an arm (IK) solution at both ends.",
    expected="every step executable by the robot's hand (see `toolbox.hand`)",
)
def gripper_room(ctx: SuiteContext, r: CheckResult) -> None:
    pool = _pool(ctx)
    hand = ctx.hand
    n_plans = n_steps = 0
    found: list[Failure] = []
    for x in pool:
        got = plan_of(ctx, x)
        if got is None:
            continue
        res, (s, g, _, _, what) = got
        if not res.ok or _schema_problem(ctx, res.value, {str(o["id"]) for o in s}):
            continue
        value = res.value
        if value["status"] != "ok":
            continue
        n_plans += 1
        problem = hand.first_problem(s, value["steps"])
        n_steps += problem.checked
        if problem.step is not None:
            if found:  # counted; the first one is shown
                found.append(Failure(message=""))
                continue
            hit, pictures = _plan_view.step_picture(
                ctx,
                s,
                value["steps"],
                problem.step,
                blockers=problem.blockers,
                hands="no top-down" in problem.message,
                name=f"gripper_room_{x[0]}",
                what=f"property.gripper_room on {what}",
            )
            r.images = pictures
            found.append(Failure(
                message=f"on {what}: step {problem.step} {problem.message}"
                + (f". Diagnosis: {hit}" if hit else ""),
                expected=f"every step has a top-down {ROBOT.gripper.name} grasp that clears "
                "the other objects "
                "at the pick (the state before the step) and at the place (after it), "
                "nothing above the object at either, and an arm pose (IK) at both",
                actual={
                    "step": problem.step,
                    "object": problem.object,
                    "blockers": list(problem.blockers),
                    "steps": value["steps"][: problem.step + 1],
                },
                counterexample=_counterexample(ctx, s, g),
            ))  # fmt: skip
    r.examples = n_plans
    r.metrics = {"steps_checked": float(n_steps)}
    raise_first(r, found, "plans")


def _pool(ctx: SuiteContext) -> list[tuple]:
    """Every instance as generated: the cases each check goes through."""
    return [(i, "as_generated", 0, 0) for i in range(len(ctx.cases["instances"]))]


RULES: tuple[Rule, ...] = rules("plan")
