"""The fork server: PID 1 of the sandbox container (or, for the local backend, a subprocess).

Design rule: heavy modules are imported once here, every job runs in a fresh forked child, and
this process alone decides the verdict from what it observes (exit status, timing, the cgroup's
OOM counter, the size and shape of the child's one result frame). It talks to the host over
its stdin/stdout with length-prefixed frames (`wire`); the child never holds those descriptors,
and this process is non-dumpable, so the child cannot open them through /proc, ptrace it or read
its memory. As PID 1 of its PID namespace it ignores every signal sent from inside the
container, and after each job it kills every other process in the container.

Usage: python -m sandbox.harness.server [--local] [--tmp DIR] [--preload default|none|a,b]
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import importlib
import os
import pkgutil
import select
import shutil
import signal
import sys
import time
from typing import Any

from . import child, wire

DEFAULT_PRELOAD = (
    "numpy",
    "scipy",
    "scipy.linalg",
    "scipy.spatial",
    "scipy.spatial.transform",
    "scipy.optimize",
    "scipy.ndimage",
    "networkx",
    "jsonschema",
    "PIL.Image",
    "cv2",
    "hypothesis",
    "trimesh",
    "open3d",
    "pyrender",
    "contracts",
    "toolbox",
)
# Packages whose submodules are preloaded too (the project's own, small and pure Python).
PRELOAD_SUBMODULES = ("contracts", "toolbox")
# The only environment variables jobs see; everything else is dropped at start.
ENV_KEEP = (
    "PATH",
    "LANG",
    "LC_ALL",
    "PYTHONPATH",
    "PYTHONDONTWRITEBYTECODE",
    "PYTHONNOUSERSITE",
    "PYTHONHASHSEED",
    "PYOPENGL_PLATFORM",
    "MUJOCO_GL",
    "EGL_PLATFORM",
    "LIBGL_ALWAYS_SOFTWARE",
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "MPLBACKEND",
)
MAX_REQUEST = 1 << 20  # [bytes]
READ_CHUNK = 1 << 20  # [bytes]
_PR_SET_DUMPABLE = 4
_PR_SET_CHILD_SUBREAPER = 36


class Server:
    """One fork server; `serve` answers requests until the host closes the channel."""

    def __init__(
        self, *, chan_in: int, chan_out: int, local: bool, tmp_root: str, preload: list[str]
    ) -> None:
        self.chan_in, self.chan_out = chan_in, chan_out
        self.local = local
        self.tmp_root = tmp_root
        self.pending = list(preload)
        self.preloaded: list[str] = []
        self.preload_errors: dict[str, str] = {}
        self.preload_s = 0.0
        self.reader = wire.FrameReader(MAX_REQUEST)
        self.in_pid1 = os.getpid() == 1 and not local
        self.jobs = 0

    # ---------------------------------------------------------------------------- channel

    def send(self, header: dict[str, Any], sections: list[bytes] | tuple[bytes, ...] = ()) -> None:
        data = memoryview(wire.pack_frame(header, sections))
        while data:
            data = data[os.write(self.chan_out, data) :]

    def _request(self, timeout: float | None) -> dict[str, Any] | None:
        """The next request; None when the host closed the channel."""
        while True:
            for header, _ in self.reader.frames():
                return header
            if timeout is not None and not _readable(self.chan_in, timeout):
                return {"kind": "idle"}
            data = os.read(self.chan_in, READ_CHUNK)
            if not data:
                return None
            self.reader.feed(data)

    def serve(self) -> None:
        self.send(
            {
                "kind": "hello",
                "pid": os.getpid(),
                "python": sys.version.split()[0],
                "local": self.local,
                "pending": list(self.pending),
            }
        )
        while True:
            if self.pending and not _readable(self.chan_in, 0):
                self._preload_next()
                continue
            req = self._request(None)
            if req is None:
                return
            kind = req.get("kind")
            if kind == "job":
                try:
                    self.send(*self.run_job(req))
                except (OSError, ValueError, KeyError, TypeError) as e:  # a failure of ours
                    detail = f"harness error: {type(e).__name__}: {e}"[:500]
                    self.send(
                        {
                            "kind": "result",
                            "id": req.get("id"),
                            "verdict": "crashed",
                            "detail": detail,
                        }
                    )
            elif kind == "warm":
                while self.pending:
                    self._preload_next()
                self.send(self.status())
            elif kind == "status":
                self.send(self.status())
            else:
                self.send({"kind": "error", "error": f"unknown request kind {kind!r}"})

    def status(self) -> dict[str, Any]:
        return {
            "kind": "status",
            "preloaded": self.preloaded,
            "pending": self.pending,
            "errors": self.preload_errors,
            "preload_s": round(self.preload_s, 3),
            "jobs": self.jobs,
            "pid1": self.in_pid1,
        }

    def _preload_next(self) -> None:
        name = self.pending.pop(0)
        t0 = time.perf_counter()
        try:
            module = importlib.import_module(name)
            if name == "cv2":
                module.setNumThreads(1)  # threads created before fork would be lost in the child
            if name in PRELOAD_SUBMODULES and hasattr(module, "__path__"):
                subs = [f"{name}.{m.name}" for m in pkgutil.iter_modules(module.__path__)]
                self.pending[:0] = [s for s in subs if s not in sys.modules]
            self.preloaded.append(name)
        except BaseException as e:  # a broken module must not take the harness down
            self.preload_errors[name] = f"{type(e).__name__}: {e}"[:500]
        self.preload_s += time.perf_counter() - t0

    # ---------------------------------------------------------------------------- jobs

    def run_job(self, req: dict[str, Any]) -> tuple[dict[str, Any], list[bytes]]:
        self.jobs += 1
        timeout = float(req["timeout_s"])
        limit = int(req["output_limit"])
        tail_bytes = int(req.get("tail_bytes", 8192))
        tmp_dir = self._job_tmp()
        res_r, res_w = os.pipe()
        out_r, out_w = os.pipe()
        err_r, err_w = os.pipe()
        oom_before = _oom_kills()
        base_rss = _status_kib("RssAnon")  # what a forked child starts with, roughly
        sys.stdout.flush()
        sys.stderr.flush()
        t0 = time.monotonic()
        pid = os.fork()
        if pid == 0:
            try:
                child.run(
                    job_dir=str(req["dir"]),
                    tmp_dir=tmp_dir,
                    result_fd=res_w,
                    out_fd=out_w,
                    err_fd=err_w,
                    memory_mb=int(req["memory_mb"]),
                    output_limit=limit,
                )
            finally:
                os._exit(70)
        for fd in (res_w, out_w, err_w):
            os.close(fd)
        watch = _Watch(
            pid, res_r, out_r, err_r, result_cap=limit + wire.MAX_HEADER + 4096, tail=tail_bytes
        )
        status, rusage, timed_out = watch.wait(t0 + timeout)
        wall_s = time.monotonic() - t0
        self._kill_leftovers(pid)
        watch.drain()
        watch.close()
        self._wipe_tmp(tmp_dir)
        oom_after = _oom_kills()
        oom = oom_before is not None and oom_after is not None and oom_after > oom_before
        head: dict[str, Any] = {
            "kind": "result",
            "id": req.get("id"),
            "wall_s": round(wall_s, 6),
            "peak_memory_mb": round(max(0, rusage.ru_maxrss - base_rss) / 1024, 3)
            if rusage
            else None,
            "stdout_tail": watch.out.text(),
            "stderr_tail": watch.err.text(),
            "stdout_bytes": watch.out.total,
            "stderr_bytes": watch.err.total,
            "exit_code": None,
            "signal": None,
            "exception": None,
            "detail": "",
        }
        if status is not None and os.WIFSIGNALED(status):
            head["signal"] = os.WTERMSIG(status)
        elif status is not None:
            head["exit_code"] = os.WEXITSTATUS(status)
        sections: list[bytes] = []
        if watch.over_cap:
            head.update(
                verdict="bad_output", detail=f"the result is over the {limit}-byte output cap"
            )
        elif timed_out:
            head.update(verdict="timeout", detail=f"killed after the {timeout:g} s time budget")
        elif oom:
            head.update(
                verdict="oom", detail="the kernel's OOM killer ended the job (memory limit)"
            )
        elif head["signal"] is not None:
            name = _signal_name(head["signal"])
            head.update(verdict="crashed", detail=f"killed by signal {head['signal']} ({name})")
        elif head["exit_code"] != 0:
            head.update(
                verdict="crashed", detail=f"exited with code {head['exit_code']} without a result"
            )
        else:
            sections = self._judge_result(bytes(watch.result), limit, head)
        return head, sections

    def _judge_result(self, data: bytes, limit: int, head: dict[str, Any]) -> list[bytes]:
        """Set the verdict from the child's result frame; the sections to pass on when ok."""
        if not data:
            head.update(verdict="crashed", detail="exited without a result")
            return []
        reader = wire.FrameReader(limit + wire.MAX_HEADER + 4096)
        try:
            reader.feed(data)
            frames = list(reader.frames())
        except wire.FrameError as e:
            head.update(verdict="bad_output", detail=f"malformed result channel: {e}")
            return []
        if len(frames) != 1 or reader.pending:
            head.update(
                verdict="bad_output",
                detail=f"the result channel carried {len(frames)} frames and {reader.pending} "
                "stray bytes; exactly one frame is accepted (forged result?)",
            )
            return []
        frame, sections = frames[0]
        status = frame.get("status")
        if status == "returned" and len(sections) == 2:
            head.update(verdict="ok")
            return sections
        if status == "raised" and _valid_exception(frame.get("exception")):
            exc = frame["exception"]
            head["exception"] = {
                k: exc[k][: 2 * child.MAX_TRACEBACK] for k in ("type", "message", "traceback")
            }
            if frame.get("oom") is True:
                head.update(verdict="oom", detail="MemoryError: the job hit its memory limit")
            else:
                head.update(verdict="exception", detail=f"{exc['type']}: {exc['message']}"[:500])
            return []
        if status == "unencodable" and isinstance(frame.get("problem"), str):
            head.update(
                verdict="bad_output", detail=f"unencodable output: {frame['problem'][:1000]}"
            )
            return []
        head.update(
            verdict="bad_output", detail=f"result frame with status {str(status)[:50]!r} is invalid"
        )
        return []

    def _job_tmp(self) -> str:
        path = os.path.join(self.tmp_root, f"job{self.jobs}-{os.urandom(4).hex()}")
        os.mkdir(path, 0o700)  # a fresh, unguessable name: nothing can be planted there
        return path

    def _wipe_tmp(self, tmp_dir: str) -> None:
        """Remove what the job left in the scratch file systems, never following links."""
        roots = [self.tmp_root, "/dev/shm"] if self.in_pid1 else [tmp_dir]
        for root in roots:
            if root == tmp_dir:
                _remove(root)
                continue
            try:
                entries = list(os.scandir(root))
            except OSError:
                continue
            for entry in entries:
                _remove(entry.path)

    def _kill_leftovers(self, pid: int) -> None:
        """Kill whatever the job started (threads died with it; processes may have escaped)."""
        for _ in range(1000):
            alive = False
            if self.in_pid1:
                try:  # every process in the container but this one; stopped first, so that
                    os.kill(-1, signal.SIGSTOP)  # a fork bomb cannot outrun the killing
                    os.kill(-1, signal.SIGKILL)
                    alive = True
                except ProcessLookupError:
                    pass
            else:  # as a subreaper, orphaned descendants become children of this process
                for p in _children(os.getpid()):
                    try:
                        os.kill(p, signal.SIGKILL)
                        alive = True
                    except ProcessLookupError:
                        pass
            reaped = _reap_all()
            if not alive and not reaped:
                return
            time.sleep(0.001)


