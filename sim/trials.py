"""One trial: observe start and goal → policy → plan → execute in physics → score.

Design rule: a trial never raises for the work failing; it returns a `TrialResult` whose
`failure` names the first stage that went wrong — perception, relations, planning, grasp,
motion or execution — so the harness always goes on with the next trial. Only a broken
harness raises.

What each party knows (the honest protocol, `TrialProtocol`): the policy gets the two observations
— rendered from the true camera with the protocol's realism, handed over with the *calibrated*
camera — and returns a plan and the states it perceived; the executor gets the plan and the
perceived start state as its belief, and senses what `TrialProtocol` switches on. The instance's
ground truth is read only to render the observations and to score. The oracle policy is the
exception by definition: ground-truth states and the reference construction order, so it
measures the executor alone.

Open or closed loop (`run_trial(loop=…)`): open, the paper's protocol, runs the plan to its
end; closed (`sim.loop`) parks the arm after each transfer, observes the scene again with the
trial's camera and realism, and lets the policy's own programs replan when the scene is not
what was believed. `faults` injects one seeded fault per trial (`sim.faults`).

What the policy hands over is bounded before anything works on it: a plan over the plan
contract's step cap (`contracts.limits`) is refused unexecuted, and every trial has a
wall-clock deadline (`TRIAL_DEADLINE_S`): the executor starts no phase of a transfer after it,
and the trial ends failed, saying so.
"""

from __future__ import annotations

import contextlib
import functools
import time
import traceback
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import mujoco
import numpy as np

from contracts import ContractError, se3, to_jsonable, validate
from contracts.errors import UsageError
from contracts.limits import clip, count_problem, plan_problem
from domains import Domain
from domains.instance import Instance
from sim import ik, robot
from sim.errors import SimError
from sim.executor import Executor, ExecutorConfig
from sim.faults import Fault, Injector, biased
from sim.faults import draw as draw_fault
from sim.loop import ClosedLoop, RecoveryBudget
from sim.observation import Renderer, observe, release_renderers
from sim.scene import body_name, build_spec
from sim.score import final_success, records_of, state_accuracy
from sim.sensing import EXACT, WRIST_CAMERA, Sensors
from sim.settle import check_order

Loop = Literal["open", "closed"]
Stage = Literal["perception", "relations", "planning", "grasp", "motion", "execution", "harness"]
TRIAL_DEADLINE_S = 600.0  # [s] wall clock, one trial: 50× the slowest domain's median (11 s)
# which stage an executor failure belongs to
_STAGE_OF_KIND: dict[str, Stage] = {
    "unknown_object": "planning",
    "non_rigid_target": "planning",
    "not_perceived": "perception",
    "no_grasp": "grasp",
    "grasp_failed": "grasp",
    "unreachable": "motion",
    "dropped": "execution",
    "deadline": "execution",
}
# which stage a policy's failing program belongs to (its exception's `function`, where it has one)
_STAGE_OF_FUNCTION: dict[str, Stage] = {
    "perceive": "perception",
    "relate": "relations",
    "plan": "planning",
}


@dataclass(frozen=True, kw_only=True)
class TrialProtocol:
    """What a trial's observations are like and what the robot senses while executing.

    Attributes:
        realism: observation realism level (`sim.realism`): clean, default or harsh.
        in_hand: the in-hand pose estimate after the grasp: "wrist" (a wrist camera, with
            `sim.sensing.WRIST_CAMERA`'s noise), "exact" (the true pose in the hand) or "none"
            (open loop).
        track_objects: the executor reads every object's true pose before each pick (a
            ground-truth tracker: no real robot has it).
        weld_assist: the physics aid of `sim.weld`.
        camera_offset: the executor estimates the perceiving camera's calibration offset from
            the wrist camera and takes it off (`ExecutorConfig.camera_offset`; needs an
            in-hand estimate).
    """

    realism: str = "default"
    in_hand: Literal["wrist", "exact", "none"] = "wrist"
    track_objects: bool = False
    weld_assist: bool = False
    camera_offset: bool = True

    @property
    def label(self) -> str:
        sensed = {"wrist": "wrist-camera in-hand estimate", "exact": "exact in-hand pose",
                  "none": "no in-hand estimate"}[self.in_hand]  # fmt: skip
        parts = [f"{self.realism} realism", sensed]
        if self.track_objects:
            parts.append("ground-truth object tracker")
        if self.weld_assist:
            parts.append("weld assist")
        if not self.camera_offset and self.in_hand != "none":
            parts.append("no camera-offset estimate")
        return ", ".join(parts)

    def executor_config(self, base: ExecutorConfig | None = None) -> ExecutorConfig:
        noise = {"wrist": WRIST_CAMERA, "exact": EXACT, "none": None}[self.in_hand]
        return replace(
            base or ExecutorConfig(),
            in_hand=noise,
            track_objects=self.track_objects,
            camera_offset=self.camera_offset,
        )


