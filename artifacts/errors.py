"""Errors of the artifact store and the thin runtime."""

from __future__ import annotations

from contracts.errors import RivetError, UsageError


class ArtifactError(RivetError):
    """A frozen artifact set is missing, tampered with or inconsistent."""


class ProgramFailed(RivetError):
    """A frozen program did not load, raised, overran its time or returned what cannot be read:
    the work failed (exit code 1), not the user's input."""


class ObservationError(UsageError):
    """An observation folder cannot be read (missing file, corrupt PNG, bad camera)."""
