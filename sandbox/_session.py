"""What both backends share: staging a job, the request/result protocol, judging the result.

Design rule: the host trusts nothing that comes back. It reads frames under a size cap, decodes
outputs with `wire.decode_value` (JSON + .npz with ``allow_pickle=False``), checks every field
of the result header, and turns anything unexpected into a verdict: a dead or garbled harness is
``crashed`` and the next job gets a fresh one; a harness that does not answer within the job's
budget plus a grace period is killed from here (``timeout``).
"""

from __future__ import annotations

import abc
import atexit
import json
import os
import secrets
import shutil
import sys
import tempfile
import time
import weakref
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sandbox.base import VERDICTS, ExceptionInfo, Executor, Job, Report, to_jsonable
from sandbox.errors import BadJob, SandboxUnavailable
from sandbox.harness import wire

GRACE_S = 30.0  # [s] on top of a job's budget before the host kills the harness
START_TIMEOUT_S = 120.0  # [s] for a harness to say hello
MAX_INPUT = 256 << 20  # [bytes]
MAX_FIELD = 16_000  # [chars] of any text field in a result header
_LIVE: weakref.WeakSet[HarnessExecutor] = weakref.WeakSet()


@atexit.register
def _close_all() -> None:  # no container or harness outlives the process that started it
    for executor in list(_LIVE):
        executor.close()


class ChannelClosed(Exception):
    """The harness closed its end: it exited or was killed."""


class Channel(abc.ABC):
    """A byte stream to one harness process."""

    @abc.abstractmethod
    def send(self, data: bytes) -> None: ...

    @abc.abstractmethod
    def recv(self, timeout: float) -> bytes:
        """Some bytes; raises TimeoutError after `timeout` [s] and ChannelClosed at EOF."""

    @abc.abstractmethod
    def close(self) -> None: ...