HONEST = TrialProtocol()
ORACLE_SENSING = TrialProtocol(realism="clean", in_hand="exact", track_objects=True)
"""Sensing no real robot has: clean images, the true camera, an exact in-hand pose and an
executor that reads every object's true pose. Measures what perception errors cost."""


@dataclass(frozen=True, kw_only=True)
class PolicyOutput:
    """What a policy made of a start/goal pair."""

    plan: Any
    start_state: dict | None  # {"objects", "relations"} as perceived; None for the oracle
    goal_state: dict | None
    timings: dict[str, float] = field(default_factory=dict)  # [s]
    fit: dict | None = None  # per side, how well the perceived state explains the image


class OraclePolicy:
    """Ground truth and the reference construction order: measures the executor alone.

    Where the domain packs objects edge to edge (`Domain.placement_spread`), the goal places
    are first spread apart a little, as a program's plan would: the final poses stay within
    the scoring tolerance, and the executor is not asked to hit half-millimetre gaps."""

    name = "oracle"
    oracle = True

    def solve_from_truth(self, instance: Instance, domain: Domain | None = None) -> PolicyOutput:
        steps = [
            {"object": s["object"], "target_pose": np.array(s["target_pose"], dtype=float)}
            for s in instance.order
        ]
        if domain is not None and domain.placement_spread is not None:
            _spread_goal_places(domain, instance, steps)
        return PolicyOutput(
            plan={"status": "ok", "steps": steps}, start_state=None, goal_state=None
        )


def _spread_goal_places(domain: Domain, instance: Instance, steps: list[dict]) -> None:
    """Shift every step that puts an object at its goal pose by the spread of the goal's
    footprints (`toolbox.packing.spread_footprints`)."""
    from toolbox.packing import footprint, spread_footprints

    assert domain.placement_spread is not None
    gap, shift = domain.placement_spread
    goal = {r["id"]: r for r in instance.goal["objects"]}
    ids = list(goal)
    footprints = [footprint(domain.mesh(goal[oid]["mesh"]), goal[oid]["pose"]) for oid in ids]
    moves = dict(zip(ids, spread_footprints(footprints, gap=gap, max_shift=shift), strict=True))
    for s in steps:  # a step to the goal pose or to one of its symmetric equivalents
        record = goal[s["object"]]
        at_goal = se3.within_tolerance(
            s["target_pose"],
            np.asarray(record["pose"], dtype=float),
            trans_tol=1e-6,
            rot_tol=1e-6,
            symmetries=list(domain.symmetries(record["mesh"])),
        )
        if at_goal:
            s["target_pose"][:2, 3] += moves[s["object"]]


@dataclass(frozen=True, kw_only=True)
class TrialResult:
    name: str
    state_ok: bool
    plan_ok: bool
    final_ok: bool
    failure: dict | None  # {"stage", "reason"}
    timings: dict[str, float]
    steps: list[dict]
    object_errors: list[dict]
    execution_failure: dict | None = None  # the executor's own failure (step, kind, phase, reason)
    plan_failure: str | None = None  # why the plan failed its abstract check, when it did
    # when the plan fails its abstract check against the true scenes: whether it still ends
    # every object at its perceived goal pose, from the perceived start (the shortfall is
    # then perception's, not the plan's)
    plan_builds_perceived: bool | None = None
    loop: dict | None = None  # the closed loop's record (`sim.loop.ClosedLoop.to_dict`)
    fault: dict | None = None  # the injected fault and what it did (`sim.faults.Fault`)
    fit: dict | None = None  # the policy's fit of each perceived state (`artifacts.fit`)
    # the perceived start and goal records, when asked for (`run_trial(keep_states=True)`)
    perceived: dict[str, list[Mapping]] | None = None

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "state_ok": self.state_ok,
            "plan_ok": self.plan_ok,
            "final_ok": self.final_ok,
            "failure": self.failure,
            "timings": {k: round(v, 4) for k, v in self.timings.items()},
            "steps": self.steps,
            "object_errors": self.object_errors,
            "execution_failure": self.execution_failure,
            "plan_failure": self.plan_failure,
            **(
                {"plan_builds_perceived": self.plan_builds_perceived}
                if self.plan_builds_perceived is not None
                else {}
            ),
            **({"loop": self.loop} if self.loop is not None else {}),
            **({"fault": self.fault} if self.fault is not None else {}),
            **({"fit": self.fit} if self.fit is not None else {}),
            **({"perceived": to_jsonable(self.perceived)} if self.perceived is not None else {}),
        }


def _seed(name: str, side: str) -> int:
    return zlib.crc32(f"{name}/{side}".encode())


