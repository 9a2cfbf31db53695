"""The local backend: the same fork-server harness as a plain subprocess. It ISOLATES NOTHING.

What it does NOT isolate — everything the Docker backend exists for: the draft runs as your
user with your file system (it can read your files and keys, and write anywhere you can: the
project tree included, so that the next `rivet` or `make` runs code it chose), your network,
your processes (it can signal them and read their environment through /proc), and no CPU,
process-count or shared-memory limits. It gets a scrubbed environment, a time budget enforced
from the parent, a memory limit (RLIMIT_DATA: one process's private memory only), orphan
cleanup (the harness is a child subreaper) and the same output validation: the verdicts are
honest, the machine is not protected. Only ever used when asked for by name
(``--sandbox local``); it says so on stderr every time it starts.

Credentials: starting the backend makes the calling process non-dumpable on Linux
(``PR_SET_DUMPABLE`` 0: its ``/proc/<pid>/environ`` and ``mem`` unreadable to processes of the
same user) and the harness drops the capabilities that bypass that flag before exec; but that
guards one process, not the user: the parent that started it, its siblings (``rivet eval
--workers N``'s other workers) and your shells stay readable. So this backend makes no promise
about keys: the command line refuses ``--sandbox local`` while a model credential is in its
environment (`rivet.commands._options`), and docs/sandbox.md says what local mode does and
does not protect.
"""

from __future__ import annotations

import ctypes
import os
import select
import subprocess
import sys
from pathlib import Path

from sandbox._session import Channel, ChannelClosed, HarnessExecutor, minimal_env
from sandbox.errors import SandboxUnavailable

WARNING = (
    "rivet sandbox: WARNING: the local backend isolates NOTHING: the draft runs as you, with "
    "your files (this project's included), network, processes and their environments. Use "
    "the docker backend for generated code."
)


_PR_CAPBSET_DROP = 24
_PR_SET_DUMPABLE = 4
_CAP_SYS_PTRACE = 19
_CAP_SYS_ADMIN = 21
_CAP_PERFMON = 38


def _prctl(option: int, arg: int) -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(option, arg, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def hide_own_environment() -> bool:
    """Make this process non-dumpable (Linux): its /proc environ and mem become unreadable to
    other processes of the same user. True when it took effect."""
    return _prctl(_PR_SET_DUMPABLE, 0)


def _drop_ptrace() -> None:
    """In the harness, before exec: none of the capabilities that read another process's
    environ or memory (fails, harmlessly, without CAP_SETPCAP: an ordinary user has none)."""
    for cap in (_CAP_SYS_PTRACE, _CAP_SYS_ADMIN, _CAP_PERFMON):
        _prctl(_PR_CAPBSET_DROP, cap)


class _PipeChannel(Channel):
    def __init__(self, proc: subprocess.Popen[bytes]) -> None:
        assert proc.stdin is not None and proc.stdout is not None
        self.proc = proc
        self.wfd, self.rfd = proc.stdin.fileno(), proc.stdout.fileno()

    def send(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self.wfd, view) :]

    def recv(self, timeout: float) -> bytes:
        if not select.select([self.rfd], [], [], timeout)[0]:
            raise TimeoutError(f"no data within {timeout:.1f} s")
        data = os.read(self.rfd, 1 << 20)
        if not data:
            raise ChannelClosed("the local harness exited")
        return data

    def close(self) -> None:
        for f in (self.proc.stdin, self.proc.stdout):
            if f is not None:
                f.close()


class LocalExecutor(HarnessExecutor):
    """Runs jobs in forked children of a local harness subprocess (no isolation at all).

    Args:
        preload: import the heavy modules in the harness ("default"), none ("none"), or
            a comma-separated list.
        quiet: do not print the warning (tests only).
    """

    name = "local"

    def __init__(self, *, preload: str = "default", quiet: bool = False, **kw: float) -> None:
        super().__init__(**kw)  # type: ignore[arg-type]
        self.preload = preload
        self.quiet = quiet
        self._proc: subprocess.Popen[bytes] | None = None
        self._log = self.stage_root / "harness.log"
        self._tmp = self.stage_root / "tmp"
        self._tmp.mkdir(mode=0o700)

    def _open(self) -> Channel:
        if not self.quiet:
            print(WARNING, file=sys.stderr)
        hide_own_environment()
        root = str(Path(__file__).resolve().parents[1])  # the folder holding `sandbox/`
        env = minimal_env({"PYTHONPATH": root, "PATH": os.environ.get("PATH", "/usr/bin:/bin")})
        cmd = [sys.executable, "-m", "sandbox.harness.server", "--local", "--tmp", str(self._tmp)]
        try:
            with open(self._log, "ab") as log:
                self._proc = subprocess.Popen(
                    [*cmd, "--preload", self.preload],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    stderr=log,
                    env=env,
                    cwd=self._tmp,
                    start_new_session=True,
                    preexec_fn=_drop_ptrace,
                )
        except OSError as e:
            raise SandboxUnavailable(f"cannot start the local harness: {e}") from None
        return _PipeChannel(self._proc)

    def _harness_path(self, staged: Path) -> str:
        return str(staged)

    def _kill(self) -> None:
        if self._proc is not None:
            self._proc.kill()
            self._proc.wait()
            self._proc = None

    def _death(self) -> tuple[str, str]:
        code = self._proc.wait() if self._proc is not None else None
        return "crashed", f"the local harness died (exit status {code}); restarted"

    def _diagnostics(self) -> str:
        try:
            return "harness log: " + self._log.read_text(errors="replace")[-2000:]
        except OSError:
            return ""
