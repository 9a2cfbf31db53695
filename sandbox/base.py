"""The executor interface: a `Program` is loaded in a `Session` that answers calls; a `Job`
(one call in a session of its own) gives a `Report` with one verdict.

Design rule: a draft's misbehaviour is data, never an exception. Every backend answers every
call with exactly one verdict; only the caller's mistakes (`BadJob`) and a sandbox that cannot
run at all (`SandboxUnavailable`) raise. Whoever judges a program does so in its own process,
from the values a session returns: nothing of the judge runs where the program runs.
"""

from __future__ import annotations

import abc
import keyword
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Literal, Self, get_args

import numpy as np

from sandbox.errors import BadJob
from sandbox.harness.wire import clean_text

Verdict = Literal["ok", "exception", "timeout", "oom", "crashed", "bad_output"]
VERDICTS: tuple[str, ...] = get_args(Verdict)

# Names a program module may not take: they would shadow what the harness and toolbox import.
RESERVED_MODULES = frozenset(sys.stdlib_module_names) | {
    "sandbox",
    "contracts",
    "geometry",
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


@dataclass(frozen=True)
class Const:
    """A reference, in call arguments, to a constant the session's program was loaded with."""

    name: str


MESHES = Const("meshes")
"""Call argument standing for the program's meshes: each call gets fresh copies."""


@dataclass(frozen=True, kw_only=True)
class Program:
    """What a session loads once and then calls many times.

    Attributes:
        modules: ``{module name: source}``, imported in this order; each may import the
            others by name (e.g. the frozen functions a draft depends on).
        meshes: ``{mesh key: mesh with .vertices (n, 3) and .faces (m, 3)}``, rebuilt as
            `trimesh.Trimesh` inside; a call argument `MESHES` gets fresh copies of them.
        constants: further named values (JSON values and arrays), passed by `Const(name)`.
    """

    modules: Mapping[str, str]
    meshes: Mapping[str, Any] | None = None
    constants: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.modules:
            raise BadJob("a program needs at least one module")
        for name, source in self.modules.items():
            if not _is_name(name):
                raise BadJob(f"module name {name!r} is not a Python identifier")
            if name in RESERVED_MODULES:
                raise BadJob(f"module name {name!r} would shadow a module the sandbox uses")
            if not isinstance(source, str):
                raise BadJob("modules must map module names to source strings")
        for name in self.constants:
            if not isinstance(name, str) or name == MESHES.name:
                raise BadJob(f"constant name {name!r} is not allowed")


@dataclass(frozen=True, kw_only=True)
class Job:
    """One call of one function, in a session of its own (`Executor.run`).

    Attributes:
        source: the draft module's source code.
        function: the function to call: ``function(**inputs)``.
        inputs: keyword arguments (JSON values and numpy arrays; arrays travel as .npz).
        modules: other modules the draft may import, ``{module name: source}`` (e.g. the
            frozen functions it depends on).
        module_name: the draft's module name.
        timeout_s: wall-time budget for loading and running the job [s].
        memory_mb: memory the job may allocate on top of the warm harness [MiB].
        output_schema: a JSON Schema the output (arrays as nested lists) must satisfy.
    """

    source: str
    function: str
    inputs: Mapping[str, Any] = field(default_factory=dict)
    modules: Mapping[str, str] = field(default_factory=dict)
    module_name: str = "draft"
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
        if not isinstance(self.inputs, Mapping) or not all(isinstance(k, str) for k in self.inputs):
            raise BadJob("inputs must map argument names (str) to values")
        check_limits(timeout_s=self.timeout_s, memory_mb=self.memory_mb)

    @property
    def sources(self) -> dict[str, str]:
        """Every module of the job by name, the draft first."""
        return {self.module_name: self.source, **self.modules}


def check_limits(*, timeout_s: float | None = None, memory_mb: int | None = None) -> None:
    """Refuse (`BadJob`) a time or memory limit no backend can honour."""
    if timeout_s is not None and not 0 < timeout_s <= 3600:
        raise BadJob(f"timeout_s={timeout_s} is outside (0, 3600]")
    if memory_mb is not None and not 16 <= memory_mb <= 1 << 20:
        raise BadJob(f"memory_mb={memory_mb} is outside [16, {1 << 20}]")


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

    def to_dict(self, *, max_elements: int | None = None) -> dict[str, Any]:
        """A JSON-able dict (strict JSON: no NaN); arrays in the output become nested lists, or
        summaries above `max_elements`."""
        return {
            "verdict": self.verdict,
            "output": to_jsonable(self.output, max_elements=max_elements),
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


@dataclass(frozen=True, kw_only=True)
class CallReport:
    """What became of one call in a session (or of loading the session's program).

    Attributes:
        verdict: as for `Report`; ``closed`` when the session could answer no more calls
            (an earlier call timed out or killed its process).
        value: the decoded return value when ok.
        seconds: from request to answer, measured outside the program's process [s].
        cpu_seconds: CPU time the program used meanwhile (all its processes and threads in
            the Docker backend), measured outside its process [s]; robust to a busy machine.
        queued_seconds: of `seconds`, the longest any one thread of the program's process
            waited, runnable, for a CPU (its run-queue delay, measured outside the process),
            plus the harness's own wait while relaying the call [s]: about what a busy
            machine added (threads that ended and other processes are not looked at, so
            ``seconds - queued_seconds`` errs towards slower).
    """

    verdict: Literal["ok", "exception", "timeout", "oom", "crashed", "bad_output", "closed"]
    value: Any = None
    exception: ExceptionInfo | None = None
    detail: str = ""
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    queued_seconds: float = 0.0
    exit_code: int | None = None
    signal: int | None = None

    @property
    def ok(self) -> bool:
        return self.verdict == "ok"


@dataclass(frozen=True, kw_only=True)
class SessionEnd:
    """What a closed session printed and used."""

    stdout_tail: str = ""
    stderr_tail: str = ""
    stdout_bytes: int = 0
    stderr_bytes: int = 0
    wall_time_s: float = 0.0
    peak_memory_mb: float | None = None


class Session(abc.ABC):
    """A program loaded once in a fresh process of the sandbox, answering calls until closed.

    Use as a context manager. `load` says whether the program imported; a call's time budget
    is enforced from outside the program's process, and after a call that timed out or
    crashed every further call answers ``closed``.
    """

    load: CallReport

    @abc.abstractmethod
    def call(
        self, module: str, function: str, *args: Any, timeout_s: float, **kwargs: Any
    ) -> CallReport:
        """Call ``module.function(*args, **kwargs)``; `MESHES` / `Const` stand for constants.

        Raises only `BadJob` (arguments that cannot be sent) and `SandboxUnavailable`.
        """

    @abc.abstractmethod
    def attribute(self, module: str, name: str, *, timeout_s: float = 10.0) -> CallReport:
        """The value of a module attribute (e.g. a declared constant), as a call would return
        it: produced inside the program's process, so only ever the program's own word."""

    @abc.abstractmethod
    def signature(self, module: str, function: str, *, timeout_s: float = 10.0) -> CallReport:
        """``{"callable", "params": [{"name", "kind", "default"}] | None, "functions"}`` of a
        module attribute, as the program's process describes it."""

    @abc.abstractmethod
    def close(self) -> SessionEnd:
        """End the session: kill its processes, wipe its scratch space; idempotent."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Executor(abc.ABC):
    """Runs programs in sessions, one at a time; use as a context manager
    (``with open_executor() as ex: ex.run(job)``)."""

    name: str = ""

    @abc.abstractmethod
    def open_session(
        self, program: Program, *, memory_mb: int = 1024, load_timeout_s: float = 60.0
    ) -> Session:
        """Load `program` in a fresh process. Raises only `BadJob` and `SandboxUnavailable`
        (a program that does not import is ``load.verdict != "ok"``, not an error)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the executor's processes and containers; idempotent."""

    def run(self, job: Job) -> Report:
        """One job to its verdict: a session of its own, one call. Raises only `BadJob` and
        `SandboxUnavailable`."""
        if not isinstance(job, Job):
            raise BadJob(f"run() takes a sandbox.Job, not {type(job).__name__}")
        program = Program(modules=job.sources)
        t0 = time.monotonic()
        with self.open_session(
            program, memory_mb=job.memory_mb, load_timeout_s=job.timeout_s
        ) as session:
            result = session.load
            if result.ok:  # the budget covers loading and running, not starting the sandbox
                left = max(0.01, job.timeout_s - result.seconds)
                result = session.call(
                    job.module_name, job.function, timeout_s=left, **dict(job.inputs)
                )
            end = session.close()
        verdict, detail, output = result.verdict, result.detail, result.value
        if verdict == "closed":
            verdict = "crashed"
        if verdict == "ok" and job.output_schema is not None:
            problem = schema_problem(output, job.output_schema)
            if problem:
                verdict, detail, output = "bad_output", problem, None
        return Report(
            verdict=verdict,  # type: ignore[arg-type]
            output=output if verdict == "ok" else None,
            exception=result.exception,
            detail=detail,
            stdout_tail=end.stdout_tail,
            stderr_tail=end.stderr_tail,
            stdout_bytes=end.stdout_bytes,
            stderr_bytes=end.stderr_bytes,
            wall_time_s=time.monotonic() - t0,
            peak_memory_mb=end.peak_memory_mb,
            exit_code=result.exit_code,
            signal=result.signal,
            backend=self.name,
        )

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def schema_problem(output: Any, schema: Mapping[str, Any]) -> str:
    """Why `output` breaks a JSON Schema ('' when it does not)."""
    import jsonschema

    try:
        validator = jsonschema.Draft202012Validator(schema)
        error = jsonschema.exceptions.best_match(validator.iter_errors(to_jsonable(output)))
    except jsonschema.exceptions.SchemaError as e:
        raise BadJob(f"output_schema is not a valid JSON Schema: {e.message}") from None
    if error is None:
        return ""
    path = "output" + "".join(f"[{p!r}]" if isinstance(p, int) else f".{p}" for p in error.path)
    return f"schema: {path}: {error.message}"[:16_000]


def to_jsonable(value: Any, *, max_elements: int | None = None) -> Any:
    """`value` as plain JSON: arrays as lists (or, when their lists would hold more than
    `max_elements` values, `listed_size`, a summary of their shape and range), non-finite numbers as the strings "NaN"/"Infinity"/"-Infinity" (JSON
    has none), strings with control characters and lone surrogates made visible."""
    if isinstance(value, np.ndarray):
        if max_elements is not None and listed_size(value.shape) > max_elements:
            finite = value[np.isfinite(value)] if value.dtype.kind in "fc" else value
            return {
                "array": {
                    "shape": list(value.shape),
                    "dtype": str(value.dtype),
                    "min": to_jsonable(finite.min().item()) if finite.size else None,
                    "max": to_jsonable(finite.max().item()) if finite.size else None,
                }
            }
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float):
        if value != value:
            return "NaN"
        if value in (float("inf"), float("-inf")):
            return "Infinity" if value > 0 else "-Infinity"
        return value
    if isinstance(value, str):
        return clean_text(value)
    if isinstance(value, Mapping):
        return {
            clean_text(str(k)): to_jsonable(v, max_elements=max_elements) for k, v in value.items()
        }
    if isinstance(value, list | tuple):
        return [to_jsonable(v, max_elements=max_elements) for v in value]
    return value


def listed_size(shape: tuple[int, ...]) -> int:
    """How many values (lists and numbers) an array of this shape becomes as nested lists:
    an (N, 0) array holds nothing but lists as N empty lists."""
    total, count = 1, 1
    for d in shape:
        count *= max(d, 1)
        total += count
    return total


def _is_name(name: Any) -> bool:
    return isinstance(name, str) and name.isidentifier() and not keyword.iskeyword(name)
