"""The fixed robot executor: a plan of object transfers becomes FR3 + 2F-85 motion in physics.

Design rule: the executor only commands the robot's actuators and reads the simulation; it
never writes an object's state (objects are never teleported). Each transfer is
grasp selection → approach above → descend → close → lift → transfer at a safe height →
descend → open → retreat, planned kinematically first (so an unreachable step fails before
the arm moves) and then run in physics with joint position control at `control_dt`.

Grasping is by friction. An optional weld assist (off by default, `weld_assist=True`)
welds the object to the gripper only while both finger pads touch it and the jaws are
commanded closed; it is released the moment the jaws are commanded open. After the lift and
again above the target the object's pose in the hand is read from the simulation and the place
pose is corrected for it, standing in for in-hand pose estimation from a wrist camera
(`ExecutorConfig.in_hand_correction`, on by default; off, the executor is open loop and reads
object poses only to plan each grasp). See docs/executor.md for both modes' measured accuracy.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import mujoco
import numpy as np
import trimesh

from contracts import se3
from contracts.errors import UsageError
from geometry.hand import STROKE, Grasp, Obstacle, plan_grasps
from sim import robot
from sim._exec_errors import ExecutionError, FailureKind
from sim._motion import PlanFailure, PlannedSegment, Segment, plan_segments
from sim.ik import ArmIK
from sim.reach import Reach

__all__ = [
    "ExecutionResult",
    "Executor",
    "ExecutorConfig",
    "FrameRecorder",
    "StepFailure",
    "StepOutcome",
]


class FrameRecorder(Protocol):
    """Called at `ExecutorConfig.record_fps` of simulated time, e.g. to render video frames."""

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData) -> None: ...


@dataclass(frozen=True, kw_only=True)
class ExecutorConfig:
    """Timing and geometry of the transfers. Speeds are mean speeds of min-jerk moves."""

    control_dt: float = 0.02  # IK and control period [s]
    move_speed: float = 0.30  # free and transfer moves [m/s]
    approach_speed: float = 0.12  # vertical moves near objects [m/s]
    final_approach: float = 0.015  # the last part of a descent, taken slowly [m]
    final_speed: float = 0.03  # [m/s]
    turn_speed: float = 1.5  # wrist rotation [rad/s]
    min_move_time: float = 0.4  # [s]
    clearance: float = 0.04  # held object and fingers above every other object [m]
    min_transfer_height: float = 0.12  # lowest TCP height of a transfer [m]
    close_time: float = 0.5  # [s]
    grip_settle: float = 0.25  # pause after closing [s]
    open_time: float = 0.5  # [s]
    release_settle: float = 0.15  # pause before and after opening [s]
    release_height: float = 0.001  # the object is let go this far above its target [m]
    in_hand_correction: bool = True  # read the object's pose in the hand (see module doc)
    measure_settle: float = 0.2  # pause before reading the object's pose in the hand [s]
    near_settle: float = 0.15  # the same, at the end of the descent onto the target [s]
    park_after: bool = True
    park_time: float = 1.5  # least time of joint moves between READY and PARK [s]
    joint_speed: float = 1.2  # mean speed of the largest joint in joint moves [rad/s]
    final_settle: float = 0.3  # physics after the last step [s]
    record_fps: float = 30.0
    max_grasp_candidates: int = 12


Phase = Literal[
    "validate", "grasp", "approach", "close", "lift", "transfer", "place", "release", "done"
]


@dataclass(frozen=True, kw_only=True)
class StepFailure:
    """Why a step failed; `kind` is one of `sim._exec_errors.FAILURE_KINDS`."""

    step: int
    object: str
    kind: FailureKind
    phase: Phase
    reason: str

    def to_error(self) -> ExecutionError:
        return ExecutionError(
            step=self.step,
            object_id=self.object,
            kind=self.kind,
            phase=self.phase,
            reason=self.reason,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "step": self.step,
            "object": self.object,
            "kind": self.kind,
            "phase": self.phase,
            "reason": self.reason,
        }


@dataclass(frozen=True, kw_only=True)
class StepOutcome:
    """What one transfer did.

    Attributes:
        position_error / rotation_error / yaw_error: the object's pose right after release
            against its target, modulo the object's symmetries [m], [rad], [rad]; None when
            the step failed before the release.
        grasp: the chosen grasp (None before one was chosen).
        phases: (phase, simulated time at its start [s]) in order, for video annotation.
        weld_engaged: whether the weld assist was active at some point of the step.
    """

    index: int
    object: str
    ok: bool
    failure: StepFailure | None = None
    position_error: float | None = None
    rotation_error: float | None = None
    yaw_error: float | None = None
    grasp: Grasp | None = None
    phases: tuple[tuple[str, float], ...] = ()
    sim_time: float = 0.0
    weld_engaged: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "object": self.object,
            "ok": self.ok,
            "failure": None if self.failure is None else self.failure.to_dict(),
            "position_error": self.position_error,
            "rotation_error": self.rotation_error,
            "yaw_error": self.yaw_error,
            "grasp_width": None if self.grasp is None else self.grasp.width,
            "phases": [list(p) for p in self.phases],
            "sim_time": self.sim_time,
            "weld_engaged": self.weld_engaged,
        }


@dataclass(frozen=True, kw_only=True)
class ExecutionResult:
    """The outcome of a plan: `ok` when every step ran; otherwise `failure` names the first
    failing step (later steps are not attempted)."""

    ok: bool
    steps: tuple[StepOutcome, ...]
    failure: StepFailure | None
    sim_time: float  # [s]
    wall_time: float  # [s]
    weld_assist: bool
    frames: int = 0  # calls made to the recorder

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("inf")

    def raise_for_failure(self) -> None:
        if self.failure is not None:
            raise self.failure.to_error()

    def to_dict(self) -> dict[str, Any]:
        return {
            "ok": self.ok,
            "failure": None if self.failure is None else self.failure.to_dict(),
            "steps": [s.to_dict() for s in self.steps],
            "sim_time": self.sim_time,
            "wall_time": self.wall_time,
            "realtime_factor": self.realtime_factor,
            "weld_assist": self.weld_assist,
            "frames": self.frames,
        }


class _StepAbort(Exception):
    def __init__(self, kind: FailureKind, phase: Phase, reason: str, grasp: Grasp | None = None):
        super().__init__(reason)
        self.kind, self.phase, self.reason, self.grasp = kind, phase, reason, grasp


@dataclass
class _Held:
    body: int
    geoms: frozenset[int]
    weld_on: bool = False
    weld_engaged: bool = False


@dataclass
class _Tracker:
    phases: list[tuple[str, float]] = field(default_factory=list)


class Executor:
    """Runs plans of object transfers on a scene built with `sim.robot.attach_robot`.

    Args:
        model, data: the scene; objects are free bodies named by their record ids (or
            ``object/<id>``, as `sim.scene` names them).
        meshes: object id → its mesh (object frame), or → (mesh, symmetry transforms (n, 4, 4)).
            Every object the plan may move or the gripper may meet should be listed.
        weld_assist: weld the object to the gripper while both pads touch it (see module doc).
        record: called at `config.record_fps` of simulated time (video frames).
        config: timings and geometry.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        meshes: Mapping[str, trimesh.Trimesh | tuple[trimesh.Trimesh, Sequence[np.ndarray]]],
        *,
        weld_assist: bool = False,
        record: FrameRecorder | None = None,
        config: ExecutorConfig | None = None,
    ) -> None:
        self.model, self.data = model, data
        self.config = config or ExecutorConfig()
        self.weld_assist = weld_assist
        self.record = record
        self.index = robot.RobotIndex.from_model(model)
        if weld_assist and self.index.weld < 0:
            raise UsageError(f"weld_assist needs the equality {robot.WELD_ASSIST!r} in the model")
        self.meshes: dict[str, trimesh.Trimesh] = {}
        self.symmetries: dict[str, list[np.ndarray]] = {}
        self.bodies: dict[str, int] = {}
        for oid, value in meshes.items():
            mesh, syms = value if isinstance(value, tuple) else (value, None)
            body = _find_body(model, oid)
            if body < 0:
                continue  # not in this scene: a plan naming it fails as an unknown object
            self.meshes[oid] = mesh
            self.symmetries[oid] = [np.eye(4)] if syms is None else [np.asarray(S) for S in syms]
            self.bodies[oid] = body
        self._body_geoms = {
            oid: frozenset(np.flatnonzero(model.geom_bodyid == b).tolist())
            for oid, b in self.bodies.items()
        }
        self.ik = ArmIK()
        self.reach = Reach(self.ik)
        dt = model.opt.timestep
        self._substeps = max(1, round(self.config.control_dt / dt))
        self._tick_dt = self._substeps * dt
        self._q_cmd = data.qpos[self.index.arm_qpos].copy()
        acts = self.index.arm_actuators
        self._servo_lag = -model.actuator_biasprm[acts, 2] / model.actuator_gainprm[acts, 0]
        self._grip_cmd = float(data.ctrl[self.index.gripper_actuator])
        self._held: _Held | None = None
        self._step_welded = False
        self._tracker = _Tracker()
        self._next_frame = data.time
        self._frames = 0
        self._pads_left = np.array(sorted(self.index.left_pads))
        self._pads_right = np.array(sorted(self.index.right_pads))

    # -- public -----------------------------------------------------------------------------

    def execute(self, plan: Any) -> ExecutionResult:
        """Run `plan` ({"status": "ok", "steps": [...]}, a list of steps, or an OkPlan)."""
        steps = _plan_steps(plan)
        wall0, sim0 = time.perf_counter(), self.data.time
        outcomes: list[StepOutcome] = []
        failure: StepFailure | None = None
        targets: list[np.ndarray] = []
        for i, (oid, raw) in enumerate(steps):
            failure = self._validate(i, oid, raw)
            if failure is not None:
                outcomes.append(StepOutcome(index=i, object=oid, ok=False, failure=failure))
                break
            targets.append(_orthonormalize(se3.as_matrix(raw)))
        if failure is None:
            for i, ((oid, _), target) in enumerate(zip(steps, targets, strict=True)):
                outcome = self._transfer(i, oid, target)
                outcomes.append(outcome)
                if not outcome.ok:
                    failure = outcome.failure
                    break
        self._finish(park=self.config.park_after)
        return ExecutionResult(
            ok=failure is None,
            steps=tuple(outcomes),
            failure=failure,
            sim_time=self.data.time - sim0,
            wall_time=time.perf_counter() - wall0,
            weld_assist=self.weld_assist,
            frames=self._frames,
        )

    def object_pose(self, oid: str) -> np.ndarray:
        """Current world pose (4, 4) of an object, from the simulation."""
        b = self.bodies[oid]
        return se3.make(self.data.xmat[b].reshape(3, 3), self.data.xpos[b])

    # -- validation -------------------------------------------------------------------------

    def _validate(self, i: int, oid: str, raw: Any) -> StepFailure | None:
        if oid not in self.bodies:
            known = ", ".join(sorted(self.bodies)) or "(none)"
            return StepFailure(
                step=i,
                object=str(oid),
                kind="unknown_object",
                phase="validate",
                reason=f"unknown object id {oid!r}; known: {known}",
            )
        try:
            T = se3.as_matrix(raw)
        except (ValueError, TypeError) as exc:
            return StepFailure(
                step=i,
                object=oid,
                kind="non_rigid_target",
                phase="validate",
                reason=f"target_pose is not a 4x4 matrix: {exc}",
            )
        if not se3.is_rigid(T, tol=1e-3):
            ortho, det = se3.rotation_defect(T[:3, :3]) if np.all(np.isfinite(T)) else (np.nan,) * 2
            return StepFailure(
                step=i,
                object=oid,
                kind="non_rigid_target",
                phase="validate",
                reason=f"target_pose is not a proper rigid transform (max |RᵀR−I| = {ortho:.3g}, "
                f"det R = {det:.3g}, last row {np.round(T[3], 6).tolist()})",
            )
        return None

    # -- one transfer -----------------------------------------------------------------------

    def _transfer(self, i: int, oid: str, target: np.ndarray) -> StepOutcome:
        self._tracker = _Tracker()
        self._step_welded = False
        t0 = self.data.time
        grasp: Grasp | None = None
        try:
            self._unpark()
            grasp, planned, transfer_z, long_way = self._choose(i, oid, target)
            self._run_phase("approach", planned[:-3])
            self._mark("close")
            self._held = _Held(body=self.bodies[oid], geoms=self._body_geoms[oid])
            self._run(planned[-3:-1])
            if not self._both_pads_touch():
                raise _StepAbort("grasp_failed", "close", "the pads do not both touch the object")
            z_grasp = self.object_pose(oid)[2, 3]
            self._run_phase("lift", planned[-1:])
            rise = self.object_pose(oid)[2, 3] - z_grasp
            expected = transfer_z - grasp.pick_tcp[2, 3]
            if rise < 0.5 * expected:
                raise _StepAbort(
                    "grasp_failed",
                    "lift",
                    f"the object rose {rise * 1000:.0f} mm of {expected * 1000:.0f} mm",
                )
            self._settle(self.config.measure_settle)
            place = self._place_segments(oid, grasp, target, transfer_z, long_way=long_way)
            self._run_phase("transfer", place[:1])
            self._settle(self.config.measure_settle)
            in_hand = se3.inverse(robot.tcp_pose(self.data, self.index)) @ self.object_pose(oid)
            if np.linalg.norm(in_hand[:3, 3] - se3.inverse(grasp.T_object_tcp)[:3, 3]) > 0.03:
                raise _StepAbort("dropped", "transfer", "the object left the hand")
            if self.config.in_hand_correction:  # again, for any slip during the transfer
                place = place[:1] + self._place_segments(oid, grasp, target, transfer_z, skip=1)
            self._run_phase("place", place[1:2])
            if self.config.in_hand_correction:
                # and once more before the last slow centimetres: the descent sways the object
                # in the hand and the arm off its path by up to a millimetre, and tangram
                # pieces go into gaps of half a millimetre
                self._settle(self.config.near_settle)
                place = place[:2] + self._place_segments(oid, grasp, target, transfer_z, skip=2)
            self._run(place[2:3])
            self._mark("release")
            self._run(place[3:6])
            self._held = None
            self._run(place[6:])
        except _StepAbort as abort:
            self._held_release()
            failure = StepFailure(
                step=i, object=oid, kind=abort.kind, phase=abort.phase, reason=abort.reason
            )
            return StepOutcome(
                index=i,
                object=oid,
                ok=False,
                failure=failure,
                grasp=abort.grasp or grasp,
                phases=tuple(self._tracker.phases),
                sim_time=self.data.time - t0,
            )
        weld = self._step_welded
        pos, rot, yaw = self._placement_error(oid, target)
        self._mark("done")
        return StepOutcome(
            index=i,
            object=oid,
            ok=True,
            position_error=pos,
            rotation_error=rot,
            yaw_error=yaw,
            grasp=grasp,
            phases=tuple(self._tracker.phases),
            sim_time=self.data.time - t0,
            weld_engaged=weld,
        )

    def _unpark(self) -> None:
        """From a posture that does not point the gripper down (e.g. parked), move to READY in
        joint space: Cartesian moves start from there."""
        T = self.ik.fk(self._q_cmd)
        if T[2, 2] < -np.cos(np.radians(15.0)):
            return
        self._mark("unpark")
        far = float(np.max(np.abs(self._q_cmd - robot.READY_QPOS)))
        seg = Segment(
            label="to ready",
            q_goal=robot.READY_QPOS,
            duration=max(self.config.park_time, far / self.config.joint_speed),
        )
        planned = plan_segments(self.ik, self._q_cmd, [seg], self._tick_dt)
        assert not isinstance(planned, PlanFailure)  # joint moves always plan
        self._run(planned)

    def _choose(
        self, i: int, oid: str, target: np.ndarray
    ) -> tuple[Grasp, list[PlannedSegment], float, bool]:
        """Pick the best grasp whose whole motion has IK solutions, and plan up to the lift.

        Per grasp, best first: Cartesian moves all along; the transfer turning the wrist the
        long way round; then the move above the object in joint space (`_through_joint_space`),
        with either transfer. Returns the grasp, the planned pick, the transfer height and
        whether the transfer turns the long way."""
        self._mark("grasp")
        T_pick = self.object_pose(oid)
        others = [
            Obstacle(id=o, mesh=self.meshes[o], pose=self.object_pose(o))
            for o in self.bodies
            if o != oid
        ]
        report = plan_grasps(
            self.meshes[oid],
            T_pick,
            target,
            symmetries=self.symmetries[oid],
            pick_obstacles=others,
            place_obstacles=others,
        )
        if not report.grasps:
            raise _StepAbort("no_grasp", "grasp", f"no feasible top-down grasp: {report.summary()}")
        tops = [float(_world_vertices(o.mesh, o.pose)[:, 2].max()) for o in others]
        candidates, unreachable = self._rank_by_wrist(report.grasps)
        if not candidates:
            raise _StepAbort("unreachable", "grasp", unreachable)
        first_failure: PlanFailure | None = None
        for grasp in candidates[: self.config.max_grasp_candidates]:
            transfer_z = self._transfer_height(oid, grasp, T_pick, tops)
            segments = self._pick_segments(grasp, transfer_z)
            # the long way round only helps for a turn of more than a quarter
            ways = (False, True) if abs(grasp.transfer_yaw) > np.pi / 2 else (False,)
            places = {w: self._place_motion(grasp, grasp.place_tcp, transfer_z, w) for w in ways}
            for long_way in ways:
                planned = plan_segments(
                    self.ik, self._q_cmd, segments + places[long_way], self._tick_dt
                )
                if not isinstance(planned, PlanFailure):
                    return grasp, planned[: len(segments)], transfer_z, long_way
                first_failure = first_failure or planned
            for long_way in ways:
                alternative = self._through_joint_space(segments, places[long_way])
                if alternative is not None:
                    return grasp, alternative[: len(segments)], transfer_z, long_way
        assert first_failure is not None
        raise _StepAbort(
            "unreachable",
            "grasp",
            f"{first_failure.describe()} (best of {min(len(candidates), self.config.max_grasp_candidates)} grasps)",
        )

    def _through_joint_space(
        self, segments: list[Segment], place: list[Segment]
    ) -> list[PlannedSegment] | None:
        """The pick and place again, but with the move above the object made in joint space to
        a fresh IK solution, for when the Cartesian move from the current arm configuration
        runs a joint into its limit (typically the wrist, which the transfer then has to turn
        further) or the descent from it does. Seeds turn the wrist a quarter or a half turn
        either way from READY; the joint move must keep the TCP within 2 cm of the transfer
        height. None when no seed gives a plan."""
        c = self.config
        k = next(i for i, seg in enumerate(segments) if seg.label == "moving above the object")
        before = plan_segments(self.ik, self._q_cmd, segments[:k], self._tick_dt)
        if isinstance(before, PlanFailure):
            return None
        q_from = before[-1].q[-1] if before else self._q_cmd
        above = segments[k].goal
        assert above is not None
        z_low = min(self.ik.fk(q_from)[2, 3], above[2, 3]) - 0.02
        lo, hi = self.index.arm_range[6]
        for turn in (0.0, -np.pi / 2, np.pi / 2, -np.pi, np.pi):
            seed = robot.READY_QPOS.copy()
            seed[0] = np.arctan2(above[1, 3], above[0, 3])
            seed[6] = np.clip(seed[6] + turn, lo + 0.1, hi - 0.1)
            sol = self.ik.solve(above, seed)
            if not sol.ok:
                continue
            far = float(np.max(np.abs(sol.q - q_from)))
            n = max(2, int(np.ceil(far / 0.02)))
            path = q_from + np.linspace(0.0, 1.0, n)[:, None] * (sol.q - q_from)
            if min(self.ik.fk(q)[2, 3] for q in path) < z_low:
                continue  # the joint move would dip towards the objects
            joint_move = Segment(
                label=segments[k].label,
                q_goal=sol.q,
                duration=max(c.min_move_time, far / c.joint_speed),
                grip=segments[k].grip,
            )
            planned = plan_segments(
                self.ik,
                self._q_cmd,
                [*segments[:k], joint_move, *segments[k + 1 :], *place],
                self._tick_dt,
            )
            if not isinstance(planned, PlanFailure):
                return planned
        return None

    def _rank_by_wrist(self, grasps: Sequence[Grasp]) -> tuple[list[Grasp], str]:
        """Drop grasps whose pick or place pose has no IK solution (`sim.reach`, the test the
        plan checks use too); among equally good ones prefer the wrist angle farthest from its
        limits (the 2F-85's half-turn symmetry gives two wrist angles per grasp)."""
        ranked, reason = [], ""
        for g in grasps[: 2 * self.config.max_grasp_candidates]:
            reached = self.reach.grasp(g, wrist=tuple(self.index.arm_range[6]))
            if reached.ok:
                ranked.append((round(g.score, 3), reached.wrist_margin, g))
            else:
                reason = reason or reached.reason
        ranked.sort(key=lambda r: (-r[0], -r[1]))
        return [r[2] for r in ranked], reason

    def _transfer_height(
        self, oid: str, grasp: Grasp, T_pick: np.ndarray, tops: Sequence[float]
    ) -> float:
        c = self.config
        bottom = float(_world_vertices(self.meshes[oid], T_pick)[:, 2].min())
        hang = max(grasp.pick_tcp[2, 3] - bottom, STROKE.tip_at_gap(grasp.width))
        z = max([*tops, 0.0]) + hang + c.clearance
        return max(
            z, c.min_transfer_height, grasp.pick_tcp[2, 3] + 0.05, grasp.place_tcp[2, 3] + 0.05
        )

    def _pick_segments(self, grasp: Grasp, z: float) -> list[Segment]:
        """Approach (rise, move above, descend, reach), then close, squeeze, lift: the last
        three segments are always close, squeeze, lift."""
        c = self.config
        open_ctrl = STROKE.ctrl_for_gap(grasp.open_gap)
        T_now = self.ik.fk(self._q_cmd)
        above = grasp.pick_tcp.copy()
        above[2, 3] = z
        near = grasp.pick_tcp.copy()
        near[2, 3] += c.final_approach
        segs = []
        if z - T_now[2, 3] > 0.001:
            up = T_now.copy()
            up[2, 3] = z
            segs.append(
                Segment(
                    label="rising to the transfer height",
                    goal=up,
                    duration=self._duration(T_now, up, c.approach_speed),
                )
            )
            T_now = up
        segs += [
            Segment(
                label="moving above the object",
                goal=above,
                duration=self._duration(T_now, above, c.move_speed),
            ),
            Segment(
                label="descending onto the object",
                goal=near,
                duration=self._duration(above, near, c.approach_speed),
            ),
        ]
        segs[0] = Segment(
            label=segs[0].label,
            goal=segs[0].goal,
            duration=segs[0].duration,
            grip=(self._grip_cmd, open_ctrl),
        )
        return [
            *segs,
            Segment(
                label="reaching the grasp",
                goal=grasp.pick_tcp,
                duration=max(c.final_approach / c.final_speed, 0.2),
            ),
            Segment(label="closing", duration=c.close_time, grip=(open_ctrl, robot.GRIPPER_CLOSED)),
            Segment(label="squeezing", duration=c.grip_settle),
            Segment(
                label="lifting",
                goal=above,
                duration=self._duration(grasp.pick_tcp, above, c.approach_speed),
            ),
        ]

    def _place_motion(
        self, grasp: Grasp, place_tcp: np.ndarray, z: float, long_way: bool = False
    ) -> list[Segment]:
        """transfer, descend, final descent, pause, open, pause, retreat; the transfer turns the
        wrist the long way round with `long_way`."""
        c = self.config
        open_ctrl = STROKE.ctrl_for_gap(grasp.open_gap)
        release = place_tcp.copy()
        release[2, 3] += c.release_height
        above = release.copy()
        above[2, 3] = z
        near = release.copy()
        near[2, 3] += c.final_approach
        lifted = grasp.pick_tcp.copy()
        lifted[2, 3] = z
        turn = None
        if long_way:
            R = above[:3, :3] @ lifted[:3, :3].T
            short = float(np.arctan2(R[1, 0], R[0, 0]))
            turn = short - np.copysign(2 * np.pi, short)
        return [
            Segment(
                label="transferring",
                goal=above,
                duration=max(
                    self._duration(lifted, above, c.move_speed),
                    0.0 if turn is None else abs(turn) / c.turn_speed,
                ),
                turn=turn,
            ),
            Segment(
                label="descending to the target",
                goal=near,
                duration=self._duration(above, near, c.approach_speed),
            ),
            Segment(
                label="reaching the target",
                goal=release,
                duration=max(c.final_approach / c.final_speed, 0.2),
            ),
            Segment(label="settling before release", duration=c.release_settle),
            Segment(label="opening", duration=c.open_time, grip=(robot.GRIPPER_CLOSED, open_ctrl)),
            Segment(label="settling after release", duration=c.release_settle),
            Segment(
                label="retreating",
                goal=above,
                duration=self._duration(release, above, c.approach_speed),
            ),
        ]

    def _place_segments(
        self,
        oid: str,
        grasp: Grasp,
        target: np.ndarray,
        z: float,
        *,
        skip: int = 0,
        long_way: bool = False,
    ) -> list[PlannedSegment]:
        """Plan the place from the current pose, corrected for the object's pose in the hand:
        from after the lift, or with `skip` 1 from above the target, 2 from the end of the
        descent (`final_approach` above the release); the transfer turns the wrist the long
        way round with `long_way`."""
        nominal = grasp.place_tcp
        candidates = []
        if self.config.in_hand_correction:
            # Against the measured TCP: the arm may still lag its command after a move.
            T_tcp = robot.tcp_pose(self.data, self.index)
            in_hand = se3.inverse(T_tcp) @ self.object_pose(oid)  # object in the TCP frame
            T_place = target @ self.symmetries[oid][grasp.symmetry]
            corrected = T_place @ se3.inverse(in_hand)
            tilt = np.arccos(np.clip(-corrected[2, 2], -1.0, 1.0))
            if tilt < np.radians(10.0):
                candidates.append(corrected)
        candidates.append(nominal)
        failure: PlanFailure | None = None
        for place_tcp in candidates:
            motion = self._place_motion(grasp, place_tcp, z, long_way)
            planned = plan_segments(self.ik, self._q_cmd, motion[skip:], self._tick_dt)
            if not isinstance(planned, PlanFailure):
                return planned
            failure = failure or planned
        assert failure is not None
        raise _StepAbort("unreachable", "transfer", failure.describe(), grasp)

    def _duration(self, T0: np.ndarray, T1: np.ndarray, speed: float) -> float:
        c = self.config
        dist = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3]))
        angle = se3.rotation_angle(T0[:3, :3].T @ T1[:3, :3])
        return max(c.min_move_time, dist / speed, angle / c.turn_speed)

    # -- running in physics ------------------------------------------------------------------

    def _mark(self, phase: str) -> None:
        self._tracker.phases.append((phase, float(self.data.time)))

    def _run_phase(self, phase: str, planned: Sequence[PlannedSegment]) -> None:
        self._mark(phase)
        self._run(planned)

    def _run(self, planned: Sequence[PlannedSegment]) -> None:
        m, d = self.model, self.data
        arm_act, grip_act = self.index.arm_actuators, self.index.gripper_actuator
        n = self._substeps
        fractions = np.arange(1, n + 1) / n
        for seg in planned:
            for k in range(len(seg.q)):
                q_prev, q_next = self._q_cmd, seg.q[k]
                # The position servos damp the joint velocity itself (-kv q̇): feeding the
                # planned velocity forward (kv/kp · q̇_d) removes the lag that would leave.
                lead = self._servo_lag * (q_next - q_prev) / self._tick_dt
                self._q_cmd = q_next
                if seg.grip is not None:
                    self._grip_cmd = float(seg.grip[k])
                d.ctrl[grip_act] = self._grip_cmd
                self._update_weld()
                for f in fractions:
                    d.ctrl[arm_act] = q_prev + f * (q_next - q_prev) + lead
                    mujoco.mj_step(m, d)
                self._maybe_record()
        d.ctrl[arm_act] = self._q_cmd

    def _settle(self, duration: float) -> None:
        n = max(1, round(duration / self._tick_dt))
        hold = PlannedSegment(
            segment=Segment(label="settling", duration=duration),
            q=np.repeat(self._q_cmd[None], n, axis=0),
            grip=None,
        )
        self._run([hold])

    def _maybe_record(self) -> None:
        if self.record is None:
            return
        if self.data.time + 1e-9 >= self._next_frame:
            self.record(self.model, self.data)
            self._frames += 1
            self._next_frame += 1.0 / self.config.record_fps

    # -- grasp state and the weld assist ----------------------------------------------------

    def _pad_contacts(self, geoms: frozenset[int]) -> tuple[bool, bool]:
        d = self.data
        n = d.ncon
        if n == 0:
            return False, False
        g = d.contact.geom[:n]  # (n, 2)
        obj = np.isin(g, list(geoms))
        left = np.isin(g, self._pads_left)
        right = np.isin(g, self._pads_right)
        touch_left = bool(np.any((obj[:, 0] & left[:, 1]) | (obj[:, 1] & left[:, 0])))
        touch_right = bool(np.any((obj[:, 0] & right[:, 1]) | (obj[:, 1] & right[:, 0])))
        return touch_left, touch_right

    def _both_pads_touch(self) -> bool:
        return self._held is not None and all(self._pad_contacts(self._held.geoms))

    def _update_weld(self) -> None:
        held = self._held
        if not self.weld_assist or held is None:
            return
        # Commanded fully closed and both pads on the object: weld; anything else: release.
        closing = self._grip_cmd >= robot.GRIPPER_CLOSED - 1e-6
        want = closing and self._both_pads_touch()
        if want and not held.weld_on:
            self._weld_on(held)
        elif held.weld_on and not want:
            self._weld_off(held)

    def _weld_on(self, held: _Held) -> None:
        m, d, eq = self.model, self.data, self.index.weld
        g = self.index.gripper_base
        T1 = se3.make(d.xmat[g].reshape(3, 3), d.xpos[g])
        T2 = se3.make(d.xmat[held.body].reshape(3, 3), d.xpos[held.body])
        rel = se3.inverse(T1) @ T2  # the object in the gripper's frame, kept while welded
        m.eq_obj2id[eq] = held.body
        data = m.eq_data[eq]
        data[:3] = 0.0  # anchor at the object's origin
        data[3:6] = rel[:3, 3]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, rel[:3, :3].ravel())
        data[6:10] = quat
        data[10] = 1.0  # torque scale
        d.eq_active[eq] = 1
        held.weld_on = True
        held.weld_engaged = True
        self._step_welded = True

    def _weld_off(self, held: _Held | None) -> None:
        eq = self.index.weld
        if eq < 0:
            return
        self.data.eq_active[eq] = 0
        self.model.eq_obj2id[eq] = 0
        if held is not None:
            held.weld_on = False

    def _held_release(self) -> None:
        self._weld_off(self._held)
        self._held = None

    # -- end of a plan ----------------------------------------------------------------------

    def _finish(self, *, park: bool) -> None:
        self._held_release()
        parked = float(np.max(np.abs(self._q_cmd - robot.PARK_QPOS))) < 1e-2
        if park and not parked:
            c = self.config
            T_now = self.ik.fk(self._q_cmd)
            up = T_now.copy()
            up[2, 3] = max(up[2, 3], c.min_transfer_height)
            segs = [
                Segment(
                    label="rising",
                    goal=up,
                    duration=self._duration(T_now, up, c.approach_speed),
                    grip=(self._grip_cmd, robot.GRIPPER_OPEN),
                ),
            ]
            planned = plan_segments(self.ik, self._q_cmd, segs, self._tick_dt)
            if isinstance(planned, PlanFailure):
                planned = []
            q_from = planned[-1].q[-1] if planned else self._q_cmd
            far = float(np.max(np.abs(q_from - robot.READY_QPOS)))
            to_ready = Segment(
                label="to ready",
                q_goal=robot.READY_QPOS,
                duration=max(c.park_time, far / c.joint_speed),
            )
            to_park = Segment(label="parking", q_goal=robot.PARK_QPOS, duration=c.park_time)
            rest = plan_segments(self.ik, q_from, [to_ready, to_park], self._tick_dt)
            assert not isinstance(rest, PlanFailure)  # joint moves always plan
            self._run([*planned, *rest])
        self._settle(self.config.final_settle)

    def _placement_error(self, oid: str, target: np.ndarray) -> tuple[float, float, float]:
        T = self.object_pose(oid)
        syms = self.symmetries[oid]
        pos, rot = se3.pose_error(T, target, syms)
        yaw = min(
            abs(_wrap(se3.yaw(T) - se3.yaw(target @ S)))
            for S in syms
            if np.linalg.norm(T[:3, 3] - (target @ S)[:3, 3]) <= pos + 1e-6
        )
        return pos, rot, float(yaw)


