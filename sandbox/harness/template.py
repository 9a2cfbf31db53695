"""The template: the one process every session's process is forked from.

Design rule: a session's process must start with nothing of any other session in its memory.
A fork copies the whole address space of its parent, freed memory included, and the harness
(PID 1) reads every call's arguments, every answer, every print and every exception message
of every session; so sessions are never forked from it. Instead PID 1 forks the template once,
first thing, before it reads a single request, and the template then forks every session's
process. The template never sees a byte of any session: it receives only *spawn* requests (the
staged program's path, a scratch path, limits) and the four pipe ends of the new session over
a private socket pair, and it answers only with process ids, exit statuses and its own
preload progress. Whatever a session received or computed lives in that session's process
(killed at its end) and in PID 1 (which no program can read: non-dumpable, no ptrace, and it
never forks again).

The template imports the heavy modules (between sessions, so that a session's calls never wait
for them), reaps the session processes it forked and reports their exit status and peak
memory. It is not PID 1, so a program could signal it; the session process's own seccomp
filter (`lockdown`) refuses every signal, priority or limit change aimed at it, and should it
die anyway PID 1 ends too: the harness is gone and the host starts a fresh one.

Messages (JSON, one per SOCK_SEQPACKET datagram): PID 1 → template ``spawn`` (with the four pipe
ends as SCM_RIGHTS), ``closed`` (the session is over and wiped: preloading may resume),
``status``, ``warm``; template → PID 1 ``spawned`` (pid, base RSS),
``exited`` (pid, wait status, peak RSS), ``status``.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import pkgutil
import select
import signal
import socket
import sys
import time
from typing import Any

# Packages whose submodules are preloaded too (the project's own, small and pure Python).
PRELOAD_SUBMODULES = ("contracts", "geometry", "toolbox")
MAX_MESSAGE = 1 << 16  # [bytes] one message either way


class TemplateGone(Exception):
    """The template process ended or stopped answering: the harness cannot go on."""


class Template:
    """PID 1's end of the template: spawn session processes, learn how they ended."""

    def __init__(self, pid: int, sock: socket.socket) -> None:
        self.pid = pid
        self.sock = sock
        self.exits: dict[int, tuple[int, int]] = {}  # pid → (wait status, peak RSS [KiB])
        self.replies: list[dict[str, Any]] = []

    @staticmethod
    def start(*, preload: list[str], close: tuple[int, ...], lockdown: bool) -> Template:
        """Fork the template now (before this process has read any request)."""
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        pid = os.fork()
        if pid == 0:
            try:
                ours.close()
                for fd in close:
                    with contextlib.suppress(OSError):
                        os.close(fd)
                _serve(theirs, list(preload), lockdown)
            finally:
                os._exit(70)
        theirs.close()
        ours.setblocking(False)
        return Template(pid, ours)

    def fileno(self) -> int:
        return self.sock.fileno()

    # ------------------------------------------------------------------ requests

    def spawn(self, params: dict[str, Any], fds: list[int], timeout: float) -> dict[str, Any]:
        """Fork a session process that runs `child.serve` with these pipe ends; returns
        ``{"pid", "base_rss"}`` once it exists."""
        try:
            socket.send_fds(self.sock, [json.dumps({"op": "spawn", **params}).encode()], fds)
        except OSError as e:
            raise TemplateGone(f"the template did not take the request ({e})") from None
        return self._reply("spawned", timeout)

    def closed(self) -> None:
        """The session is over and its scratch space wiped: the template may preload again
        (never before: a program could have planted modules where imports look)."""
        try:
            self.sock.send(json.dumps({"op": "closed"}).encode())
        except OSError as e:
            raise TemplateGone(f"the template did not take the request ({e})") from None

    def ask(self, op: str, timeout: float) -> dict[str, Any]:
        """``status`` (preload progress) or ``warm`` (preload everything, then status)."""
        try:
            self.sock.send(json.dumps({"op": op}).encode())
        except OSError as e:
            raise TemplateGone(f"the template did not take the request ({e})") from None
        return self._reply("status", timeout)

    def _reply(self, op: str, timeout: float) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while True:
            self.poll()
            for i, msg in enumerate(self.replies):
                if msg.get("op") == op:
                    return self.replies.pop(i)
            left = deadline - time.monotonic()
            if left <= 0:
                raise TemplateGone(f"the template did not answer {op!r} within {timeout:g} s")
            select.select([self.sock], [], [], left)

    # ------------------------------------------------------------------ exits

    def poll(self) -> None:
        """Take every message waiting (exit reports are kept in `exits`)."""
        while True:
            try:
                data = self.sock.recv(MAX_MESSAGE)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as e:
                raise TemplateGone(f"the template's socket broke ({e})") from None
            if not data:
                raise TemplateGone("the template process ended")
            msg = json.loads(data)
            if msg.get("op") == "exited":
                self.exits[int(msg["pid"])] = (int(msg["status"]), int(msg["maxrss"]))
            else:
                self.replies.append(msg)

    def exit_of(self, pid: int) -> tuple[int, int] | None:
        """(wait status, peak RSS [KiB]) of a session process that ended, else None."""
        self.poll()
        return self.exits.pop(pid, None)

    def wait_exit(self, pid: int, timeout: float) -> tuple[int, int] | None:
        deadline = time.monotonic() + timeout
        while True:
            got = self.exit_of(pid)
            if got is not None:
                return got
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            select.select([self.sock], [], [], min(left, 0.05))