def _state_reason(score, side: str) -> tuple[Stage, str]:
    if score.missing or score.extra:
        return "perception", f"{side}: missing {score.missing}, extra {score.extra}"
    bad = [e for e in score.objects if not e.within]
    if bad:
        e = bad[0]
        return "perception", f"{side}: {e.id} off by {1000 * e.translation:.1f} mm" + (
            "" if e.rotation is None else f", {np.degrees(e.rotation):.1f}°"
        )
    return (
        "relations",
        f"{side}: relations differ (missing {score.missing_edges[:3]}, extra {score.extra_edges[:3]})",
    )


def observations(
    domain: Domain, instance: Instance, camera: Any, protocol: TrialProtocol
) -> tuple[dict, dict]:
    """The trial's start and goal observations: seeded by the instance's name, one camera
    calibrated once for both (what the policy is given)."""
    calibration = _seed(instance.name, "camera")
    return tuple(  # type: ignore[return-value]
        observe(
            domain,
            scene,
            camera,
            seed=_seed(instance.name, side),
            realism=protocol.realism,
            calibration_seed=calibration,
        )
        for side, scene in (("start", instance.start), ("goal", instance.goal))
    )


def belief_of(state: Mapping | None) -> dict[str, np.ndarray]:
    """The executor's belief from a perceived state: the poses of its valid records."""
    out: dict[str, np.ndarray] = {}
    for r in (state or {}).get("objects", []) if isinstance(state, Mapping) else []:
        try:
            T = se3.as_matrix(r["pose"])
        except (KeyError, TypeError, ValueError):
            continue
        if se3.is_rigid(T, tol=1e-3):
            out[str(r["id"])] = T
    return out