# -- helpers ----------------------------------------------------------------------------------


def _merge(a: Segment, b: Segment) -> Segment:
    """Two moves as one label (keeps the first's gripper ramp)."""
    return Segment(label=b.label, goal=b.goal, duration=a.duration + b.duration, grip=a.grip)


OBJECT_BODY_NAMES = ("{id}", "object/{id}")
"""How an object's body may be named in the model (the first that exists is used)."""


def _find_body(model: mujoco.MjModel, oid: str) -> int:
    for pattern in OBJECT_BODY_NAMES:
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, pattern.format(id=oid))
        if body >= 0:
            return body
    return -1


def _wrap(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


def _world_vertices(mesh: trimesh.Trimesh, T: np.ndarray) -> np.ndarray:
    return np.asarray(mesh.vertices) @ T[:3, :3].T + T[:3, 3]


def _orthonormalize(T: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(T[:3, :3])
    out = T.copy()
    out[:3, :3] = U @ Vt
    out[3] = [0.0, 0.0, 0.0, 1.0]
    return out


def _plan_steps(plan: Any) -> list[tuple[str, Any]]:
    """(object id, raw target) per step, from the accepted plan forms."""
    steps: Any = plan
    if isinstance(plan, Mapping):
        if plan.get("status") != "ok":
            raise UsageError(f"only an ok plan can be executed, got status {plan.get('status')!r}")
        steps = plan.get("steps")
    elif hasattr(plan, "steps"):
        steps = plan.steps
    if not isinstance(steps, Sequence) or isinstance(steps, (str, bytes)):
        raise UsageError("a plan is a list of steps {'object': id, 'target_pose': 4x4}")
    out = []
    for k, s in enumerate(steps):
        if isinstance(s, Mapping):
            if "object" not in s or "target_pose" not in s:
                raise UsageError(f"plan step {k} needs 'object' and 'target_pose'")
            out.append((str(s["object"]), s["target_pose"]))
        elif hasattr(s, "object") and hasattr(s, "target_pose"):
            out.append((str(s.object), s.target_pose))
        else:
            raise UsageError(f"plan step {k} is not a step: {s!r}")
    return out