class HarnessExecutor(Executor):
    """An executor that drives a fork-server harness over a `Channel`.

    Subclasses start the harness (`_open`), say where it sees the staged job files
    (`_harness_path`), kill it (`_kill`) and explain its death (`_death`). One job runs at a
    time per executor; run jobs in parallel with several executors.

    Args:
        output_limit_mb: cap on a job's output [MiB] (JSON plus arrays).
        tail_bytes: how much of stdout/stderr to keep [bytes].
    """

    def __init__(self, *, output_limit_mb: float = 64, tail_bytes: int = 8192) -> None:
        self.output_limit = int(output_limit_mb * (1 << 20))
        self.tail_bytes = tail_bytes
        self.stage_root = Path(tempfile.mkdtemp(prefix=f"rivet-sandbox-{self.name}-"))
        self.stage_root.chmod(0o755)  # the harness runs as another user
        self._channel: Channel | None = None
        self._reader = wire.FrameReader(self.output_limit + wire.MAX_HEADER + (1 << 16))
        self._jobs = 0
        self.hello: dict[str, Any] = {}
        self.cold_start_s: float | None = None
        self.restarts = 0
        self._closed = False
        _LIVE.add(self)

    # ------------------------------------------------------------------------ to implement

    @abc.abstractmethod
    def _open(self) -> Channel:
        """Start a harness and return the channel to it."""

    @abc.abstractmethod
    def _harness_path(self, staged: Path) -> str:
        """Where the harness sees a staged job directory."""

    @abc.abstractmethod
    def _kill(self) -> None:
        """Kill the harness (and its container) now."""

    @abc.abstractmethod
    def _death(self) -> tuple[str, str]:
        """(verdict, detail) for a harness that died during a job: ``oom`` or ``crashed``."""

    # ------------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Start the harness if it is not running (raises `SandboxUnavailable`)."""
        if self._closed:
            raise SandboxUnavailable(f"this {self.name} executor is closed")
        if self._channel is not None:
            return
        if self.hello:
            self.restarts += 1
        t0 = time.perf_counter()
        self._reader = wire.FrameReader(self._reader.max_bytes)
        self._channel = self._open()
        try:
            hello, _ = self._read(time.monotonic() + START_TIMEOUT_S)
        except (ChannelClosed, TimeoutError, wire.FrameError) as e:
            detail = self._diagnostics()
            self._discard()
            raise SandboxUnavailable(
                f"the {self.name} sandbox harness did not start ({type(e).__name__}: {e}). {detail}"
            ) from None
        if hello.get("kind") != "hello":
            self._discard()
            raise SandboxUnavailable(f"the {self.name} harness greeted with {hello!r:.200}")
        self.hello = hello
        self.cold_start_s = time.perf_counter() - t0

    def warm(self, timeout: float = 300.0) -> dict[str, Any]:
        """Wait until the harness has imported every heavy module; its status."""
        return self._ask({"kind": "warm"}, timeout)

    def status(self, timeout: float = 30.0) -> dict[str, Any]:
        """The harness's status: modules preloaded, preload errors, jobs run."""
        return self._ask({"kind": "status"}, timeout)

    def _ask(self, request: dict[str, Any], timeout: float) -> dict[str, Any]:
        self.start()
        assert self._channel is not None
        try:
            self._channel.send(wire.pack_frame(request))
            header, _ = self._read(time.monotonic() + timeout)
        except (ChannelClosed, TimeoutError, wire.FrameError, OSError) as e:
            self._discard()
            raise SandboxUnavailable(f"the {self.name} harness did not answer: {e}") from None
        return header

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._discard()
        shutil.rmtree(self.stage_root, ignore_errors=True)

    def _discard(self) -> None:
        """Kill the harness and forget it; the next job starts a fresh one."""
        if self._channel is not None:
            try:
                self._channel.close()
            finally:
                self._channel = None
                self._kill()

    def _diagnostics(self) -> str:
        return ""

    def _check(self, job: Job) -> None:
        """Refuse (`BadJob`) a job this executor cannot honour."""

    # ------------------------------------------------------------------------ jobs

    def run(self, job: Job) -> Report:
        if not isinstance(job, Job):
            raise BadJob(f"run() takes a sandbox.Job, not {type(job).__name__}")
        self._check(job)
        staged = self._stage(job)
        try:
            self.start()
            self._jobs += 1
            return self._run_staged(job, staged)
        finally:
            shutil.rmtree(staged, ignore_errors=True)

    def _run_staged(self, job: Job, staged: Path) -> Report:
        assert self._channel is not None
        request = {
            "kind": "job",
            "id": staged.name,
            "dir": self._harness_path(staged),
            "timeout_s": job.timeout_s,
            "memory_mb": job.memory_mb,
            "output_limit": self.output_limit,
            "tail_bytes": self.tail_bytes,
        }
        t0 = time.monotonic()
        try:
            self._channel.send(wire.pack_frame(request))
            header, sections = self._read(t0 + job.timeout_s + GRACE_S)
        except TimeoutError:
            self._discard()
            return Report(
                verdict="timeout",
                detail=f"the harness did not answer within {job.timeout_s:g} s + "
                f"{GRACE_S:g} s grace; killed from the host",
                wall_time_s=time.monotonic() - t0,
                backend=self.name,
            )
        except (ChannelClosed, OSError, wire.FrameError) as e:
            verdict, detail = self._death() if not isinstance(e, wire.FrameError) else ("", "")
            self._discard()
            if not verdict:
                verdict, detail = "crashed", f"the harness channel broke ({e}); harness restarted"
            return Report(
                verdict=verdict,  # type: ignore[arg-type]
                detail=detail,
                wall_time_s=time.monotonic() - t0,
                backend=self.name,
            )
        if header.get("kind") != "result" or header.get("id") != staged.name:
            self._discard()
            return Report(
                verdict="crashed",
                detail=f"the harness answered out of turn ({str(header)[:200]}); restarted",
                backend=self.name,
            )
        return self._judge(job, header, sections)

    def _read(self, deadline: float) -> tuple[dict[str, Any], list[bytes]]:
        assert self._channel is not None
        while True:
            for frame in self._reader.frames():
                return frame
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("no answer before the deadline")
            self._reader.feed(self._channel.recv(left))

    def _judge(self, job: Job, head: Mapping[str, Any], sections: list[bytes]) -> Report:
        """The report for a result frame, checking every field; decodes the output."""
        verdict = head.get("verdict")
        fields: dict[str, Any] = {
            "detail": _text(head.get("detail")),
            "stdout_tail": _text(head.get("stdout_tail")),
            "stderr_tail": _text(head.get("stderr_tail")),
            "stdout_bytes": _int(head.get("stdout_bytes")) or 0,
            "stderr_bytes": _int(head.get("stderr_bytes")) or 0,
            "wall_time_s": _num(head.get("wall_s")) or 0.0,
            "peak_memory_mb": _num(head.get("peak_memory_mb")),
            "exit_code": _int(head.get("exit_code")),
            "signal": _int(head.get("signal")),
            "backend": self.name,
        }
        if verdict not in VERDICTS:
            return Report(
                verdict="crashed", **{**fields, "detail": f"unknown verdict {verdict!r:.50}"}
            )
        exc = head.get("exception")
        if isinstance(exc, Mapping):
            fields["exception"] = ExceptionInfo(
                type=_text(exc.get("type")),
                message=_text(exc.get("message")),
                traceback=_text(exc.get("traceback")),
            )
        if verdict != "ok":
            return Report(verdict=verdict, **fields)
        if len(sections) != 2:
            return Report(verdict="bad_output", **{**fields, "detail": "malformed output sections"})
        try:
            output = wire.decode_value(sections[0], sections[1], max_bytes=self.output_limit)
        except wire.BadValue as e:
            return Report(verdict="bad_output", **{**fields, "detail": f"output {e}"})
        if job.output_schema is not None:
            problem = _schema_problem(output, job.output_schema)
            if problem:
                return Report(verdict="bad_output", **{**fields, "detail": problem})
        return Report(verdict="ok", output=output, **fields)

    def _stage(self, job: Job) -> Path:
        """Write the job's files where the harness can read them (read-only for it)."""
        try:
            text, blob = wire.encode_value(dict(job.inputs), max_bytes=MAX_INPUT)
        except wire.BadValue as e:
            raise BadJob(f"input {e.path.replace('$', 'inputs', 1)}: {e.problem}") from None
        staged = self.stage_root / f"j{self._jobs:05d}-{secrets.token_hex(4)}"
        (staged / "src").mkdir(parents=True)
        sources = {}
        for name, source in job.sources.items():
            try:
                (staged / "src" / f"{name}.py").write_bytes(source.encode())
            except UnicodeEncodeError as e:
                shutil.rmtree(staged, ignore_errors=True)
                raise BadJob(f"module {name!r}: source is not valid text ({e.reason})") from None
            sources[name] = f"src/{name}.py"
        (staged / "inputs.json").write_bytes(text)
        if blob:
            (staged / "inputs.npz").write_bytes(blob)
        spec = {
            "module": job.module_name,
            "function": job.function,
            "entry": job.entry,
            "sources": sources,
            "inputs": {"json": "inputs.json", "npz": "inputs.npz" if blob else None},
        }
        (staged / "job.json").write_text(json.dumps(spec))
        for path in [staged, staged / "src"]:
            path.chmod(0o755)
        for path in staged.rglob("*"):
            if path.is_file():
                path.chmod(0o644)
        return staged


def _schema_problem(output: Any, schema: Mapping[str, Any]) -> str:
    import jsonschema

    try:
        validator = jsonschema.Draft202012Validator(schema)
        error = jsonschema.exceptions.best_match(validator.iter_errors(to_jsonable(output)))
    except jsonschema.exceptions.SchemaError as e:
        raise BadJob(f"output_schema is not a valid JSON Schema: {e.message}") from None
    if error is None:
        return ""
    path = "output" + "".join(f"[{p!r}]" if isinstance(p, int) else f".{p}" for p in error.path)
    return f"schema: {path}: {error.message}"[:MAX_FIELD]


def _text(value: Any) -> str:
    return value[:MAX_FIELD] if isinstance(value, str) else ""


def _int(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _num(value: Any) -> float | None:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    return float(value) if ok else None


def minimal_env(extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment a harness process starts with: nothing from the caller but PATH."""
    env = {
        "PATH": os.defpath if sys.platform != "linux" else "/usr/local/bin:/usr/bin:/bin",
        "LANG": "C.UTF-8",
        "PYTHONDONTWRITEBYTECODE": "1",
        "PYTHONNOUSERSITE": "1",
        "PYOPENGL_PLATFORM": "egl",
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }
    env.update(extra or {})
    return env