def run_trial(
    domain: Domain,
    instance: Instance,
    policy: Any,
    *,
    camera: Any = "front",
    protocol: TrialProtocol = HONEST,
    record_dir: Path | None = None,
    config: ExecutorConfig | None = None,
    deadline_s: float = TRIAL_DEADLINE_S,
    loop: Loop = "open",
    faults: Sequence[str] = (),
    budget: RecoveryBudget | None = None,
    keep_states: bool = False,
) -> TrialResult:
    """Run one trial end to end; see the module docstring. `camera`: a view name or a camera
    dict (the true camera; the policy gets it calibrated). `deadline_s`: the trial's wall-clock
    deadline [s], counted from its start. `loop`: "open" (the paper's protocol: the plan runs
    to its end) or "closed" (`sim.loop`: look again after each transfer and replan, with the
    policy's programs and `budget`). `faults`: the names (`sim.faults.FAULTS`) one fault of the
    trial is drawn from; none when empty. `keep_states`: the result keeps the perceived start
    and goal records (`TrialResult.perceived`; the trial gate judges them)."""
    if loop not in ("open", "closed"):
        raise UsageError(f"loop must be 'open' or 'closed', got {loop!r}")
    if loop == "closed" and not callable(getattr(policy, "programs", None)):
        raise UsageError(
            f"the closed loop needs a policy with programs to look again with; "
            f"{getattr(policy, 'name', type(policy).__name__)} has none"
        )
    timings: dict[str, float] = {}
    failure: tuple[Stage, str] | None = None
    t0 = time.perf_counter()
    deadline = t0 + deadline_s
    trim_heap()  # what the process's earlier work (the last trial, its setup) left free
    start_obs, goal_obs = observations(domain, instance, camera, protocol)
    timings["observe"] = time.perf_counter() - t0
    if record_dir is not None:
        _save_png(record_dir / "start.png", start_obs["rgb"])
        _save_png(record_dir / "goal.png", goal_obs["rgb"])

    # -- policy -------------------------------------------------------------------------------
    t = time.perf_counter()
    try:
        if getattr(policy, "oracle", False):
            out = policy.solve_from_truth(instance, domain)
        else:
            out = policy.solve(domain, start_obs, goal_obs)
    except Exception as e:
        return TrialResult(
            name=instance.name,
            state_ok=False,
            plan_ok=False,
            final_ok=False,
            failure={
                "stage": _STAGE_OF_FUNCTION.get(str(getattr(e, "function", "")), "perception"),
                "reason": f"policy raised {type(e).__name__}: {clip(str(e))}",
                "traceback": traceback.format_exc(limit=-3),
            },
            timings={**timings, "policy": time.perf_counter() - t},
            steps=[],
            object_errors=[],
        )
    # the policy's own time: without judging its fit (for the trial's JSON, not for planning)
    timings["policy"] = time.perf_counter() - t - out.timings.get("fit", 0.0)
    timings.update({f"policy_{k}": v for k, v in out.timings.items()})
    if bad_state := _states_problem(domain, out):  # before scoring: its geometry is pairwise
        return TrialResult(
            name=instance.name,
            state_ok=False,
            plan_ok=False,
            final_ok=False,
            failure={"stage": bad_state[0], "reason": bad_state[1]},
            timings={**timings, "total": time.perf_counter() - t0},
            steps=[],
            object_errors=[],
        )

    # -- state accuracy -----------------------------------------------------------------------
    state_ok = True
    if out.start_state is not None:
        s_score = state_accuracy(domain, out.start_state, instance.start)
        g_score = state_accuracy(domain, out.goal_state, instance.goal)
        state_ok = s_score.correct and g_score.correct
        if not s_score.correct:
            failure = _state_reason(s_score, "start")
        elif not g_score.correct:
            failure = _state_reason(g_score, "goal")

    # -- plan success (abstract, physics-free: geometry.apply_plan, as the plan checks) -------
    plan_ok = False
    plan_failure: str | None = None
    builds_perceived: bool | None = None
    steps: list[dict] = []
    valid = False
    if too_long := plan_problem(out.plan):  # before any work on it: listing it costs too
        plan = None
        plan_failure = f"plan refused unexecuted: {too_long}"
        failure = failure or ("planning", plan_failure)
    else:
        raw = to_jsonable(out.plan)
        try:
            plan = validate("plan", raw)
            valid = True
        except ContractError as e:
            plan = None
            plan_failure = f"plan is malformed: {e}"
            failure = failure or ("planning", plan_failure)
            if _executable_shape(raw):
                plan = raw  # let the executor refuse it step by step, naming the step
    if plan is not None and plan["status"] != "ok":
        plan_failure = f"plan says infeasible: {clip(str(plan['reason']))}"
        failure = failure or ("planning", plan_failure)
    elif valid and plan is not None:
        steps = plan["steps"]
        problems = check_order(domain, instance.start, steps, instance.goal, physics=False)
        plan_ok = not problems
        if problems:
            first = problems[0]
            plan_failure = (
                first.problem if first.object is None else f"{first.object}: {first.problem}"
            )
            failure = failure or ("planning", plan_failure)
            if out.start_state is not None:
                builds_perceived = ends_at(domain, out.start_state, steps, out.goal_state)

    # -- execution in physics ---------------------------------------------------------------
    final_ok = False
    execution_failure: dict | None = None
    step_info: list[dict] = []
    object_errors: list[dict] = []
    fault: Fault | None = None
    loop_record: dict | None = None
    recorder: _Recorder | None = None
    if plan is not None and plan["status"] == "ok":
        t = time.perf_counter()
        # a recording's worker keeps no mesh cache: its peak memory is the one with a target
        model, data = _world(domain, instance, mesh_cache=record_dir is None)
        trim_heap()  # what the world's compile left free
        ids = [o["id"] for o in instance.start["objects"]]
        view = domain.camera(camera) if isinstance(camera, str) else camera
        if record_dir is not None and loop == "open":
            release_renderers()  # no look until the next trial: the video's context takes its place
        recorder = (
            _Recorder(model, _twin(domain, ids), view, record_dir / "trial.mp4")
            if record_dir is not None
            else None
        )
        meshes = {
            o["id"]: (domain.mesh(o["mesh"]), list(domain.symmetries(o["mesh"])))
            for o in instance.start["objects"]
        }
        fault = draw_fault(faults, instance.name, len(plan["steps"]))
        believed_start = biased(fault, out.start_state)
        belief = (
            {o["id"]: np.asarray(o["pose"], float) for o in instance.start["objects"]}
            if out.start_state is None  # the oracle: ground-truth states
            else belief_of(believed_start)
        )
        exec_config = protocol.executor_config(config)
        if recorder is not None:
            exec_config = replace(exec_config, record_fps=_Recorder.FPS)
        sensors = Sensors.of(
            model,
            data,
            [o["id"] for o in instance.start["objects"]],
            in_hand=exec_config.in_hand,
            track_objects=exec_config.track_objects,
            weld_assist=protocol.weld_assist,
            seed=_seed(instance.name, "in-hand"),
        )
        executor = Executor(
            model, data, meshes, belief=belief, sensors=sensors, record=recorder, config=exec_config
        )
        injector = Injector(fault, model, data, meshes)

        def on_phase(ex: Executor, phase: str, oid: str) -> None:
            injector.on_phase(ex, phase, oid)
            if recorder is not None and phase == "done":  # the recording's poses (scoring side)
                recorder.poses(
                    f"{oid} placed", data.time, _final_scene(domain, instance, model, data)
                )

        executor.on_phase = on_phase
        if loop == "closed":
            assert isinstance(believed_start, Mapping) and isinstance(out.goal_state, Mapping)
            closed = _ClosedTrial(domain, instance, camera, protocol, executor, injector, deadline)
            step_info, last_failure, loop_record = closed.run(
                ClosedLoop(
                    domain,
                    policy.programs(),
                    budget=budget or RecoveryBudget(),
                    judge=functools.partial(policy.look_problems, domain)
                    if callable(getattr(policy, "look_problems", None))
                    else None,
                    referee=functools.partial(policy.look_prefers_belief, domain)
                    if callable(getattr(policy, "look_prefers_belief", None))
                    else None,
                ),
                believed_start,
                out.goal_state,
                plan,
            )
            timings["loop_programs"] = closed.program_seconds
            if loop_record["status"] == "gave_up" and failure is None:
                failure = (
                    loop_record.get("cause")
                    or (_STAGE_OF_KIND.get(last_failure.kind, "execution") if last_failure
                        else "execution"),
                    f"the closed loop gave up: {loop_record['reason']}",
                )  # fmt: skip
            result_failure = last_failure if loop_record["status"] != "done" else None
        else:
            if fault is not None and fault.name == "skip":
                plan = {
                    **plan,
                    "steps": [s for k, s in enumerate(plan["steps"]) if k != fault.step],
                }
                injector.skipped_in_plan()
            result = executor.execute(plan, deadline=deadline)
            timings["execute_wall"] = result.wall_time
            timings["execute_sim"] = result.sim_time
            step_info = [s.to_dict() for s in result.steps]
            result_failure = result.failure
        if result_failure is not None:
            f = result_failure
            execution_failure = f.to_dict()
            failure = failure or (
                _STAGE_OF_KIND.get(f.kind, "execution"),
                f"the trial ran past its {deadline_s:g} s wall-clock deadline: step {f.step} "
                f"({f.object}) stopped before its {f.phase} phase, later steps not run"
                if f.kind == "deadline"
                else f"step {f.step} ({f.object}, {f.phase}): {f.kind}: {clip(f.reason)}",
            )
        injector.settle()  # a fault's topples, judged now if its moment came late
        final = _final_scene(domain, instance, model, data)
        score = final_success(
            domain,
            final,
            instance.goal,
            released=_released(model, data, [o["id"] for o in instance.start["objects"]]),
        )
        # A trial stopped at its deadline fails, wherever the objects were when it stopped:
        # the plan did not run to its end.
        final_ok = score.success and not (
            execution_failure is not None and execution_failure["kind"] == "deadline"
        )
        if (
            final_ok
            and loop == "closed"
            and failure is not None
            and failure[1].startswith("the closed loop gave up")
        ):
            failure = None  # it gave up, but the scene it left was the goal
        object_errors = [e.to_dict() for e in score.objects]
        if not final_ok and failure is None:
            bad = [e for e in score.objects if not e.within]
            why = (
                "gripper still holds an object"
                if not score.released
                else "not at rest"
                if not score.at_rest
                else f"{bad[0].id} off its goal by {1000 * bad[0].translation:.1f} mm"
                if bad
                else "final state wrong"
            )
            failure = ("execution", why)
        timings["execute"] = time.perf_counter() - t
        if recorder is not None and record_dir is not None:
            recorder.poses("end", data.time, final)
            recorder.close()
            _save_png(record_dir / "final.png", recorder.last_rgb())
    elif failure is None:
        failure = ("planning", "no plan to execute")
    timings["total"] = time.perf_counter() - t0
    trial = TrialResult(
        name=instance.name,
        state_ok=state_ok,
        plan_ok=plan_ok,
        final_ok=final_ok,
        failure=None
        if failure is None or (final_ok and state_ok and plan_ok)
        else {"stage": failure[0], "reason": failure[1]},
        timings=timings,
        steps=step_info,
        object_errors=object_errors,
        execution_failure=execution_failure,
        plan_failure=plan_failure,
        plan_builds_perceived=builds_perceived,
        loop=loop_record,
        fault=None if fault is None else fault.to_dict(),
        fit=out.fit,
        perceived={"start": records_of(out.start_state), "goal": records_of(out.goal_state)}
        if keep_states and out.start_state is not None
        else None,
    )
    if record_dir is not None:
        _write_record(record_dir, domain, instance, camera, protocol, loop, out, plan,
                      recorder.log if recorder is not None else [], trial)  # fmt: skip
    return trial


