"""What both backends share: staging a program, the session protocol, judging the answers.

Design rule: the host trusts nothing that comes back. It reads frames under a size cap, decodes
values with `wire.decode_value` (JSON + .npz with ``allow_pickle=False``, bounded in bytes,
elements, nesting and array shapes), checks every field of an answer header, and turns anything
unexpected into a verdict: a dead or garbled harness is ``crashed`` and the next session gets a
fresh one; a harness that does not answer within a call's budget plus a grace period is killed
from here (``timeout``); a harness whose post-session wipe could not finish is replaced.
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

import numpy as np

from sandbox.base import (
    CallReport,
    Const,
    ExceptionInfo,
    Executor,
    Program,
    Session,
    SessionEnd,
    check_limits,
)
from sandbox.errors import BadJob, SandboxUnavailable
from sandbox.harness import wire

GRACE_S = 30.0  # [s] on top of a call's budget before the host kills the harness
START_TIMEOUT_S = 120.0  # [s] for a harness to say hello
CONTROL_TIMEOUT_S = 60.0  # [s] for an open/close answer beyond the program's load budget
MAX_INPUT = 256 << 20  # [bytes] of one call's arguments, or of a program's constants
MAX_FIELD = 16_000  # [chars] of any text field in an answer header
_CALL_VERDICTS = ("ok", "exception", "timeout", "oom", "crashed", "bad_output", "closed")
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


class _HarnessBroke(Exception):
    """The harness died, garbled its answer or did not answer: (verdict, detail)."""

    def __init__(self, verdict: str, detail: str) -> None:
        super().__init__(detail)
        self.verdict, self.detail = verdict, detail


class HarnessExecutor(Executor):
    """An executor that drives a fork-server harness over a `Channel`.

    Subclasses start the harness (`_open`), say where it sees the staged files
    (`_harness_path`), kill it (`_kill`) and explain its death (`_death`). One session runs
    at a time per executor; run sessions in parallel with several executors.

    Args:
        output_limit_mb: cap on one call's answer [MiB] (JSON plus arrays).
        tail_bytes: how much of stdout/stderr to keep [bytes].
    """

    def __init__(self, *, output_limit_mb: float = 64, tail_bytes: int = 8192) -> None:
        self.output_limit = int(output_limit_mb * (1 << 20))
        self.tail_bytes = tail_bytes
        self.stage_root = Path(tempfile.mkdtemp(prefix=f"rivet-sandbox-{self.name}-"))
        self.stage_root.chmod(0o755)  # the harness runs as another user
        self._channel: Channel | None = None
        self._reader = wire.FrameReader(self.output_limit + wire.MAX_HEADER + (1 << 16))
        self._sessions = 0
        self._open_session: HarnessSession | None = None
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
        """Where the harness sees a staged program directory."""

    @abc.abstractmethod
    def _kill(self) -> None:
        """Kill the harness (and its container) now."""

    @abc.abstractmethod
    def _death(self) -> tuple[str, str]:
        """(verdict, detail) for a harness that died during a call: ``oom`` or ``crashed``."""

    def _diagnostics(self) -> str:
        return ""

    def _check(self, memory_mb: int) -> None:
        """Refuse (`BadJob`) a memory limit this executor cannot honour."""

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
        """The harness's status: modules preloaded, preload errors, sessions run."""
        return self._ask({"kind": "status"}, timeout)

    def _ask(self, request: dict[str, Any], timeout: float) -> dict[str, Any]:
        self.start()
        try:
            header, _ = self._exchange(request, (), timeout)
        except _HarnessBroke as e:
            raise SandboxUnavailable(f"the {self.name} harness did not answer: {e}") from None
        return header

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._open_session is not None:
            self._open_session.close()
        self._discard()
        shutil.rmtree(self.stage_root, ignore_errors=True)

    def _discard(self) -> None:
        """Kill the harness and forget it; the next session starts a fresh one."""
        try:
            if self._channel is not None:
                self._channel.close()
        finally:
            self._channel = None
            self._kill()  # also a harness whose start was interrupted before its channel

    # ------------------------------------------------------------------------ sessions

    def open_session(
        self, program: Program, *, memory_mb: int = 1024, load_timeout_s: float = 60.0
    ) -> HarnessSession:
        if not isinstance(program, Program):
            raise BadJob(f"open_session() takes a sandbox.Program, not {type(program).__name__}")
        check_limits(timeout_s=load_timeout_s, memory_mb=memory_mb)
        self._check(memory_mb)
        if self._open_session is not None:
            raise BadJob("this executor already has an open session; close it first")
        staged = self._stage(program)
        self._sessions += 1
        sid = staged.name
        try:
            self.start()
            request = {
                "kind": "open",
                "id": sid,
                "dir": self._harness_path(staged),
                "memory_mb": memory_mb,
                "load_timeout_s": load_timeout_s,
                "output_limit": self.output_limit,
                "tail_bytes": self.tail_bytes,
            }
            try:
                head, _ = self._exchange(request, (), load_timeout_s + GRACE_S, expect="opened")
                load = self._call_report(head, [])
            except _HarnessBroke as e:
                load = CallReport(verdict=e.verdict, detail=e.detail)  # type: ignore[arg-type]
        except BaseException:
            shutil.rmtree(staged, ignore_errors=True)
            raise
        session = HarnessSession(self, sid, staged, load)
        self._open_session = session
        return session

    def _exchange(
        self,
        request: dict[str, Any],
        sections: tuple[bytes, ...] | list[bytes],
        timeout: float,
        *,
        expect: str | None = None,
    ) -> tuple[dict[str, Any], list[bytes]]:
        """Send one request, read its answer; `_HarnessBroke` when the harness does not answer
        in time (killed), dies, or answers out of turn (restarted)."""
        if self._channel is None:
            raise _HarnessBroke("crashed", "the harness is gone; it restarts for the next session")
        t0 = time.monotonic()
        try:
            self._channel.send(wire.pack_frame(request, sections))
            header, out = self._read(t0 + timeout)
        except TimeoutError:
            self._discard()
            raise _HarnessBroke(
                "timeout", f"the harness did not answer within {timeout:g} s; killed from the host"
            ) from None
        except (ChannelClosed, OSError, wire.FrameError) as e:
            if isinstance(e, wire.FrameError):
                verdict, detail = "crashed", f"the harness channel broke ({e}); restarted"
            else:
                verdict, detail = self._death()
            self._discard()
            raise _HarnessBroke(verdict, detail) from None
        if header.get("kind") == "error":
            raise _HarnessBroke("crashed", f"harness error: {_text(header.get('error'))}")
        if expect is not None and (
            header.get("kind") != expect or header.get("id") != request.get("id")
        ):
            self._discard()
            raise _HarnessBroke(
                "crashed", f"the harness answered out of turn ({str(header)[:200]}); restarted"
            )
        return header, out

    def _read(self, deadline: float) -> tuple[dict[str, Any], list[bytes]]:
        assert self._channel is not None
        while True:
            for frame in self._reader.frames():
                return frame
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("no answer before the deadline")
            self._reader.feed(self._channel.recv(left))

    def _call_report(self, head: Mapping[str, Any], sections: list[bytes]) -> CallReport:
        """The report for an answer header, checking every field; decodes the value."""
        verdict = head.get("verdict")
        fields: dict[str, Any] = {
            "detail": _text(head.get("detail")),
            "seconds": _num(head.get("seconds")) or 0.0,
            "cpu_seconds": _num(head.get("cpu_seconds")) or 0.0,
            "queued_seconds": _num(head.get("queued_seconds")) or 0.0,
            "exit_code": _int(head.get("exit_code")),
            "signal": _int(head.get("signal")),
        }
        if verdict not in _CALL_VERDICTS:
            return CallReport(verdict="crashed", **{**fields, "detail": "unknown verdict"})
        exc = head.get("exception")
        if isinstance(exc, Mapping):
            fields["exception"] = ExceptionInfo(
                type=_text(exc.get("type")),
                message=_text(exc.get("message")),
                traceback=_text(exc.get("traceback")),
            )
        if verdict != "ok":
            return CallReport(verdict=verdict, **fields)
        if head.get("kind") == "opened":
            return CallReport(verdict="ok", **fields)
        if len(sections) != 2:
            return CallReport(verdict="bad_output", **{**fields, "detail": "malformed answer"})
        try:
            value = wire.decode_value(sections[0], sections[1], max_bytes=self.output_limit)
        except wire.BadValue as e:
            return CallReport(verdict="bad_output", **{**fields, "detail": f"output {e}"})
        return CallReport(verdict="ok", value=value, **fields)

    def _stage(self, program: Program) -> Path:
        """Write the program's files where the harness can read them (read-only for it)."""
        staged = self.stage_root / f"s{self._sessions:05d}-{secrets.token_hex(4)}"
        (staged / "src").mkdir(parents=True)
        try:
            sources = {}
            for name, source in program.modules.items():
                try:
                    (staged / "src" / f"{name}.py").write_bytes(source.encode())
                except UnicodeEncodeError as e:
                    raise BadJob(
                        f"module {name!r}: source is not valid text ({e.reason})"
                    ) from None
                sources[name] = f"src/{name}.py"
            spec: dict[str, Any] = {"sources": sources}
            constants, kinds = dict(program.constants), dict.fromkeys(program.constants, "value")
            if program.meshes is not None:
                constants["meshes"] = {
                    str(k): {
                        "vertices": np.asarray(m.vertices, np.float64),
                        "faces": np.asarray(m.faces, np.int64),
                    }
                    for k, m in program.meshes.items()
                }
                kinds["meshes"] = "meshes"
            if constants:
                try:
                    text, blob = wire.encode_value(constants, max_bytes=MAX_INPUT)
                except wire.BadValue as e:
                    raise BadJob(
                        f"constant {e.path.replace('$', 'constants', 1)}: {e.problem}"
                    ) from None
                (staged / "constants.json").write_bytes(text)
                if blob:
                    (staged / "constants.npz").write_bytes(blob)
                spec["constants"] = {
                    "json": "constants.json",
                    "npz": "constants.npz" if blob else None,
                    "kinds": kinds,
                }
            (staged / "program.json").write_text(json.dumps(spec))
        except BaseException:
            shutil.rmtree(staged, ignore_errors=True)
            raise
        for path in [staged, staged / "src"]:
            path.chmod(0o755)
        for path in staged.rglob("*"):
            if path.is_file():
                path.chmod(0o644)
        return staged


