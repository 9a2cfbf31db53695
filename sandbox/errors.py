"""Errors of the sandbox package.

`BadJob` is the caller's mistake (exit code 2). `SandboxUnavailable` and `ImageBuildError` are
failures of the machinery (exit code 1), and their messages say how to fix them. A draft that
misbehaves is never an error here: it is a `Report` with a verdict.
"""

from __future__ import annotations

from contracts.errors import RivetError, UsageError


class SandboxError(RivetError):
    """Root of the sandbox's own errors."""


class SandboxUnavailable(SandboxError):
    """The sandbox cannot run: no Docker engine, no image, or the harness does not start."""


class ImageBuildError(SandboxError):
    """Building the sandbox image (or its offline base) failed."""


class BadJob(SandboxError, UsageError):
    """A job is malformed: a bad name, inputs that cannot be sent, an impossible limit."""
