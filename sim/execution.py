"""What the executor is told and what it reports: its configuration and the results of a plan.

Design rule: plain values. A step's outcome carries the placement error measured by the
simulation (`sim.sensing.PlacementMeter`) — scoring, which the executor never reads back.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, Protocol

import mujoco

from geometry.grasps import Grasp
from sim.errors import ExecutionError, FailureKind
from sim.sensing import WRIST_CAMERA, InHandNoise


class FrameRecorder(Protocol):
    """Called at `ExecutorConfig.record_fps` of simulated time, e.g. to render video frames."""

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData) -> None: ...


@dataclass(frozen=True, kw_only=True)
class ExecutorConfig:
    """Timing, geometry and sensing of the transfers. Speeds are mean speeds of min-jerk
    moves."""

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
    in_hand_correction: bool = True  # correct the place for the in-hand estimate, when there is one
    # estimate the camera's calibration offset from the wrist camera's readings of objects
    # about to be grasped, and act on the belief shifted by it (see `sim.executor`); readings
    # farther than `camera_offset_max` from the belief are that object misperceived, not the
    # camera, and are left out
    camera_offset: bool = True
    camera_offset_max: float = 0.012  # [m]
    measure_settle: float = 0.2  # pause before reading the object's pose in the hand [s]
    near_settle: float = 0.15  # the same, at the end of the descent onto the target [s]
    park_after: bool = True
    park_time: float = 1.5  # least time of joint moves between READY and PARK [s]
    joint_speed: float = 1.2  # mean speed of the largest joint in joint moves [rad/s]
    final_settle: float = 0.3  # physics after the last step [s]
    record_fps: float = 30.0
    max_grasp_candidates: int = 12
    # what the robot senses (see sim.sensing): the wrist camera's in-hand estimate (None: open
    # loop after the grasp); ground-truth object poses before each pick (never by default)
    in_hand: InHandNoise | None = WRIST_CAMERA
    track_objects: bool = False
    hold_tolerance: float = 0.008  # closed jaws this much narrower than the grasp: empty [m]


Phase = Literal[
    "validate", "grasp", "approach", "close", "lift", "transfer", "place", "release", "done"
]


@dataclass(frozen=True, kw_only=True)
class StepFailure:
    """Why a step failed; `kind` is one of `sim.errors.FAILURE_KINDS`."""

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
        camera_offset: the executor's estimate of the camera's calibration offset (x, y) [m]
            after this step (what it subtracted from the belief and the targets), None when
            it has no reading yet.
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
    camera_offset: tuple[float, float] | None = None

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
            "camera_offset": None if self.camera_offset is None else list(self.camera_offset),
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