def _write_record(record_dir: Path, domain, instance, camera, protocol, loop, out, plan,
                  poses: list[dict], result: TrialResult) -> None:  # fmt: skip
    """`trial.json` beside the video: enough to replay and plot the trial without running it —
    the true start and goal, what was perceived, the plan, every step's outcome, and the
    objects' true poses after each placement and at the end."""
    import json
    from dataclasses import asdict

    doc = {
        "name": instance.name,
        "domain": domain.name,
        "observation_seeds": {side: _seed(instance.name, side) for side in ("start", "goal")},
        "camera": domain.camera(camera) if isinstance(camera, str) else camera,
        "view": camera if isinstance(camera, str) else None,
        "protocol": asdict(protocol),
        "loop": loop,
        "truth": {"start": instance.start, "goal": instance.goal, "order": instance.order},
        "perceived": {"start": out.start_state, "goal": out.goal_state},
        "plan": plan,
        "poses": poses,  # [{"label", "sim_time", "objects": {id: 4×4}}], the last: "end"
        "result": result.to_dict(),
    }
    record_dir.mkdir(parents=True, exist_ok=True)
    (record_dir / "trial.json").write_text(json.dumps(to_jsonable(doc)) + "\n")


class _ClosedTrial:
    """The robot side of a closed-loop trial: carry out each step the loop hands out (parking
    after it), let the fault act, and look again with the trial's camera and realism."""

    def __init__(self, domain, instance, camera, protocol, executor, injector, deadline) -> None:
        self.domain, self.instance, self.camera, self.protocol = domain, instance, camera, protocol
        self.executor, self.injector, self.deadline = executor, injector, deadline
        self.program_seconds = 0.0
        self.look_seconds = 0.0  # second looks rendered inside the loop's report

    def look(self, k: int, again: bool = False) -> dict:
        """A new observation of the scene as it now is (the camera's physics renders the world;
        the arm is parked out of view), with the trial's calibrated camera; `again`: a second
        photo of the same scene (the sensor's noise drawn anew)."""
        scene = _final_scene(self.domain, self.instance, self.executor.model, self.executor.data)
        return observe(
            self.domain,
            scene,
            self.camera,
            seed=_seed(self.instance.name, f"look-{k}" + ("-again" if again else "")),
            realism=self.protocol.realism,
            calibration_seed=_seed(self.instance.name, "camera"),
        )

    def _look_again(self, k: int) -> dict:
        """The second look `ClosedLoop.report` may ask for (its rendering is not program time)."""
        t = time.perf_counter()
        try:
            return self.look(k, again=True)
        finally:
            self.look_seconds += time.perf_counter() - t

    def run(self, loop: ClosedLoop, start: Mapping, goal: Mapping, plan: Mapping):
        from sim.execution import StepFailure

        outcomes: list[dict] = []
        last_failure: StepFailure | None = None
        t = time.perf_counter()
        try:
            step = loop.adopt(start, goal, plan)
        except Exception as e:  # a program failing inside the loop ends it, saying so
            loop.give_up(f"a program failed: {type(e).__name__}: {clip(str(e))}")
            step = None
        self.program_seconds += time.perf_counter() - t
        k = 0
        while step is not None:
            if time.perf_counter() > self.deadline:
                last_failure = StepFailure(step=k, object=step["object"], kind="deadline",
                                           phase="grasp", reason="the deadline passed")  # fmt: skip
                loop.give_up("the trial's wall-clock deadline passed")
                break
            why: str | None = None
            missed = False  # the hand closed on nothing: the object was not where believed
            if self.injector.skips():
                ok = True
            else:
                ex = self.executor
                ex.belief = {oid: T for oid, T in loop.belief.items() if oid in ex.meshes}
                result = ex.execute([step], deadline=self.deadline)
                for s in result.steps:
                    outcomes.append({**s.to_dict(), "index": k})
                ok = result.ok
                if result.failure is not None:
                    last_failure = replace(result.failure, step=k)
                    why = f"{result.failure.kind}: {result.failure.reason}"
                    missed = result.failure.kind == "grasp_failed"
                    if result.failure.kind == "deadline":
                        loop.give_up("the trial's wall-clock deadline passed")
                        break
            k += 1
            seen = self.look(k)
            t, rendered = time.perf_counter(), self.look_seconds
            try:
                step = loop.report(
                    ok=ok,
                    observation=seen,
                    failure=why,
                    missed=missed,
                    look_again=functools.partial(self._look_again, k),
                )
            except Exception as e:
                loop.give_up(f"a program failed: {type(e).__name__}: {clip(str(e))}")
                step = None
            self.program_seconds += time.perf_counter() - t - (self.look_seconds - rendered)
        if loop.status == "done":
            last_failure = None
        return outcomes, last_failure, loop.to_dict()


