"""The sandbox: runs generated drafts (and their checks) where they cannot reach the host.

Design rule: one executor interface (`Executor.run(Job) -> Report`), a hardened Docker backend
by default, and a local backend that isolates nothing, used only when named. When Docker is
missing the sandbox raises `SandboxUnavailable` saying how to fix it; it never falls back.

    from sandbox import Job, open_executor
    with open_executor() as ex:
        report = ex.run(Job(source=src, function="render", inputs={...}, timeout_s=30))
        report.verdict, report.output
"""

from __future__ import annotations

from typing import Any

from sandbox.base import VERDICTS, ExceptionInfo, Executor, Job, Report, Verdict
from sandbox.errors import BadJob, ImageBuildError, SandboxError, SandboxUnavailable
from sandbox.harness.context import EntryContext

BACKENDS = ("docker", "local")

__all__ = [
    "BACKENDS",
    "VERDICTS",
    "BadJob",
    "EntryContext",
    "ExceptionInfo",
    "Executor",
    "ImageBuildError",
    "Job",
    "Report",
    "SandboxError",
    "SandboxUnavailable",
    "Verdict",
    "open_executor",
]


def open_executor(backend: str = "docker", **options: Any) -> Executor:
    """An executor of the named backend; options go to its constructor.

    Raises:
        BadJob: unknown backend name.
        SandboxUnavailable: the Docker engine or the image is missing (docker backend).
    """
    if backend == "docker":
        from sandbox.docker_backend import DockerExecutor

        return DockerExecutor(**options)
    if backend == "local":
        from sandbox.local_backend import LocalExecutor

        return LocalExecutor(**options)
    raise BadJob(f"unknown sandbox backend {backend!r}; known: {', '.join(BACKENDS)}")
