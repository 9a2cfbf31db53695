"""The fork server: PID 1 of the sandbox container (or, for the local backend, a subprocess).

Design rule: heavy modules are imported once, by the template (`template`: the first thing this
process forks, before it reads any request); every program runs in a fresh process the template
forks (a *session*: load once, answer many calls), so no session starts with anything of an
earlier one in its memory. This process relays requests and answers and alone decides each
call's verdict
from what it observes: the time from request to answer (it kills the child when the call's
budget runs out, whatever the child does with its signals), the memory the session holds (it
kills the child when that goes over the job's limit: `MemoryWatch`), the exit status, the
cgroup's OOM counter, the size and shape of the one answer frame per call. It talks to the host over its
stdin/stdout with length-prefixed frames (`wire`); the child never holds those descriptors, and
this process is non-dumpable, so the child cannot open them through /proc, ptrace it or read its
memory. As PID 1 of its PID namespace it ignores every signal sent from inside the container.
When a session closes it kills every other process in the container (the template excepted),
removes every System V
and POSIX IPC object, and wipes the scratch file systems within a time bound; a wipe that
cannot finish says so and the host replaces the container.

Requests (host → here): ``open`` (stage dir, limits) → ``opened``; ``call`` (module, function,
budget; two sections: arguments as JSON + .npz, the .npz empty when ``arrays_file`` names it in
the staged ``args/`` folder, which the child then reads itself: a 6 MB observation skips two
copies, through the container's attach stream and the request pipe) → ``answer``; ``close`` → ``closed``;
``warm`` / ``status`` → ``status``.

Usage: python -m sandbox.harness.server [--local] [--tmp DIR] [--preload default|none|a,b]
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import os
import re
import select
import signal
import stat
import sys
import time
from typing import Any

from . import child, wire
from .template import PRELOAD_SUBMODULES, Template, TemplateGone

__all__ = [
    "DEFAULT_PRELOAD",
    "ENV_KEEP",
    "PRELOAD_SUBMODULES",
    "MemoryWatch",
    "Server",
    "main",
    "wipe",
]

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
    "trimesh",
    "open3d",
    "pyrender",
    "contracts",
    "geometry",
    "toolbox",
)
# The only environment variables programs see; everything else is dropped at start.
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
MAX_CONTROL = 1 << 20  # [bytes] an open/close/status request
MAX_CALL = 320 << 20  # [bytes] a call request (its arguments)
READ_CHUNK = 1 << 20  # [bytes]
ARRAYS_FILE = re.compile(r"c[0-9]{1,9}\.npz")  # a call's arrays in the session's args/
WIPE_BUDGET_S = 3.0  # [s] the post-session wipe; a longer one reports the container dirty
MEMORY_POLL_S = 0.02  # [s] how often a call's loop reads the session's memory (at most)
_PR_SET_DUMPABLE = 4
_PR_SET_CHILD_SUBREAPER = 36
_IPC_RMID = 0


class Server:
    """One fork server; `serve` answers requests until the host closes the channel.

    Session processes are forked by the `template` (started before this process reads any
    request), never by this process: see `sandbox.harness.template`.
    """

    def __init__(
        self,
        *,
        chan_in: int,
        chan_out: int,
        local: bool,
        tmp_root: str,
        preload: list[str],
        template: Template,
    ) -> None:
        self.chan_in, self.chan_out = chan_in, chan_out
        self.local = local
        self.tmp_root = tmp_root
        self.preload = list(preload)
        self.template = template
        self.reader = wire.FrameReader(MAX_CALL + wire.MAX_HEADER + 4096)
        self.in_pid1 = os.getpid() == 1 and not local
        self.sessions = 0
        self.session: _Child | None = None
        self.dirty = ""  # why the container can no longer be trusted clean ("" when it can)

    # ---------------------------------------------------------------------------- channel

    def send(self, header: dict[str, Any], sections: list[bytes] | tuple[bytes, ...] = ()) -> None:
        data = memoryview(wire.pack_frame(header, sections))
        while data:
            data = data[os.write(self.chan_out, data) :]

    def _request(self) -> tuple[dict[str, Any], list[bytes]] | None:
        """The next request; None when the host closed the channel."""
        while True:
            for frame in self.reader.frames():
                return frame
            watched: list[Any] = [self.chan_in, self.template.sock]
            ready = select.select(watched, [], [])[0]
            if self.template.sock in ready:
                self.template.poll()  # raises TemplateGone when the template ended
            if self.chan_in not in ready:
                continue
            data = os.read(self.chan_in, READ_CHUNK)
            if not data:
                return None
            self.reader.feed(data)

    def serve(self) -> None:
        try:
            self._serve()
        except TemplateGone as e:
            self._fatal(str(e))

    def _fatal(self, why: str) -> None:
        """The template is gone, so no session can start or end cleanly: kill every process
        this harness is answerable for and exit (the host starts a fresh harness)."""
        with contextlib.suppress(OSError):
            if self.session is not None:
                self.session.kill()
            if self.in_pid1:
                os.kill(-1, signal.SIGKILL)
            else:
                for p in _children(os.getpid()):
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(p, signal.SIGKILL)
        with contextlib.suppress(OSError):
            os.write(2, f"sandbox harness: {why}; exiting\n".encode())
        os._exit(3)

    def _serve(self) -> None:
        self.send(
            {
                "kind": "hello",
                "pid": os.getpid(),
                "python": sys.version.split()[0],
                "local": self.local,
                "pending": list(self.preload),
                "template": self.template.pid,
            }
        )
        while True:
            got = self._request()
            if got is None:
                if self.session is not None:
                    self._close_session()
                return
            req, sections = got
            kind = req.get("kind")
            try:
                if kind == "open":
                    self.send(self.open_session(req))
                elif kind == "call":
                    self.send(*self.call(req, sections))
                elif kind == "close":
                    self.send(self._close_session(req.get("id")))
                elif kind in ("warm", "status"):
                    self.send(self.status(warm=kind == "warm"))
                else:
                    self.send({"kind": "error", "error": f"unknown request kind {kind!r:.40}"})
            except (OSError, ValueError, KeyError, TypeError) as e:  # a failure of ours
                detail = f"harness error: {type(e).__name__}: {e}"[:500]
                self.send({"kind": "error", "id": req.get("id"), "error": detail})

    def status(self, *, warm: bool = False) -> dict[str, Any]:
        got = self.template.ask("warm" if warm else "status", 600.0 if warm else 60.0)
        return {
            "kind": "status",
            "preloaded": got.get("preloaded", []),
            "pending": got.get("pending", []),
            "errors": got.get("errors", {}),
            "preload_s": got.get("preload_s", 0.0),
            "sessions": self.sessions,
            "pid1": self.in_pid1,
            "template": self.template.pid,
            "dirty": self.dirty,
        }

    # ---------------------------------------------------------------------------- sessions

    def open_session(self, req: dict[str, Any]) -> dict[str, Any]:
        """Have the template fork a process that loads the program; answer once it is ready
        (or failed)."""
        if self.session is not None:
            return {"kind": "error", "id": req.get("id"), "error": "a session is already open"}
        self.sessions += 1
        tmp_dir = self._session_tmp()
        pipes = {name: os.pipe() for name in ("res", "req", "out", "err")}
        output_limit = int(req["output_limit"])
        load_timeout = float(req["load_timeout_s"])
        oom_before = _oom_kills()
        memory = MemoryWatch.start(int(req["memory_mb"])) if self.in_pid1 else None
        t0 = time.monotonic()
        theirs = [pipes["res"][1], pipes["req"][0], pipes["out"][1], pipes["err"][1]]
        try:
            spawned = self.template.spawn(
                {
                    "dir": str(req["dir"]),
                    "tmp_dir": tmp_dir,
                    "memory_mb": int(req["memory_mb"]),
                    "output_limit": output_limit,
                    "request_limit": MAX_CALL + wire.MAX_HEADER + 4096,
                },
                theirs,
                timeout=max(load_timeout, 60.0),
            )
        finally:
            for end in theirs:
                os.close(end)
        self.session = _Child(
            id=req.get("id"),
            pid=int(spawned["pid"]),
            template=self.template,
            res_r=pipes["res"][0],
            req_w=pipes["req"][1],
            out_r=pipes["out"][0],
            err_r=pipes["err"][0],
            result_cap=output_limit + wire.MAX_HEADER + 4096,
            tail=int(req.get("tail_bytes", 8192)),
            tmp_dir=tmp_dir,
            base_rss=int(spawned.get("base_rss", 0)),
            started=t0,
            in_container=self.in_pid1,
            memory=memory.allowing(int(spawned.get("base_rss", 0)) << 10) if memory else None,
        )
        head, _ = self.session.exchange(None, [], load_timeout, oom_before)
        head.update(kind="opened", id=req.get("id"), load_s=round(time.monotonic() - t0, 6))
        if head.get("verdict") == "returned":
            head["verdict"] = "ok"
        return head

    def call(self, req: dict[str, Any], sections: list[bytes]) -> tuple[dict, list[bytes]]:
        s = self.session
        if s is None or s.id != req.get("id"):
            return {"kind": "error", "id": req.get("id"), "error": "no such open session"}, []
        if s.dead:
            return {"kind": "answer", "id": s.id, "verdict": "closed", "detail": s.dead}, []
        forward = {
            "module": str(req.get("module")),
            "function": str(req.get("function")),
            "op": str(req.get("op", "call")),
        }
        arrays_file = req.get("arrays_file")
        if arrays_file is not None:
            if not (isinstance(arrays_file, str) and ARRAYS_FILE.fullmatch(arrays_file)):
                return {"kind": "error", "id": s.id, "error": "malformed arrays_file"}, []
            forward["arrays_file"] = arrays_file
        request = wire.pack_frame(forward, sections)
        head, out = s.exchange(request, sections, float(req["timeout_s"]), _oom_kills())
        head.update(kind="answer", id=s.id, alive=not s.dead and s.status is None)
        if head.get("verdict") == "returned":
            head["verdict"] = "ok"
        return head, out

    def _close_session(self, sid: Any = None) -> dict[str, Any]:
        s = self.session
        if s is None or (sid is not None and s.id != sid):
            return {"kind": "error", "id": sid, "error": "no such open session"}
        s.kill()
        ended = s.reap()
        self._kill_leftovers()
        s.drain()
        s.close_fds()
        self.session = None
        t_wipe = time.monotonic()
        left = self._cleanup(s.tmp_dir)
        if left:
            self.dirty = left
        self.template.closed()  # wiped: the template may import again
        return {
            "kind": "closed",
            "id": s.id,
            "wall_s": round(time.monotonic() - s.started, 6),
            "wipe_s": round(time.monotonic() - t_wipe, 6),
            "peak_memory_mb": round(max(0, ended[1] - s.base_rss) / 1024, 3)
            if ended is not None
            else None,
            "stdout_tail": s.out.text(),
            "stderr_tail": s.err.text(),
            "stdout_bytes": s.out.total,
            "stderr_bytes": s.err.total,
            "dirty": self.dirty,
        }

    def _session_tmp(self) -> str:
        path = os.path.join(self.tmp_root, f"s{self.sessions}-{os.urandom(4).hex()}")
        os.mkdir(path, 0o700)  # a fresh, unguessable name: nothing can be planted there
        return path

    def _kill_leftovers(self) -> None:
        """Kill whatever the program started (threads died with it; processes may have
        escaped into their own sessions), sparing only the template."""
        spare = {os.getpid(), self.template.pid}
        for _ in range(1000):
            alive = False
            if self.in_pid1:
                # every process in the container but this one, stopped first so that a fork
                with contextlib.suppress(ProcessLookupError):  # bomb cannot outrun the killing
                    os.kill(-1, signal.SIGSTOP)
                for p in _live_pids():
                    if p not in spare:
                        with contextlib.suppress(ProcessLookupError):
                            os.kill(p, signal.SIGKILL)
                            alive = True
                with contextlib.suppress(ProcessLookupError):
                    os.kill(self.template.pid, signal.SIGCONT)
            else:  # as a subreaper, orphaned descendants become children of this process
                for p in _children(os.getpid()):
                    if p in spare:
                        continue
                    try:
                        os.kill(p, signal.SIGKILL)
                        alive = True
                    except ProcessLookupError:
                        pass
            reaped = self._reap_all()
            if not alive and not reaped:
                return
            time.sleep(0.001)

    def _reap_all(self) -> int:
        """Reap every child that ended (orphans the container's init adopted); the template
        among them means the harness cannot go on."""
        n = 0
        while True:
            try:
                pid, _ = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                return n
            if pid == 0:
                return n
            if pid == self.template.pid:
                raise TemplateGone("the template process ended")
            n += 1

    def _cleanup(self, tmp_dir: str) -> str:
        """Remove what the session left: IPC objects, scratch files. '' when all is gone,
        else what is left (the container is then dirty)."""
        deadline = time.monotonic() + WIPE_BUDGET_S
        problems = []
        if self.in_pid1:
            problems += _remove_ipc()
            roots = [self.tmp_root, "/dev/shm"]
        else:
            roots = [tmp_dir]
        for root in roots:
            left = wipe(root, deadline, keep_root=root != tmp_dir)
            if left:
                problems.append(f"{root}: {left}")
        return "; ".join(problems)


class MemoryWatch:
    """What a session holds of the container's memory, against the job's limit.

    `RLIMIT_DATA` (set in the session's process) stops the heap early with a `MemoryError`,
    but it counts one process's private memory only: not shared memory (shared anonymous
    maps, memfds, files in the tmpfs /tmp and /dev/shm), nor what processes the session forks
    allocate each. So PID 1 also reads the container's cgroup — anonymous plus shared memory —
    while a call runs (every `MEMORY_POLL_S`, and once the answer is in) and kills the session
    when what it holds goes over its limit. What the session holds is the cgroup's count less
    what it was when the session opened (the harness and the template, idle meanwhile) and
    less what PID 1 itself grew by since (the frames it relays). A session's limit is the
    job's `memory_mb` plus the template's own anonymous memory: a forked process that writes
    to pages it shares with the template gets private copies of them, which the job did not
    allocate. The container's memory limit stays the hard bound (its OOM killer takes a
    session's process first); a session that holds memory for less than `MEMORY_POLL_S` at a
    time can go over its own limit unseen, never over the container's.
    """

    def __init__(self, *, base: int, pid1: int, limit: int) -> None:
        self.base = base  # [bytes] the cgroup's anonymous + shared memory at the start
        self.pid1 = pid1  # [bytes] PID 1's anonymous memory at the start
        self.limit = limit  # [bytes]

    @staticmethod
    def start(memory_mb: int) -> MemoryWatch | None:
        """The watch of a session about to be spawned; None where the cgroup is unreadable."""
        base = _cgroup_memory()
        if base is None:
            return None
        return MemoryWatch(base=base, pid1=_status_kib("RssAnon") << 10, limit=memory_mb << 20)

    def allowing(self, inherited: int) -> MemoryWatch:
        """The same watch with `inherited` bytes (the template's anonymous memory, which the
        session may come to hold private copies of) added to the limit."""
        return MemoryWatch(base=self.base, pid1=self.pid1, limit=self.limit + max(0, inherited))

    def held(self) -> int:
        """What the session holds now [bytes] (0 where the cgroup became unreadable)."""
        now = _cgroup_memory()
        if now is None:
            return 0
        grown = max(0, (_status_kib("RssAnon") << 10) - self.pid1)
        return now - self.base - grown

    def over(self) -> bool:
        return self.held() > self.limit


class _Tail:
    """The last `size` bytes of a stream and its total length."""

    def __init__(self, size: int) -> None:
        self.size, self.total, self.buf = size, 0, bytearray()

    def add(self, data: bytes) -> None:
        self.total += len(data)
        self.buf += data[-self.size :]
        del self.buf[: max(0, len(self.buf) - self.size)]

    def text(self) -> str:
        return wire.clean_text(self.buf.decode("utf-8", errors="replace"))


class _Child:
    """One session's process: its pipes, what it printed, and how it answers."""

    def __init__(
        self,
        *,
        id: Any,
        pid: int,
        template: Template,
        res_r: int,
        req_w: int,
        out_r: int,
        err_r: int,
        result_cap: int,
        tail: int,
        tmp_dir: str,
        base_rss: int,
        started: float,
        in_container: bool,
        memory: MemoryWatch | None = None,
    ) -> None:
        self.id, self.pid = id, pid
        self.template = template
        self.req_w = req_w
        self.result_cap = result_cap
        self.tmp_dir, self.base_rss, self.started = tmp_dir, base_rss, started
        self.out, self.err = _Tail(tail), _Tail(tail)
        self.results = wire.FrameReader(result_cap)
        self.malformed = False
        self.fds = {res_r: "result", out_r: "out", err_r: "err"}
        self.poll = select.poll()
        for fd in self.fds:
            os.set_blocking(fd, False)
            self.poll.register(fd, select.POLLIN)
        self.poll.register(template.fileno(), select.POLLIN)  # wakes when the process ends
        self._watching_request = False
        os.set_blocking(req_w, False)
        self.status: int | None = None
        self.peak_kib = 0  # peak resident memory of the process [KiB], known once it ended
        self.dead = ""  # why the session can answer no more calls
        self.in_container = in_container
        self.memory = memory  # None: only RLIMIT_DATA (the local backend)
        self.memory_read = 0.0  # when the memory was last read [monotonic s]

    def over_memory(self, now: float, *, force: bool = False) -> bool:
        """Whether the session holds more memory than its limit (read at most every
        `MEMORY_POLL_S` unless `force`)."""
        if self.memory is None or (not force and now - self.memory_read < MEMORY_POLL_S):
            return False
        self.memory_read = now
        return self.memory.over()

    def exchange(
        self, request: bytes | None, sections: list[bytes], timeout: float, oom_before: Any
    ) -> tuple[dict[str, Any], list[bytes]]:
        """Send a request (None: wait for the ready frame) and wait for its one answer frame.

        Returns (header with ``verdict`` and ``seconds``, sections when it returned).
        """
        stray = request is not None and (
            self.results.pending or self.malformed or self._readable_result()
        )
        if stray:  # bytes before the request: the program wrote them on its own
            self._die("the program wrote to its result channel out of turn")
            return self._verdict("bad_output", self.dead), []
        t0 = time.monotonic()
        cpu0 = self.cpu_seconds()
        queued0 = self.run_delays()
        relay0 = _own_run_delay()
        deadline = t0 + max(timeout, 0.0)
        pending = memoryview(request) if request is not None else memoryview(b"")
        frame, over_cap = None, False
        while True:
            if self.status is None:
                ended = self.template.exit_of(self.pid)
                if ended is not None:
                    self.status, self.peak_kib = ended
            frame, over_cap = self._frame()
            if frame is None and not over_cap and self.status is not None:
                # it has ended, so all it wrote is in the pipes: read the rest before judging
                # it (its answer may have come with its exit, in one wake-up or none)
                for fd in [f for f, kind in self.fds.items() if kind == "result"]:
                    while fd in self.fds and self._read(fd):
                        pass
                frame, over_cap = self._frame()
            if frame is not None or over_cap or self.status is not None:
                break
            now = time.monotonic()
            if self.memory is not None and self.over_memory(now):
                self._watch_request(False)
                return self._memory_out(self.memory, t0, cpu0), []
            if now >= deadline:
                self.kill()
                self.reap()
                seconds = time.monotonic() - t0
                self._die(f"killed after the {timeout:.3g} s budget of a call")
                late = self._verdict("timeout", f"killed after the {timeout:.3g} s time budget")
                late["seconds"] = round(seconds, 6)
                self._watch_request(False)
                return late, []
            if pending:
                try:
                    n = os.write(self.req_w, pending[:READ_CHUNK])
                    pending = pending[n:]
                except BlockingIOError:
                    pass
                except BrokenPipeError:
                    pending = memoryview(b"")
            # while a request is being written, wake as soon as the program has drained the
            # pipe (POLLOUT), not after a fixed pause: a 6 MB observation is 100 pipefuls
            self._watch_request(bool(pending))
            idle = MEMORY_POLL_S if self.memory is not None else 0.05
            wait = min(deadline - now, idle)
            for fd, _ in self.poll.poll(int(wait * 1000) + 1):
                if fd in self.fds:
                    self._read(fd)
        self._watch_request(False)
        if (
            self.memory is not None
            and self.status is None
            and self.over_memory(time.monotonic(), force=True)
        ):  # it still holds too much once it answered
            return self._memory_out(self.memory, t0, cpu0), []
        seconds = time.monotonic() - t0
        cpu = self.cpu_seconds() - cpu0
        oom_after = _oom_kills()
        oom = oom_before is not None and oom_after is not None and oom_after > oom_before
        head: dict[str, Any]
        out: list[bytes] = []
        if over_cap:
            self.kill()
            self._die("the answer was over the output cap or not a frame")
            head = self._verdict(
                "bad_output",
                "the answer is over the output cap, or its channel does not carry frames "
                "(forged result?)",
            )
        elif frame is not None:
            # the first frame is the answer; bytes after it (forged or stray) are refused when
            # the next call finds them, so that what this call gets never depends on timing
            head, out = self._judge(*frame)
        elif oom:
            self._die("the kernel's OOM killer ended the program")
            head = self._verdict("oom", "the kernel's OOM killer ended the job (memory limit)")
        else:
            head = self._death()
        head["seconds"] = round(seconds, 6)
        head["cpu_seconds"] = round(max(cpu, 0.0), 6)
        queued = self.queued_seconds(queued0) if self.status is None else 0.0
        queued += max(0, _own_run_delay() - relay0) / 1e9  # this process relaying meanwhile
        head["queued_seconds"] = round(min(queued, seconds), 6)
        return head, out

    def _watch_request(self, on: bool) -> None:
        """Poll the request pipe for room (POLLOUT) while a request is pending, else not."""
        if on == self._watching_request:
            return
        if on:
            self.poll.register(self.req_w, select.POLLOUT)
        else:
            self.poll.unregister(self.req_w)
        self._watching_request = on

    def _memory_out(self, memory: MemoryWatch, t0: float, cpu0: float) -> dict[str, Any]:
        """Kill a session over its memory limit: the call's ``oom`` answer."""
        held = memory.held()
        cpu = self.cpu_seconds() - cpu0
        self.kill()
        self.reap()
        self._die("killed: it held more memory than its limit")
        head = self._verdict(
            "oom",
            f"the job held {held / (1 << 20):.0f} MiB (shared memory and files in /tmp and "
            f"/dev/shm included), over its limit of {memory.limit / (1 << 20):.0f} MiB",
        )
        head["seconds"] = round(time.monotonic() - t0, 6)
        head["cpu_seconds"] = round(max(cpu, 0.0), 6)
        return head

    def run_delays(self) -> dict[str, int]:
        """How long each thread of the session's process has waited, runnable, for a CPU so
        far (its run-queue delay, /proc/PID/task/TID/schedstat) [ns], by thread id."""
        out: dict[str, int] = {}
        try:
            tids = os.listdir(f"/proc/{self.pid}/task")
        except OSError:
            return out
        for tid in tids:
            try:
                with open(f"/proc/{self.pid}/task/{tid}/schedstat", "rb") as f:
                    out[tid] = int(f.read().split()[1])
            except (OSError, ValueError, IndexError):
                continue
        return out

    def queued_seconds(self, before: dict[str, int]) -> float:
        """The longest any one thread of the session's process waited for a CPU since
        `before` (`run_delays`) [s]: what a busy machine added to the call's wall time, about.
        One thread's, not the sum: many threads made runnable at once pile up waits without
        using much CPU, while one thread waits only as long as others run (CPU time the
        checks count) or the machine is busy. Threads that ended, and the session's other
        processes, are not looked at: the figure can only understate the wait."""
        now = self.run_delays()
        grown = [delay - before.get(tid, 0) for tid, delay in now.items()]
        return max([0, *grown]) / 1e9

    def cpu_seconds(self) -> float:
        """CPU time used so far by the program: the container's whole account inside the
        sandbox (every process and thread the program started; the harness idles meanwhile),
        else the program's own process [s]. Unlike wall time, it does not grow when the
        machine is busy with other work."""
        used = _cgroup_cpu_seconds() if self.in_container else None
        if used is not None:
            return used
        try:
            with open(f"/proc/{self.pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        except (OSError, ValueError, IndexError):
            return 0.0

    def _readable_result(self) -> bool:
        for fd, kind in list(self.fds.items()):
            if kind == "result" and _readable(fd, 0):
                self._read(fd)
        return bool(self.results.pending) or self.malformed

    def _frame(self) -> tuple[tuple[dict, list[bytes]] | None, bool]:
        """The first complete frame of the result stream (taken from it), or None; True when
        the stream is over its cap or not frames at all."""
        if self.malformed:
            return None, True
        try:
            for frame in self.results.frames():
                return frame, False
        except wire.FrameError:
            self.malformed = True
            return None, True
        return None, False

    def _judge(self, frame: dict[str, Any], sections: list[bytes]) -> tuple[dict, list[bytes]]:
        status = frame.get("status")
        if status in ("returned", "ready") and len(sections) == (2 if status == "returned" else 0):
            return {"verdict": "returned"}, list(sections)
        if status == "raised" and _valid_exception(frame.get("exception")):
            exc = frame["exception"]
            head: dict[str, Any] = {
                "exception": {
                    k: wire.clean_text(exc[k][: 2 * child.MAX_TRACEBACK])
                    for k in ("type", "message", "traceback")
                }
            }
            if frame.get("oom") is True:
                head.update(verdict="oom", detail="MemoryError: the job hit its memory limit")
            else:
                detail = f"{exc['type']}: {exc['message']}"[:500]
                head.update(verdict="exception", detail=wire.clean_text(detail))
            return head, []
        if status == "unencodable" and isinstance(frame.get("problem"), str):
            problem = wire.clean_text(frame["problem"][:1000])
            return {"verdict": "bad_output", "detail": f"unencodable output: {problem}"}, []
        return self._verdict(
            "bad_output", f"answer frame with status {str(status)[:50]!r} is invalid"
        ), []

    def _death(self) -> dict[str, Any]:
        status = self.status
        if status is not None and os.WIFSIGNALED(status):
            sig = os.WTERMSIG(status)
            self._die(f"the program's process was killed by signal {sig}")
            return {
                **self._verdict("crashed", f"killed by signal {sig} ({_signal_name(sig)})"),
                "signal": sig,
            }
        code = os.WEXITSTATUS(status) if status is not None else None
        self._die(f"the program's process exited (code {code})")
        return {
            **self._verdict("crashed", f"exited with code {code} without a result"),
            "exit_code": code,
        }

    def _verdict(self, verdict: str, detail: str) -> dict[str, Any]:
        return {"verdict": verdict, "detail": detail}

    def _die(self, why: str) -> None:
        self.dead = self.dead or why

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
            if not self.malformed:
                try:
                    self.results.feed(data)
                except wire.FrameError:
                    self.malformed = True
        else:
            (self.out if kind == "out" else self.err).add(data)
        return True

    def kill(self) -> None:
        """SIGKILL the session's process and its process group (it leads one: `setsid`) in one
        go: the kernel also delivers a group signal to a child forked while it is sent, so
        a fork bomb ends at once instead of slowing the death of each process it outnumbers.
        What left the group is killed when the session closes."""
        if self.status is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.pid, signal.SIGKILL)
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGKILL)

    def reap(self) -> tuple[int, int] | None:
        """Wait until the template reports the process ended (it was sent SIGKILL):
        (wait status, peak RSS [KiB]), None when it did not say in time."""
        if self.status is None:
            ended = self.template.wait_exit(self.pid, 30.0)
            if ended is None:
                raise TemplateGone(f"the template did not report the end of process {self.pid}")
            self.status, self.peak_kib = ended
        return self.status, self.peak_kib

    def drain(self) -> None:
        for fd in list(self.fds):
            for _ in range(64):  # bounded: a leftover writer was killed, the pipe ends
                if fd not in self.fds or not self._read(fd):
                    break

    def close_fds(self) -> None:
        for fd in [*self.fds, self.req_w]:
            with contextlib.suppress(OSError):
                os.close(fd)
        self.fds.clear()