def ends_at(domain: Domain, start: Any, steps: Sequence[Mapping], goal: Any) -> bool:
    """Whether `steps` leave every object of `goal` at its pose there (the domain's
    tolerance, modulo symmetry), each object starting where `start` has it: the end of a plan,
    judged on the states it was made from."""
    poses = {str(r["id"]): se3.as_matrix(r["pose"]) for r in records_of(start)}
    for step in steps:
        poses[str(step["object"])] = se3.as_matrix(step["target_pose"])
    tol = domain.tolerance
    for r in records_of(goal):
        T = poses.get(str(r["id"]))
        if T is None or not se3.within_tolerance(
            T,
            se3.as_matrix(r["pose"]),
            trans_tol=tol.translation,
            rot_tol=tol.rotation,
            symmetries=list(domain.symmetries(r["mesh"])),
        ):
            return False
    return True


def _states_problem(domain: Domain, out: PolicyOutput) -> tuple[Stage, str] | None:
    """The first perceived state over a count limit (`contracts.limits`), as a failure."""
    objects = len(domain.objects)
    for side, state in (("start", out.start_state), ("goal", out.goal_state)):
        if not isinstance(state, Mapping):
            continue
        if problem := count_problem("perceive", state.get("objects"), objects=objects):
            return "perception", f"{side}: the perceived records are refused: {problem}"
        if problem := count_problem("relate", state.get("relations"), objects=objects):
            return "relations", f"{side}: the relation graph is refused: {problem}"
    return None


