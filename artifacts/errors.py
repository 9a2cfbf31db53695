"""Errors of the artifact store and the thin runtime."""

from __future__ import annotations

from contracts.errors import RivetError, UsageError


class ArtifactError(RivetError):
    """A frozen artifact set is missing, tampered with or inconsistent."""


class ObservationError(UsageError):
    """An observation folder cannot be read (missing file, corrupt PNG, bad camera)."""