class _Tail:
    """The last `size` bytes of a stream and its total length."""

    def __init__(self, size: int) -> None:
        self.size, self.total, self.buf = size, 0, bytearray()

    def add(self, data: bytes) -> None:
        self.total += len(data)
        self.buf += data[-self.size :]
        del self.buf[: max(0, len(self.buf) - self.size)]

    def text(self) -> str:
        return self.buf.decode("utf-8", errors="replace")


class _Watch:
    """Waits for one child while reading its three pipes, with a deadline."""

    def __init__(
        self, pid: int, res_r: int, out_r: int, err_r: int, *, result_cap: int, tail: int
    ) -> None:
        self.pid = pid
        self.result = bytearray()
        self.result_cap = result_cap
        self.over_cap = False
        self.out = _Tail(tail)
        self.err = _Tail(tail)
        self.fds = {res_r: "result", out_r: "out", err_r: "err"}
        self.poll = select.poll()
        for fd in self.fds:
            os.set_blocking(fd, False)
            self.poll.register(fd, select.POLLIN)
        try:
            self.pidfd: int | None = os.pidfd_open(pid)
            self.poll.register(self.pidfd, select.POLLIN)
        except (AttributeError, OSError):
            self.pidfd = None

    def wait(self, deadline: float) -> tuple[int | None, Any, bool]:
        """(wait status, rusage, timed out) once the child exited or was killed."""
        timed_out = False
        while True:
            pid, status, rusage = os.wait4(self.pid, os.WNOHANG)
            if pid:
                return status, rusage, timed_out
            now = time.monotonic()
            if now >= deadline or self.over_cap:
                timed_out = not self.over_cap
                os.kill(self.pid, signal.SIGKILL)
                _, status, rusage = os.wait4(self.pid, 0)
                return status, rusage, timed_out
            wait_s = deadline - now if self.pidfd is not None else min(deadline - now, 0.002)
            for fd, _ in self.poll.poll(int(wait_s * 1000) + 1):
                if fd in self.fds:
                    self._read(fd)

    def _read(self, fd: int) -> bool:
        try:
            data = os.read(fd, READ_CHUNK)
        except BlockingIOError:
            return False
        if not data:
            self.poll.unregister(fd)
            del self.fds[fd]
            os.close(fd)
            return False
        kind = self.fds[fd]
        if kind == "result":
            if len(self.result) + len(data) > self.result_cap:
                self.over_cap = True
            else:
                self.result += data
        else:
            (self.out if kind == "out" else self.err).add(data)
        return True

    def drain(self) -> None:
        for fd in list(self.fds):
            while fd in self.fds and self._read(fd) and not self.over_cap:
                pass

    def close(self) -> None:
        for fd in [*self.fds, *([self.pidfd] if self.pidfd is not None else [])]:
            with contextlib.suppress(OSError):
                os.close(fd)
        self.fds.clear()