def _executable_shape(plan: Any) -> bool:
    """An `ok` plan whose steps have the right keys, whatever their poses hold."""
    return (
        isinstance(plan, dict)
        and plan.get("status") == "ok"
        and isinstance(plan.get("steps"), list)
        and all(isinstance(s, dict) and {"object", "target_pose"} <= set(s) for s in plan["steps"])
    )


def _world(
    domain: Domain, instance: Instance, *, mesh_cache: bool = True
) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The trial's physics: the robot without its visual meshes (nothing renders this model;
    the same physics to the last bit, in a fifth of the memory). `mesh_cache=False` compiles
    it without MuJoCo's global mesh cache, which otherwise keeps the robot's collision meshes
    (about 23 MB) for the next trial's compile (0.1 s faster)."""
    spec = build_spec(domain, instance.start, with_robot=True, robot_visuals=False)
    with contextlib.nullcontext() if mesh_cache else robot.no_mesh_cache():
        model = spec.compile()
    data = mujoco.MjData(model)
    robot.park(model, data)
    return model, data


_TWINS: dict[tuple[str, frozenset[str]], mujoco.MjModel] = {}


def _twin(domain: Domain, object_ids: Iterable[str]) -> mujoco.MjModel:
    """A world with the robot's visual meshes (coarse: `robot.attach_robot`) and the objects
    `object_ids` (at the origin: the recorder sets every joint from the trial's), for the
    recordings to draw. Compiled once per object set and process, the last set's only, outside
    MuJoCo's mesh cache."""
    key = (domain.name, frozenset(object_ids))
    if key not in _TWINS:
        _TWINS.clear()
        scene = {
            "domain": domain.name,
            "objects": [
                {"id": i, "mesh": domain.object(i).mesh, "pose": np.eye(4)} for i in sorted(key[1])
            ],
        }
        with robot.no_mesh_cache():
            _TWINS[key] = build_spec(
                domain, scene, with_robot=True, robot_visuals="coarse"
            ).compile()
    return _TWINS[key]


def prepare(domain: Domain, *, record: bool = False) -> None:
    """Compile, before a trial holds any memory, what later trials reuse: the robot's inertias
    (`sim.robot.attach_robot(visuals=False)`), the arm's IK model and, for recordings, the
    world they draw. Each
    compile's transient peak (about 200 MB) then does not add to a trial's. Optional: a trial
    compiles what it lacks."""
    _return_large_blocks()
    robot.geom_inertials()
    ik.ik_model()
    if record:
        _twin(domain, domain.object_ids)
    trim_heap()


def trim_heap() -> None:
    """Give the heap's free memory back to the system (glibc's `malloc_trim`). A compile
    leaves tens of thousands of small freed blocks behind, which the allocator otherwise keeps:
    about 60 MB after the robot's inertias and 60 MB after a recording's world. A no-op where
    the C library is not glibc."""
    _glibc("malloc_trim", 0)


def _return_large_blocks() -> None:
    """Have glibc's allocator give blocks of 1 MB or more back to the system when freed.

    By default the threshold for that grows to 32 MB as large blocks are freed, and a trial's
    images and meshes (a few MB each) then stay in the heap after use: a recorded trial peaked
    about 100 MB higher (`rivet eval cubes --trials 2 --workers 1 --record DIR`). No effect
    where the C library is not glibc."""
    m_mmap_threshold = -3  # glibc's malloc.h
    _glibc("mallopt", m_mmap_threshold, 1 << 20)


def _glibc(function: str, *args: int) -> None:
    """Call a glibc allocator function; nothing where the C library has none."""
    libc = _libc()
    if libc is not None and hasattr(libc, function):
        getattr(libc, function)(*args)