# -------------------------------------------------------------------------------- cleanup


def wipe(root: str, deadline: float, *, keep_root: bool = True) -> str:
    """Remove everything under `root` (and `root` itself unless `keep_root`), never following a
    link, whatever the modes (a directory chmod-ed to 000 is opened again) and however deep
    (no recursion, two descriptors at a time). Returns '' when done, else what stopped it."""
    flags = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW
    try:
        top = os.open(root, flags)
    except FileNotFoundError:
        return ""
    except OSError as e:
        return f"cannot open: {e.strerror}"
    names: list[str] = []  # the path from `top` to `cur`
    cur = top
    try:
        while True:
            if time.monotonic() > deadline:
                return f"not wiped within {WIPE_BUDGET_S:g} s ({len(names)} levels deep)"
            with os.scandir(cur) as it:
                entry = next(iter(it), None)
            if entry is None:  # empty: go up and remove it
                if not names:
                    break
                parent = os.open("..", flags, dir_fd=cur)
                os.close(cur)
                cur = parent
                os.rmdir(names.pop(), dir_fd=cur)
                continue
            name = entry.name
            try:
                is_dir = entry.is_dir(follow_symlinks=False)
            except OSError:
                is_dir = False
            if not is_dir:
                os.unlink(name, dir_fd=cur)
                continue
            with contextlib.suppress(OSError):
                os.chmod(name, stat.S_IRWXU, dir_fd=cur)
            sub = os.open(name, flags, dir_fd=cur)
            os.close(cur)
            cur = sub
            names.append(name)
    except OSError as e:
        return f"cannot remove ({e.strerror})"
    finally:
        os.close(cur)
    if not keep_root:
        try:
            os.rmdir(root)
        except OSError as e:
            return f"cannot remove the root ({e.strerror})"
    return ""


