"""Errors of the simulator layer: scenes and cameras (bad input), the robot model (a setup
problem), and execution (a plan that could not be carried out: a failed trial, exit code 1)."""

from __future__ import annotations

from typing import Literal

from contracts.errors import RivetError, UsageError


class SimError(RivetError):
    """The simulator failed (no rendering context, a model that does not compile)."""


class InvalidSceneError(UsageError):
    """A scene is malformed or physically invalid; the message names the object and problem.

    Attributes:
        object: the offending object's id (None when the problem is not one object's).
        problem: what is wrong, e.g. ``penetrates 'blue' by 3.2 mm``.
        problems: every problem found, as ``(object, problem)`` pairs (the first is the above).
    """

    def __init__(self, object: str | None, problem: str, *, problems=None, where: str = "") -> None:
        self.object = object
        self.problem = problem
        self.problems = list(problems or [(object, problem)])
        prefix = f"{where}: " if where else ""
        subject = f"object {object!r}" if object is not None else "scene"
        more = f" (and {len(self.problems) - 1} more problems)" if len(self.problems) > 1 else ""
        super().__init__(f"{prefix}{subject}: {problem}{more}")


class InvalidCameraError(UsageError):
    """A camera the MuJoCo renderer cannot reproduce (non-square pixels, shifted centre)."""


FailureKind = Literal[
    "unknown_object",  # the plan names an object the scene does not have
    "not_perceived",  # the plan moves an object the robot's belief holds no pose of
    "non_rigid_target",  # the target pose is not a proper rigid transform
    "no_grasp",  # no top-down grasp clears the neighbours at both pick and place
    "unreachable",  # no IK solution for a waypoint of the transfer
    "grasp_failed",  # the fingers closed but the object is not held
    "dropped",  # the object left the hand during the transfer
    "deadline",  # the wall-clock deadline passed before the plan was done
]

FAILURE_KINDS: tuple[str, ...] = FailureKind.__args__  # type: ignore[attr-defined]


class RobotModelError(RivetError):
    """The robot's models could not be loaded or attached (e.g. MENAGERIE_ROOT is not set)."""


class ExecutionError(RivetError):
    """A plan step could not be executed.

    Attributes:
        step: index of the failing step in the plan.
        object_id: the object that step moves.
        kind: one of `FAILURE_KINDS`.
        phase: the phase of the transfer that failed (e.g. ``validate``, ``grasp``, ``place``).
        reason: what went wrong, in words.
    """

    def __init__(
        self, *, step: int, object_id: str, kind: FailureKind, phase: str, reason: str
    ) -> None:
        self.step = step
        self.object_id = object_id
        self.kind = kind
        self.phase = phase
        self.reason = reason
        super().__init__(f"step {step} ({object_id!r}), {phase}: {kind}: {reason}")