def _readable(fd: int, timeout: float) -> bool:
    return bool(select.select([fd], [], [], timeout)[0])


def _reap_all() -> int:
    n = 0
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return n
        if pid == 0:
            return n
        n += 1


def _children(ppid: int) -> list[int]:
    """Direct children of `ppid`: with the subreaper flag, every orphaned descendant too."""
    out = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == ppid:
            out.append(int(name))
    return out


def _remove(path: str) -> None:
    """Remove a file or a tree without following links, even dirs a job chmod-ed to 000."""
    try:
        if os.path.isdir(path) and not os.path.islink(path):
            os.chmod(path, 0o700)
            for dirpath, dirnames, _ in os.walk(path):  # top-down: fix modes before descending
                for d in dirnames:
                    full = os.path.join(dirpath, d)
                    if not os.path.islink(full):
                        os.chmod(full, 0o700)
            shutil.rmtree(path, ignore_errors=True)
        else:
            os.unlink(path)
    except OSError:
        pass


def _valid_exception(exc: Any) -> bool:
    return isinstance(exc, dict) and all(
        isinstance(exc.get(k), str) for k in ("type", "message", "traceback")
    )


def _status_kib(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


def _oom_kills() -> int | None:
    """The container's OOM-kill count (cgroup v2 or v1), None where it cannot be read."""
    for path in ("/sys/fs/cgroup/memory.events", "/sys/fs/cgroup/memory/memory.oom_control"):
        try:
            with open(path) as f:
                for line in f:
                    if line.startswith("oom_kill "):
                        return int(line.split()[1])
        except OSError:
            continue
    return None


def _signal_name(sig: int) -> str:
    try:
        return signal.Signals(sig).name
    except ValueError:
        return "unknown"


def _prctl(option: int, value: int) -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(option, value, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), f"prctl({option}) failed")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="sandbox.harness.server")
    parser.add_argument("--local", action="store_true", help="run as a host subprocess")
    parser.add_argument("--tmp", default="/tmp", help="scratch root for jobs")
    parser.add_argument("--preload", default="default", help="default, none, or a,b,c")
    args = parser.parse_args(argv)
    # The channel moves off fds 0/1 so that stray prints (ours, libraries') go to stderr.
    chan_in, chan_out = os.dup(0), os.dup(1)
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.dup2(2, 1)
    os.close(null)
    for fd in (chan_in, chan_out):
        os.set_inheritable(fd, False)
    _prctl(_PR_SET_DUMPABLE, 0)
    if args.local:
        _prctl(_PR_SET_CHILD_SUBREAPER, 1)
    keep = {k: os.environ[k] for k in ENV_KEEP if k in os.environ}
    os.environ.clear()
    os.environ.update(keep, HOME=args.tmp, TMPDIR=args.tmp)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    if args.preload == "default":
        preload = list(DEFAULT_PRELOAD)
    elif args.preload == "none":
        preload = []
    else:
        preload = [m for m in args.preload.split(",") if m]
    server = Server(
        chan_in=chan_in, chan_out=chan_out, local=args.local, tmp_root=args.tmp, preload=preload
    )
    with contextlib.suppress(BrokenPipeError):
        server.serve()
    return 0


if __name__ == "__main__":
    sys.exit(main())
