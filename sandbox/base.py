"""The executor interface: a `Job` goes in, a `Report` with one verdict comes out.

Design rule: a draft's misbehaviour is data, never an exception. Every backend returns exactly
one of the verdicts in `VERDICTS` for every job; only the caller's mistakes (`BadJob`) and a
sandbox that cannot run at all (`SandboxUnavailable`) raise.
"""

from __future__ import annotations

import abc
import keyword
import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Literal, Self, get_args

import numpy as np

from sandbox.errors import BadJob

Verdict = Literal["ok", "exception", "timeout", "oom", "crashed", "bad_output"]
VERDICTS: tuple[str, ...] = get_args(Verdict)

_ENTRY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*:[A-Za-z_][A-Za-z0-9_]*")
# Names a draft module may not take: they would shadow what the harness and checks import.
RESERVED_MODULES = frozenset(sys.stdlib_module_names) | {
    "sandbox",
    "contracts",
    "toolbox",
    "numpy",
    "scipy",
    "cv2",
    "open3d",
    "trimesh",
    "networkx",
    "pyrender",
    "hypothesis",
    "jsonschema",
    "PIL",
    "OpenGL",
}


@dataclass(frozen=True, kw_only=True)
class Job:
    """One draft to run.

    Attributes:
        source: the draft module's source code.
        function: the function to call (``entry="call"``), or the one an entry point checks.
        inputs: keyword arguments (JSON values and numpy arrays; arrays travel as .npz).
        modules: other modules the draft may import, ``{module name: source}`` (e.g. the
            frozen functions it depends on).
        module_name: the draft's module name.
        entry: ``"call"`` runs ``function(**inputs)``; ``"pkg.mod:fn"`` (a module baked into
            the image, e.g. a check suite) runs ``fn(ctx)`` with a
            `sandbox.harness.context.EntryContext` holding the loaded modules and inputs.
        timeout_s: wall-time budget for loading and running the job [s].
        memory_mb: memory the job may allocate on top of the warm harness [MiB].
        output_schema: a JSON Schema the output (arrays as nested lists) must satisfy.
    """

    source: str
    function: str
    inputs: Mapping[str, Any] = field(default_factory=dict)
    modules: Mapping[str, str] = field(default_factory=dict)
    module_name: str = "draft"
    entry: str = "call"
    timeout_s: float = 10.0
    memory_mb: int = 1024
    output_schema: Mapping[str, Any] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.source, str):
            raise BadJob(f"source must be a str, not {type(self.source).__name__}")
        if not _is_name(self.function):
            raise BadJob(f"function {self.function!r} is not a Python identifier")
        for name in [self.module_name, *self.modules]:
            if not _is_name(name):
                raise BadJob(f"module name {name!r} is not a Python identifier")
            if name in RESERVED_MODULES:
                raise BadJob(f"module name {name!r} would shadow a module the sandbox uses")
        if self.module_name in self.modules:
            raise BadJob(f"module {self.module_name!r} is both the draft and an extra module")
        if not all(isinstance(s, str) for s in self.modules.values()):
            raise BadJob("extra modules must map module names to source strings")
        if self.entry != "call" and not _ENTRY.fullmatch(self.entry):
            raise BadJob(f"entry {self.entry!r} is neither 'call' nor 'package.module:function'")
        if not isinstance(self.inputs, Mapping) or not all(isinstance(k, str) for k in self.inputs):
            raise BadJob("inputs must map argument names (str) to values")
        if not 0 < self.timeout_s <= 3600:
            raise BadJob(f"timeout_s={self.timeout_s} is outside (0, 3600]")
        if not 16 <= self.memory_mb <= 1 << 20:
            raise BadJob(f"memory_mb={self.memory_mb} is outside [16, {1 << 20}]")

    @property
    def sources(self) -> dict[str, str]:
        """Every module of the job by name, the draft first."""
        return {self.module_name: self.source, **self.modules}


@dataclass(frozen=True, kw_only=True)
class ExceptionInfo:
    """An exception raised in the job: its type, message, and traceback (draft frames only)."""

    type: str
    message: str
    traceback: str


@dataclass(frozen=True, kw_only=True)
class Report:
    """What became of one job.

    Attributes:
        verdict: ``ok``, ``exception``, ``timeout`` (killed from outside), ``oom``, ``crashed``
            (a signal, an exit without a result, or the harness died) or ``bad_output``
            (schema, size or type).
        output: the decoded output when ok (JSON values and numpy arrays), else None.
        exception: for ``exception`` (and a MemoryError ``oom``).
        detail: one line saying why, for every verdict but ok.
        stdout_tail, stderr_tail: the last bytes the job printed (decoded, never parsed).
        stdout_bytes, stderr_bytes: how much it printed in all [bytes].
        wall_time_s: from fork to exit, as the harness measured it [s].
        peak_memory_mb: peak resident memory the job added on top of the warm harness [MiB].
        exit_code, signal: how the job's process ended, when known.
        backend: the executor that ran it (``docker`` or ``local``).
    """

    verdict: Verdict
    output: Any = None
    exception: ExceptionInfo | None = None
    detail: str = ""
    stdout_tail: str = ""
    stderr_tail: str = ""
    stdout_bytes: int = 0
    stderr_bytes: int = 0
    wall_time_s: float = 0.0
    peak_memory_mb: float | None = None
    exit_code: int | None = None
    signal: int | None = None
    backend: str = ""

    @property
    def ok(self) -> bool:
        return self.verdict == "ok"

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict; arrays in the output become nested lists."""
        return {
            "verdict": self.verdict,
            "output": to_jsonable(self.output),
            "exception": None if self.exception is None else vars(self.exception).copy(),
            "detail": self.detail,
            "stdout_tail": self.stdout_tail,
            "stderr_tail": self.stderr_tail,
            "stdout_bytes": self.stdout_bytes,
            "stderr_bytes": self.stderr_bytes,
            "wall_time_s": self.wall_time_s,
            "peak_memory_mb": self.peak_memory_mb,
            "exit_code": self.exit_code,
            "signal": self.signal,
            "backend": self.backend,
        }


class Executor(abc.ABC):
    """Runs jobs; use as a context manager (``with open_executor() as ex: ex.run(job)``)."""

    name: str = ""

    @abc.abstractmethod
    def run(self, job: Job) -> Report:
        """Run one job to its verdict. Raises only `BadJob` and `SandboxUnavailable`."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the executor's processes and containers; idempotent."""

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def to_jsonable(value: Any) -> Any:
    """`value` with numpy arrays and scalars as plain lists and numbers."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if isinstance(value, Mapping):
        return {k: to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_jsonable(v) for v in value]
    return value


def _is_name(name: Any) -> bool:
    return isinstance(name, str) and name.isidentifier() and not keyword.iskeyword(name)