class HarnessSession(Session):
    """A session of a `HarnessExecutor` (see `sandbox.base.Session`)."""

    def __init__(self, executor: HarnessExecutor, sid: str, staged: Path, load: CallReport) -> None:
        self.executor = executor
        self.id = sid
        self.staged = staged
        self.load = load
        self.dead = "" if load.ok else f"the program did not load ({load.verdict})"
        self._end: SessionEnd | None = None
        self.calls = 0

    def call(
        self, module: str, function: str, *args: Any, timeout_s: float, **kwargs: Any
    ) -> CallReport:
        return self._request("call", module, function, args, kwargs, timeout_s)

    def attribute(self, module: str, name: str, *, timeout_s: float = 10.0) -> CallReport:
        return self._request("attribute", module, name, (), {}, timeout_s)

    def signature(self, module: str, function: str, *, timeout_s: float = 10.0) -> CallReport:
        return self._request("signature", module, function, (), {}, timeout_s)

    def _request(
        self,
        op: str,
        module: str,
        function: str,
        args: Any,
        kwargs: Mapping[str, Any],
        timeout_s: float,
    ) -> CallReport:
        check_limits(timeout_s=timeout_s)
        if self._end is not None:
            raise BadJob("call() on a closed session")
        if self.dead:
            return CallReport(verdict="closed", detail=self.dead)
        try:
            text, arrays = wire.encode_tree(
                {"args": _consts(list(args)), "kwargs": _consts(kwargs)}, max_bytes=MAX_INPUT
            )
        except wire.BadValue as e:
            raise BadJob(
                f"call argument {e.path.replace('$', 'arguments', 1)}: {e.problem}"
            ) from None
        ex = self.executor
        self.calls += 1
        request = {
            "kind": "call",
            "id": self.id,
            "module": module,
            "function": function,
            "op": op,
            "timeout_s": timeout_s,
        }
        staged = None
        if arrays:  # the child reads them from the staged folder (read-only to the container)
            staged = self.staged / "args" / f"c{self.calls}.npz"
            staged.parent.mkdir(mode=0o755, exist_ok=True)
            with open(staged, "wb") as f:
                wire.write_npz(f, arrays)
            staged.chmod(0o644)
            request["arrays_file"] = staged.name
        try:
            head, sections = ex._exchange(request, (text, b""), timeout_s + GRACE_S)
        except _HarnessBroke as e:
            self.dead = e.detail
            return CallReport(verdict=e.verdict, detail=e.detail)  # type: ignore[arg-type]
        finally:
            if staged is not None:
                staged.unlink(missing_ok=True)
        if head.get("kind") != "answer" or head.get("id") != self.id:
            ex._discard()
            self.dead = "the harness answered out of turn; restarted"
            return CallReport(verdict="crashed", detail=self.dead)
        report = ex._call_report(head, sections)
        if head.get("alive") is not True:
            self.dead = self.dead or report.detail or report.verdict
        return report

    def close(self) -> SessionEnd:
        if self._end is not None:
            return self._end
        ex = self.executor
        end = SessionEnd()
        try:
            if ex._channel is not None:
                head, _ = ex._exchange(
                    {"kind": "close", "id": self.id}, (), CONTROL_TIMEOUT_S, expect="closed"
                )
                end = SessionEnd(
                    stdout_tail=_text(head.get("stdout_tail")),
                    stderr_tail=_text(head.get("stderr_tail")),
                    stdout_bytes=_int(head.get("stdout_bytes")) or 0,
                    stderr_bytes=_int(head.get("stderr_bytes")) or 0,
                    wall_time_s=_num(head.get("wall_s")) or 0.0,
                    peak_memory_mb=_num(head.get("peak_memory_mb")),
                )
                if head.get("dirty"):  # the wipe could not finish: never reuse this container
                    ex._discard()
        except _HarnessBroke:
            pass  # the harness is gone (discarded); the next session starts a fresh one
        finally:
            self._end = end
            ex._open_session = None
            shutil.rmtree(self.staged, ignore_errors=True)
        return end


def _consts(value: Any) -> Any:
    """Call arguments with `Const` markers as the wire's constant references."""
    if isinstance(value, Const):
        return {wire.CONST_KEY: value.name}
    if isinstance(value, Mapping):
        return {k: _consts(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_consts(v) for v in value]
    return value


def _text(value: Any) -> str:
    return wire.clean_text(value[:MAX_FIELD]) if isinstance(value, str) else ""


def _int(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _num(value: Any) -> float | None:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    return float(value) if ok and np.isfinite(value) else None


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
