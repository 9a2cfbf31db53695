"""The sandbox: runs generated drafts (and their checks) where they cannot reach the host.

Design rule: one executor interface — `open_session(Program)` loads programs once in a fresh
process and answers calls, `run(Job)` is one call in a session of its own — a hardened Docker
backend by default, and a local backend that isolates nothing, used only when named. When
Docker is missing the sandbox raises `SandboxUnavailable` saying how to fix it; it never falls
back. Nothing but the program runs in the sandbox: whoever judges it reads the values a
session returns, in a process of its own.

    from sandbox import MESHES, Job, Program, open_executor
    with open_executor() as ex:
        report = ex.run(Job(source=src, function="render", inputs={...}, timeout_s=30))
        with ex.open_session(Program(modules={"render": src}, meshes=meshes)) as s:
            answer = s.call("render", "render", records, MESHES, camera, timeout_s=10)
"""

from __future__ import annotations

from typing import Any

from sandbox.base import (
    MESHES,
    VERDICTS,
    CallReport,
    Const,
    ExceptionInfo,
    Executor,
    Job,
    Program,
    Report,
    Session,
    SessionEnd,
    Verdict,
)
from sandbox.errors import BadJob, ImageBuildError, SandboxError, SandboxUnavailable

BACKENDS = ("docker", "local")

__all__ = [
    "BACKENDS",
    "MESHES",
    "VERDICTS",
    "BadJob",
    "CallReport",
    "Const",
    "ExceptionInfo",
    "Executor",
    "ImageBuildError",
    "Job",
    "Program",
    "Report",
    "SandboxError",
    "SandboxUnavailable",
    "Session",
    "SessionEnd",
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