# ---------------------------------------------------------------------- the template itself


class _Preloader:
    def __init__(self, pending: list[str]) -> None:
        self.pending = pending
        self.preloaded: list[str] = []
        self.errors: dict[str, str] = {}
        self.seconds = 0.0

    def next(self) -> None:
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
            self.errors[name] = f"{type(e).__name__}: {e}"[:500]
        self.seconds += time.perf_counter() - t0

    def status(self) -> dict[str, Any]:
        return {
            "op": "status",
            "preloaded": self.preloaded,
            "pending": self.pending,
            "errors": self.errors,
            "preload_s": round(self.seconds, 3),
        }


def _serve(sock: socket.socket, preload: list[str], lockdown: bool) -> None:
    """The template's loop: preload while no session runs, fork sessions, report exits."""
    from . import child  # the session's code, imported before any session exists

    os.setsid()  # its own process group: no group signal aimed at a session reaches it
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_w, False)
    os.set_blocking(wake_r, False)
    signal.set_wakeup_fd(wake_w, warn_on_full_buffer=False)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    loader = _Preloader(preload)
    live: set[int] = set()
    busy = False  # from a spawn until PID 1 says the session is closed and wiped

    def send(msg: dict[str, Any]) -> None:
        sock.send(json.dumps(msg).encode())

    while True:
        while True:  # report every session process that ended
            try:
                pid, status, usage = os.wait4(-1, os.WNOHANG)
            except ChildProcessError:
                break
            if pid == 0:
                break
            live.discard(pid)
            send({"op": "exited", "pid": pid, "status": status, "maxrss": usage.ru_maxrss})
        # preload only while no session runs (its calls would compete for the CPU) and none
        # has left anything behind
        idle = not live and not busy and loader.pending
        watched: list[Any] = [sock, wake_r]
        ready = select.select(watched, [], [], 0 if idle else None)[0]
        if wake_r in ready:
            with contextlib.suppress(BlockingIOError):
                os.read(wake_r, 4096)
        if sock not in ready:
            if idle and not ready:
                loader.next()
            continue
        data, fds, _, _ = socket.recv_fds(sock, MAX_MESSAGE, 4)
        if not data:
            return  # PID 1 is gone
        req = json.loads(data)
        op = req.get("op")
        if op == "closed":
            busy = False
        elif op == "status":
            send(loader.status())
        elif op == "warm":
            while loader.pending and not live and not busy:
                loader.next()
            send(loader.status())
        elif op == "spawn" and len(fds) == 4:
            base_rss = _status_kib("RssAnon")  # what a forked child starts with, roughly
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:
                try:
                    signal.set_wakeup_fd(-1)
                    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                    for fd in (wake_r, wake_w, sock.fileno()):
                        os.close(fd)
                    child.serve(
                        program_dir=str(req["dir"]),
                        tmp_dir=str(req["tmp_dir"]),
                        result_fd=fds[0],
                        request_fd=fds[1],
                        out_fd=fds[2],
                        err_fd=fds[3],
                        memory_mb=int(req["memory_mb"]),
                        output_limit=int(req["output_limit"]),
                        request_limit=int(req["request_limit"]),
                        lockdown=lockdown,
                        template_pid=os.getppid(),
                    )
                finally:
                    os._exit(70)
            for fd in fds:
                os.close(fd)
            live.add(pid)
            busy = True
            send({"op": "spawned", "pid": pid, "base_rss": base_rss})
        else:
            for fd in fds:
                os.close(fd)
            send({"op": "error", "error": f"bad template request {str(op)[:40]!r}"})


def _status_kib(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0
