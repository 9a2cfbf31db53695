"""Errors of the simulator layer."""

from __future__ import annotations

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