def _remove_ipc() -> list[str]:
    """Remove every System V IPC object and POSIX message queue of the container's IPC
    namespace (the seccomp profile denies creating them; this holds where it is not in force)."""
    problems = []
    libc = ctypes.CDLL(None, use_errno=True)
    for kind, ctl in (("shm", "shmctl"), ("msg", "msgctl"), ("sem", "semctl")):
        try:
            with open(f"/proc/sysvipc/{kind}") as f:
                rows = f.read().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            fields = row.split()
            if len(fields) < 2 or not fields[1].isdigit():
                continue
            ident = int(fields[1])
            args = (ident, 0, _IPC_RMID, None) if kind == "sem" else (ident, _IPC_RMID, None)
            if getattr(libc, ctl)(*args) != 0:
                problems.append(f"{kind} {ident}: {os.strerror(ctypes.get_errno())}")
    try:
        queues = os.listdir("/dev/mqueue")
    except OSError:
        queues = []
    for name in queues:
        try:
            os.unlink(os.path.join("/dev/mqueue", name))
        except OSError as e:
            problems.append(f"mqueue {name}: {e.strerror}")
    return problems


def _readable(fd: int, timeout: float) -> bool:
    return bool(select.select([fd], [], [], timeout)[0])


def _live_pids() -> list[int]:
    """Every process of the PID namespace that has not ended (zombies left out)."""
    out = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as f:
                state = f.read().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            continue
        if state not in ("Z", "X"):
            out.append(int(name))
    return out


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


