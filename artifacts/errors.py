"""Errors of the artifact store and the thin runtime."""

from __future__ import annotations

from contracts.errors import RivetError, UsageError


class ArtifactError(RivetError):
    """A frozen artifact set is missing, tampered with or inconsistent."""


class ProgramFailed(RivetError):
    """A frozen program did not load, raised, overran its time or returned what cannot be used:
    the work failed (exit code 1), not the user's input.

    Attributes:
        function: the function whose call failed ("perceive", "relate", "plan"); None when
            the programs did not load.
    """

    def __init__(self, message: str, *, function: str | None = None) -> None:
        super().__init__(message)
        self.function = function


class ObservationError(UsageError):
    """An observation folder cannot be read (missing file, corrupt PNG, bad camera)."""
