"""Errors of the robot and its executor.

`RobotModelError` means the robot could not be built (a setup problem: fix the environment);
`ExecutionError` means a plan could not be carried out (a failed trial, exit code 1), and names
the step, the object and the phase that failed.
"""

from __future__ import annotations

from typing import Literal

from contracts.errors import RivetError

FailureKind = Literal[
    "unknown_object",  # the plan names an object the scene does not have
    "non_rigid_target",  # the target pose is not a proper rigid transform
    "no_grasp",  # no top-down grasp clears the neighbours at both pick and place
    "unreachable",  # no IK solution for a waypoint of the transfer
    "grasp_failed",  # the fingers closed but the object is not held
    "dropped",  # the object left the hand during the transfer
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