def _own_run_delay() -> int:
    """How long this process has waited, runnable, for a CPU [ns] (0 where unreadable): while
    it relays a call's arguments or answer, the session's process waits on it."""
    try:
        with open("/proc/self/schedstat", "rb") as f:
            return int(f.read().split()[1])
    except (OSError, ValueError, IndexError):
        return 0


def _cgroup_cpu_seconds() -> float | None:
    """CPU time the container's cgroup has used (v2 or v1) [s], None where unreadable."""
    try:
        with open("/sys/fs/cgroup/cpu.stat") as f:
            for line in f:
                if line.startswith("usage_usec "):
                    return int(line.split()[1]) / 1e6
    except OSError:
        pass
    for path in (
        "/sys/fs/cgroup/cpuacct/cpuacct.usage",
        "/sys/fs/cgroup/cpu,cpuacct/cpuacct.usage",
    ):
        try:
            with open(path) as f:
                return int(f.read()) / 1e9
        except (OSError, ValueError):
            continue
    return None


_MEMORY_STAT = (  # (file, the keys whose sum is anonymous + shared memory): cgroup v2, v1
    ("/sys/fs/cgroup/memory.stat", ("anon", "shmem")),
    ("/sys/fs/cgroup/memory/memory.stat", ("total_rss", "total_shmem")),
)