@functools.cache
def _libc() -> Any:
    """The C library, loaded once (finding it runs `ldconfig`); None where it cannot be."""
    import ctypes
    import ctypes.util

    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return None


def _final_scene(domain: Domain, instance: Instance, model, data) -> dict:
    """The objects' true poses at the end: scoring."""
    objects = []
    for o in instance.start["objects"]:
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_name(o["id"]))
        pose = np.eye(4)
        pose[:3, :3] = data.xmat[b].reshape(3, 3)
        pose[:3, 3] = data.xpos[b]
        objects.append({"id": o["id"], "mesh": o["mesh"], "pose": pose})
    return {"domain": domain.name, "objects": objects}


def _released(model, data, object_ids) -> bool:
    """No contact between any robot body and any object body (scoring)."""
    objects = {mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_name(i)) for i in object_ids}
    robot_bodies = {b for b in range(model.nbody) if model.body(b).name.startswith(robot.PREFIX)}
    for c in data.contact[: data.ncon]:
        pair = {int(model.geom_bodyid[c.geom1]), int(model.geom_bodyid[c.geom2])}
        if pair & objects and pair & robot_bodies:
            return False
    return True


_QPOS_WIDTH = {
    int(mujoco.mjtJoint.mjJNT_FREE): 7,
    int(mujoco.mjtJoint.mjJNT_BALL): 4,
    int(mujoco.mjtJoint.mjJNT_SLIDE): 1,
    int(mujoco.mjtJoint.mjJNT_HINGE): 1,
}


class _Recorder:
    """Streams the trial, seen from the observation camera at half resolution, into an MP4
    as it is simulated (bounded memory: one frame at a time), at `FPS` frames per simulated
    second, rendered without shadows and reflections (a review video, not an observation).
    Keeps the objects' true poses after each placement (`poses`) for `trial.json`."""

    FPS = 6.0

    def __init__(self, model, twin, camera: Mapping, path: Path) -> None:
        import imageio.v2 as imageio

        # the physics model has no visual meshes: frames are drawn from `twin`, its joints
        # set from the physics model's by name
        names = [model.joint(j).name for j in range(model.njnt)]
        if sorted(names) != sorted(twin.joint(j).name for j in range(twin.njnt)):
            raise SimError("the recording's model does not have the trial's joints")
        src: list[int] = []
        dst: list[int] = []
        for j, name in enumerate(names):
            k, width = twin.joint(name).id, _QPOS_WIDTH[int(model.jnt_type[j])]
            src += range(model.jnt_qposadr[j], model.jnt_qposadr[j] + width)
            dst += range(twin.jnt_qposadr[k], twin.jnt_qposadr[k] + width)
        self._src, self._dst = np.asarray(src), np.asarray(dst)
        self.twin, self.twin_data = twin, mujoco.MjData(twin)

        self.camera = {
            **camera,
            "width": camera["width"] // 2,
            "height": camera["height"] // 2,
            "K": np.asarray(camera["K"], float) * np.array([[0.5], [0.5], [1.0]]),
        }
        # its own GL context, sized to the frame and without multisampling: reading the pixels
        # back from a large multisampled buffer costs a CPU rasteriser more than drawing them
        q = twin.vis.quality
        saved, q.offsamples = q.offsamples, 0
        try:
            self.renderer = Renderer(twin, self.camera["width"], self.camera["height"])
        finally:
            q.offsamples = saved
        path.parent.mkdir(parents=True, exist_ok=True)
        # H.264 in yuv420p needs even sizes only: a 960×540 camera's 480×270 frames are kept
        # as they are, where a block size of 8 had them resized (and warned about) each trial
        self.writer: Any = imageio.get_writer(
            path, fps=self.FPS, codec="libx264", quality=6, macro_block_size=2
        )
        self.last: np.ndarray | None = None
        self.log: list[dict] = []

    def __call__(self, model, data) -> None:
        self.twin_data.qpos[self._dst] = data.qpos[self._src]
        mujoco.mj_kinematics(self.twin, self.twin_data)
        mujoco.mj_comPos(self.twin, self.twin_data)
        self.last = self.renderer.render(self.twin_data, self.camera, depth=False, quick=True)[
            "rgb"
        ]
        self.writer.append_data(self.last)

    def poses(self, label: str, sim_time: float, scene: Mapping) -> None:
        self.log.append({"label": label, "sim_time": round(float(sim_time), 3),
                         "objects": {o["id"]: o["pose"] for o in scene["objects"]}})  # fmt: skip

    def last_rgb(self) -> np.ndarray:
        return self.last if self.last is not None else np.zeros((8, 8, 3), np.uint8)

    def close(self) -> None:
        self.writer.close()
        self.renderer.close()


def _save_png(path: Path, rgb: np.ndarray) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.asarray(rgb, np.uint8)).save(path)
