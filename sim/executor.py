"""The fixed robot executor: a plan of object transfers becomes FR3 + 2F-85 motion in physics.

Design rule: the executor acts only on what the robot could know. It keeps a *belief* of where
each object is — its perceived start pose (the policy's own `perceive` output) until it moves
it, then the target of the step that moved it — and plans every pick, grasp and obstacle from
that belief (`sim.transfer`). It senses only through `sim.sensing`: the gripper's own signals
(jaw opening, pad contact) to detect a failed or lost grasp, and, when configured, a wrist
camera's noisy in-hand pose estimate to correct the place (`ExecutorConfig.in_hand`, on by
default) or an explicit ground-truth object tracker (`ExecutorConfig.track_objects`, off by
default: the oracle-sensing protocol). It commands the robot's actuators and never writes an
object's state (objects are never teleported).

The belief is in the frame of the camera that perceived it, and a camera's calibration is off
by a few millimetres (`sim.realism`): every perceived pose, start and goal alike, is shifted by
about the same offset, which no program can see in the image. The robot can: with the jaws
open around an object it is about to grasp, the wrist camera reads where the object is in the
hand, so where it is on the table (the arm's own kinematics), and the difference from the
belief is a reading of that offset (`ExecutorConfig.camera_offset`). The executor keeps the
median of its readings and acts on the belief and the targets shifted by it, so a figure is
built where the goal image showed it, not a calibration error away. Only objects whose belief
came from perception give readings (not one the robot itself put down), and a reading farther
from the belief than `camera_offset_max` is that object misperceived, not the camera.

Each transfer is grasp selection → approach above → descend → close → lift → transfer at a
safe height → descend → open → retreat, planned kinematically first (so an unreachable step
fails before the arm moves) and then run in physics with joint position control at
`control_dt`. Grasping is by friction; the optional weld assist (`sim.weld`, off by default)
is a physics aid. See docs/executor.md.

`execute` takes a wall-clock deadline: no transfer and no phase of one starts after it, so a
long plan (or a slow machine) ends the plan with a ``deadline`` failure instead of holding its
caller; the arm is still parked.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
import trimesh

from contracts import se3
from contracts.errors import UsageError
from contracts.limits import clip
from geometry.grasps import Grasp
from sim import robot
from sim._motion import PlanFailure, PlannedSegment, Segment, plan_segments, split_at
from sim.execution import (
    ExecutionResult,
    ExecutorConfig,
    FrameRecorder,
    Phase,
    StepFailure,
    StepOutcome,
)
from sim.ik import ArmIK
from sim.sensing import Sensors
from sim.transfer import (
    CLOSING,
    DESCENDING,
    LIFTING,
    REACHING,
    RETREATING,
    SETTLING,
    TransferAbort,
    TransferPlanner,
    obstacles,
)

__all__ = [
    "ExecutionResult",
    "Executor",
    "ExecutorConfig",
    "FrameRecorder",
    "Sensors",
    "StepFailure",
    "StepOutcome",
]


@dataclass
class _Tracker:
    phases: list[tuple[str, float]] = field(default_factory=list)


class _StepAbort(Exception):
    def __init__(self, kind: str, phase: Phase, reason: str, grasp: Grasp | None = None):
        super().__init__(reason)
        self.kind, self.phase, self.reason, self.grasp = kind, phase, reason, grasp


class Executor:
    """Runs plans of object transfers on a scene built with `sim.robot.attach_robot`.

    Args:
        model, data: the scene.
        meshes: object id → its mesh (object frame), or → (mesh, symmetry transforms (n, 4, 4)),
            for every object of the scene.
        belief: object id → the pose (4, 4) the robot believes it has: the perceived start
            state (an object missing from it cannot be picked).
        sensors: what the robot senses (`Sensors.of(...)` builds them for a scene).
        record: called at `config.record_fps` of simulated time (video frames).
        config: timings, geometry and sensing.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        meshes: Mapping[str, trimesh.Trimesh | tuple[trimesh.Trimesh, Sequence[np.ndarray]]],
        *,
        belief: Mapping[str, Any],
        sensors: Sensors,
        record: FrameRecorder | None = None,
        config: ExecutorConfig | None = None,
    ) -> None:
        self.model, self.data = model, data
        self.config = config or ExecutorConfig()
        self.record = record
        self.sensors = sensors
        self.index = robot.RobotIndex.from_model(model)
        self.meshes: dict[str, trimesh.Trimesh] = {}
        self.symmetries: dict[str, list[np.ndarray]] = {}
        for oid, value in meshes.items():
            mesh, syms = value if isinstance(value, tuple) else (value, None)
            if oid not in sensors.objects:
                continue  # not in this scene: a plan naming it fails as an unknown object
            self.meshes[oid] = mesh
            self.symmetries[oid] = [np.eye(4)] if syms is None else [np.asarray(S) for S in syms]
        self.belief: dict[str, np.ndarray] = {
            str(oid): np.asarray(T, dtype=float) for oid, T in belief.items() if oid in self.meshes
        }
        self.ik = ArmIK()
        dt = model.opt.timestep
        self._substeps = max(1, round(self.config.control_dt / dt))
        self._tick_dt = self._substeps * dt
        self.transfers = TransferPlanner(
            self.ik, self.config, tuple(self.index.arm_range[6]), self._tick_dt
        )
        self._q_cmd = data.qpos[self.index.arm_qpos].copy()
        acts = self.index.arm_actuators
        self._servo_lag = -model.actuator_biasprm[acts, 2] / model.actuator_gainprm[acts, 0]
        self._grip_cmd = float(data.ctrl[self.index.gripper_actuator])
        self._tracker = _Tracker()
        self._readings: list[np.ndarray] = []  # camera offset readings (x, y) [m]
        self._placed: dict[str, np.ndarray] = {}  # object → the target it was put at (belief)
        self._next_frame = data.time
        self._frames = 0
        self._deadline: float | None = None
        self._oid = ""
        self.on_phase: Callable[[Executor, str, str], None] | None = None
        """Called as `on_phase(executor, phase, object)` at the start of each phase of a
        transfer (and "done" at its end): the world's hook for faults (`sim.faults`)."""
        self.grip_override: float | None = None
        """A gripper command that replaces the executor's own while set: a fault (the hand
        letting go), never the executor's decision."""

    @property
    def weld_assist(self) -> bool:
        return self.sensors.weld is not None

    # -- public -----------------------------------------------------------------------------

    def execute(self, plan: Any, *, deadline: float | None = None) -> ExecutionResult:
        """Run `plan` ({"status": "ok", "steps": [...]} or a list of steps).

        Args:
            deadline: a `time.perf_counter()` value [s] after which no transfer or phase of
                one starts (the step then fails with kind ``deadline``); None: none.
        """
        steps = _plan_steps(plan)
        wall0, sim0 = time.perf_counter(), self.data.time
        self._deadline = deadline
        outcomes: list[StepOutcome] = []
        failure: StepFailure | None = None
        targets: list[np.ndarray] = []
        for i, (oid, raw) in enumerate(steps):
            failure = self._validate(i, oid, raw)
            if failure is not None:
                outcomes.append(
                    StepOutcome(index=i, object=failure.object, ok=False, failure=failure)
                )
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

    # -- validation -------------------------------------------------------------------------

    def _validate(self, i: int, oid: str, raw: Any) -> StepFailure | None:
        if oid not in self.meshes:
            known = ", ".join(sorted(self.meshes)) or "(none)"
            return StepFailure(
                step=i,
                object=clip(str(oid), 128),
                kind="unknown_object",
                phase="validate",
                reason=f"unknown object id {clip(repr(oid))}; known: {known}",
            )
        try:
            T = se3.as_matrix(raw)
        except (ValueError, TypeError) as exc:
            return StepFailure(
                step=i,
                object=oid,
                kind="non_rigid_target",
                phase="validate",
                reason=f"target_pose is not a 4x4 matrix: {clip(str(exc))}",
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
        self._oid = oid
        t0 = self.data.time
        grasp: Grasp | None = None
        weld = self.sensors.weld
        try:
            self._check_deadline("grasp")
            self._unpark()
            self._mark("grasp")
            if self.config.track_objects and self.sensors.tracker is not None:
                self.belief.update(self.sensors.tracker.poses())  # the explicit GT sensor
            if oid not in self.belief:
                raise _StepAbort(
                    "not_perceived", "grasp", f"the robot has no pose of {oid!r} (not perceived)"
                )
            T_pick = self._robot_frame(self.belief[oid])
            try:
                chosen = self.transfers.choose(
                    self._q_cmd,
                    self._grip_cmd,
                    self.meshes[oid],
                    self.symmetries[oid],
                    T_pick,
                    self._robot_frame(target),
                    obstacles(
                        {k: self._robot_frame(T) for k, T in self.belief.items()}, self.meshes, oid
                    ),
                )
            except TransferAbort as abort:
                raise _StepAbort(abort.kind, abort.phase, abort.reason, abort.grasp) from None  # type: ignore[arg-type]
            grasp, transfer_z = chosen.grasp, chosen.transfer_z
            approach, close, lift = split_at(chosen.pick, CLOSING, LIFTING)
            self._run_phase("approach", approach)
            self._read_offset(oid)
            self._mark("close")
            if weld is not None:
                weld.hold(oid)
            self._run(close)
            self._check_hold(grasp, "close")
            self._run_phase("lift", lift)
            self._check_hold(grasp, "lift")
            self._settle(self.config.measure_settle)
            T_place = self._robot_frame(target) @ self.symmetries[oid][grasp.symmetry]
            place = self._place(
                grasp,
                T_place,
                transfer_z,
                oid,
                long_way=chosen.long_way,
                transfer_q=chosen.transfer_q,
            )
            transfer = _place_phases(place)[0]
            self._run_phase("transfer", transfer)
            self._settle(self.config.measure_settle)
            self._check_hold(grasp, "transfer", dropped=True)
            in_hand = self._in_hand(oid, grasp)
            if in_hand is not None:  # again, for any slip during the transfer
                place = transfer + self._place(grasp, T_place, transfer_z, oid, start=DESCENDING)
            descend = _place_phases(place)[1]
            self._run_phase("place", descend)
            if in_hand is not None:
                # and once more before the last slow centimetres: the descent sways the object
                # in the hand and the arm off its path by up to a millimetre, and tangram
                # pieces go into gaps of half a millimetre
                self._settle(self.config.near_settle)
                place = (
                    transfer
                    + descend
                    + self._place(grasp, T_place, transfer_z, oid, start=REACHING)
                )
            _, _, reach, release, retreat = _place_phases(place)
            self._run(reach)
            self._mark("release")
            self._run(release)
            if weld is not None:
                weld.hold(None)
            self._run(retreat)
        except _StepAbort as abort:
            if weld is not None:
                weld.hold(None)
            failure = StepFailure(
                step=i,
                object=oid,
                kind=abort.kind,  # type: ignore[arg-type]
                phase=abort.phase,
                reason=abort.reason,
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
        self.belief[oid] = target  # what the robot now believes: where it put the object
        self._placed[oid] = target
        pos, rot, yaw = self.sensors.meter.errors(
            oid, self._robot_frame(target), self.symmetries[oid]
        )  # against where the robot aimed
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
            weld_engaged=weld is not None and weld.engaged,
            camera_offset=self.camera_offset,
        )

    # -- the camera's calibration offset (see the module doc) ---------------------------------

    @property
    def camera_offset(self) -> tuple[float, float] | None:
        """The estimated offset (x, y) [m] of perceived poses from the robot's frame: the
        median of the readings so far, None before the first."""
        if not self._readings:
            return None
        x, y = np.median(np.asarray(self._readings), axis=0)
        return float(x), float(y)

    def _robot_frame(self, T: np.ndarray) -> np.ndarray:
        """A perceived pose (the belief's, a plan target's) where the robot will find it."""
        offset = self.camera_offset
        if offset is None:
            return T
        out = np.array(T, dtype=float)
        out[:2, 3] -= offset
        return out

    def _read_offset(self, oid: str) -> None:
        """With the jaws open around `oid`, read where it is (wrist camera and the arm's
        joints) against where the belief puts it."""
        sensor = self.sensors.in_hand
        if sensor is None or not self.config.camera_offset or self.config.track_objects:
            return
        placed = self._placed.get(oid)
        if placed is not None and np.allclose(placed, self.belief[oid], atol=1e-6):
            return  # where the robot put it: nothing about the camera
        rel = sensor.estimate(oid)
        if rel is None:
            return
        T_tcp = self.ik.fk(self.data.qpos[self.index.arm_qpos])
        # the mesh's centroid: the same point in every frame a symmetric object may be read in
        c = np.append(np.asarray(self.meshes[oid].centroid, dtype=float), 1.0)
        seen = (T_tcp @ rel @ c)[:2]
        believed = (self.belief[oid] @ c)[:2]
        reading = believed - seen
        if float(np.linalg.norm(reading)) <= self.config.camera_offset_max:
            self._readings.append(reading)

    def _check_hold(self, grasp: Grasp, phase: Phase, *, dropped: bool = False) -> None:
        """Fail the step when the gripper's own signals say nothing is held: the jaws closed
        well past the grasp's width, or a pad touches nothing."""
        opening = self.sensors.gripper.opening()
        left, right = self.sensors.gripper.pads_touch()
        if opening < grasp.width - self.config.hold_tolerance or not (left and right):
            what = (
                f"the jaws closed to {1000 * opening:.0f} mm on a {1000 * grasp.width:.0f} mm grasp"
                if opening < grasp.width - self.config.hold_tolerance
                else "a pad touches nothing"
            )
            kind = "dropped" if dropped else "grasp_failed"
            raise _StepAbort(kind, phase, f"{what}: nothing is held", grasp)

    def _in_hand(self, oid: str, grasp: Grasp) -> np.ndarray | None:
        """The in-hand sensor's T_tcp_object when there is one (and the object is where the
        grasp holds it, roughly), else None."""
        sensor = self.sensors.in_hand
        if sensor is None or not self.config.in_hand_correction:
            return None
        rel = sensor.estimate(oid)
        if rel is None:
            return None
        # A symmetric object's pose is known only up to its symmetry, and the frame the sensor
        # reports need not be the one the robot's belief (perception) used to plan the grasp:
        # take the equivalent frame closest to the one the grasp expects (continuity)
        expected = se3.inverse(grasp.T_object_tcp)
        rel = min(
            (rel @ S for S in self.symmetries[oid]),
            key=lambda X: se3.rotation_angle(expected[:3, :3].T @ X[:3, :3]),
        )
        if np.linalg.norm(rel[:3, 3] - expected[:3, 3]) > 0.03:
            raise _StepAbort("dropped", "transfer", "the object left the hand", grasp)
        return rel

    def _place(
        self,
        grasp: Grasp,
        T_place: np.ndarray,
        z: float,
        oid: str,
        *,
        start: str | None = None,
        long_way: bool = False,
        transfer_q: np.ndarray | None = None,
    ) -> list[PlannedSegment]:
        try:
            return self.transfers.place_segments(
                self._q_cmd,
                grasp,
                T_place,
                z,
                in_hand=self._in_hand(oid, grasp),
                start=start,
                long_way=long_way,
                transfer_q=transfer_q,
            )
        except TransferAbort as abort:
            raise _StepAbort(abort.kind, abort.phase, abort.reason, abort.grasp or grasp) from None  # type: ignore[arg-type]

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

    # -- running in physics ------------------------------------------------------------------

    def _mark(self, phase: str) -> None:
        self._tracker.phases.append((phase, float(self.data.time)))
        if self.on_phase is not None:
            self.on_phase(self, phase, self._oid)

    def _run_phase(self, phase: Phase, planned: Sequence[PlannedSegment]) -> None:
        self._check_deadline(phase)
        self._mark(phase)
        self._run(planned)

    def _check_deadline(self, phase: Phase) -> None:
        if self._deadline is not None and time.perf_counter() > self._deadline:
            raise _StepAbort(
                "deadline", phase, f"the wall-clock deadline passed before the {phase} phase"
            )

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
                d.ctrl[grip_act] = (
                    self._grip_cmd if self.grip_override is None else self.grip_override
                )
                if self.sensors.weld is not None:
                    self.sensors.weld.update(self._grip_cmd)
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

    # -- end of a plan ----------------------------------------------------------------------

    def _finish(self, *, park: bool) -> None:
        if self.sensors.weld is not None:
            self.sensors.weld.hold(None)
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
                    duration=self.transfers.duration(T_now, up, c.approach_speed),
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


# -- helpers ----------------------------------------------------------------------------------


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
            raise UsageError(f"plan step {k} is not a step: {clip(repr(s))}")
    return out


def _place_phases(place: list[PlannedSegment]) -> list[list[PlannedSegment]]:
    """A place's phases by their labels: transfer, descent, final reach, release (settle,
    open, settle), retreat."""
    return split_at(place, DESCENDING, REACHING, SETTLING, RETREATING)