def _cgroup_memory() -> int | None:
    """Anonymous plus shared memory (shmem: tmpfs files, shared maps, memfds, System V
    segments) charged to the container's cgroup [bytes], None where it cannot be read."""
    for path, keys in _MEMORY_STAT:
        try:
            with open(path, "rb") as f:
                text = f.read()
        except OSError:
            continue
        found = {}
        for line in text.splitlines():
            key, _, value = line.partition(b" ")
            if key.decode() in keys:
                found[key.decode()] = int(value)
        if len(found) == len(keys):
            return sum(found.values())
    return None


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
    parser.add_argument("--tmp", default="/tmp", help="scratch root for sessions")
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
    # `python -m` puts the working directory (the scratch root, which programs write) first
    # on the module path: nothing is ever imported from there, by the harness, the template
    # (which imports between sessions) or a session.
    scratch, cwd = os.path.realpath(args.tmp), os.path.realpath(os.getcwd())
    sys.path[:] = [
        p
        for p in sys.path
        if p
        and os.path.realpath(p) != cwd
        and os.path.commonpath([scratch, os.path.realpath(p)]) != scratch
    ]
    keep = {k: os.environ[k] for k in ENV_KEEP if k in os.environ}
    os.environ.clear()
    os.environ.update(keep, HOME=args.tmp, TMPDIR=args.tmp)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    if args.preload == "default":
        preload = list(DEFAULT_PRELOAD)
    elif args.preload == "none":
        preload = []
    else:
        preload = [m for m in args.preload.split(",") if m]
    # The template is forked before anything is read from the host: see `template`.
    template = Template.start(
        preload=preload, close=(chan_in, chan_out), lockdown=os.getpid() == 1 and not args.local
    )
    server = Server(
        chan_in=chan_in,
        chan_out=chan_out,
        local=args.local,
        tmp_root=args.tmp,
        preload=preload,
        template=template,
    )
    with contextlib.suppress(BrokenPipeError):
        server.serve()
    return 0


if __name__ == "__main__":
    sys.exit(main())
