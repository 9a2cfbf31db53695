"""A session process's own seccomp filter, stacked on the container's profile.

Design rule: what a program does can never reach the harness. The container's profile
(`sandbox.seccomp`) is the same for every process in the container, the harness included; this
filter is installed by each session's process on itself, after its setup and before the
program's first line runs, and every process or thread the program starts inherits it (filters
cannot be removed). It refuses (EPERM):

- ``execve``/``execveat``: a new program image would be dumpable again (and could then lower its
  OOM preference, see below); drafts are Python functions and never start programs;
- ``prctl(PR_SET_DUMPABLE, ≠ 0)``: the session's process makes itself non-dumpable once it has
  set its ``oom_score_adj`` to 1000, so that /proc/<pid>/oom_score_adj belongs to root and the
  program cannot lower it: every process of a session is then the OOM killer's first choice,
  ahead of the harness (PID 1) and the template, whatever memory it holds;
- every way to signal, renice, reschedule or limit the template (the process sessions are
  forked from, which PID 1 cannot protect as it protects itself) or PID 1: ``kill`` of the
  template, its group or everyone (-1), ``tkill``/``tgkill``/``rt_sigqueueinfo``/
  ``rt_tgsigqueueinfo`` of the template, ``pidfd_send_signal``, ``fcntl(F_SETOWN[_EX])`` and the
  ``ioctl`` equivalents (signals on I/O readiness sent to another process),
  ``prlimit64``/``setpriority``/``sched_set*``/``ioprio_set`` aimed at either (or at every
  process of the user).

Only the machine's native architecture (x86_64 or aarch64) is allowed; any other entry point is
refused here as it is by the container's profile.

Without exec, `ctypes.util.find_library` (which runs ldconfig, gcc or ld to answer) finds
nothing; `find_library` here answers the same question by reading the linker's configuration
and listing its directories, and the session's process uses it in place of the standard one
(PyOpenGL loads libGL and libEGL that way when a program imports it first).
"""

from __future__ import annotations

import ctypes
import glob
import os
import platform
import sysconfig

_PR_SET_DUMPABLE = 4
_PR_SET_NO_NEW_PRIVS = 38
_PR_SET_SECCOMP = 22
_SECCOMP_MODE_FILTER = 2
_F_SETOWN, _F_SETOWN_EX = 8, 15
_FIOSETOWN, _SIOCSPGRP, _TIOCSPGRP = 0x8901, 0x8902, 0x5410
_PRIO_USER, _IOPRIO_WHO_USER = 2, 3
_X32_BIT = 0x40000000
EPERM = 1

_LD_ABS = 0x20  # BPF_LD | BPF_W | BPF_ABS
_JEQ = 0x15  # BPF_JMP | BPF_JEQ | BPF_K
_JGE = 0x35  # BPF_JMP | BPF_JGE | BPF_K
_RET = 0x06  # BPF_RET | BPF_K
_ALLOW = 0x7FFF0000  # SECCOMP_RET_ALLOW
_DENY = 0x00050000 | EPERM  # SECCOMP_RET_ERRNO | EPERM

ARCHES: dict[str, tuple[int, dict[str, int]]] = {
    "x86_64": (0xC000003E, {
        "execve": 59, "execveat": 322, "pidfd_send_signal": 424, "prctl": 157, "fcntl": 72,
        "ioctl": 16, "kill": 62, "tkill": 200, "tgkill": 234, "rt_sigqueueinfo": 129,
        "rt_tgsigqueueinfo": 297, "prlimit64": 302, "setpriority": 141,
        "sched_setscheduler": 144, "sched_setparam": 142, "sched_setattr": 314,
        "sched_setaffinity": 203, "ioprio_set": 251,
    }),
    "aarch64": (0xC00000B7, {
        "execve": 221, "execveat": 281, "pidfd_send_signal": 424, "prctl": 167, "fcntl": 25,
        "ioctl": 29, "kill": 129, "tkill": 130, "tgkill": 131, "rt_sigqueueinfo": 138,
        "rt_tgsigqueueinfo": 240, "prlimit64": 261, "setpriority": 140,
        "sched_setscheduler": 119, "sched_setparam": 118, "sched_setattr": 274,
        "sched_setaffinity": 122, "ioprio_set": 30,
    }),
}  # fmt: skip
DENIED = ("execve", "execveat", "pidfd_send_signal")


def rules(template: int) -> list[tuple[str, int, tuple[int, ...]]]:
    """(syscall, argument index, values refused in that argument): the low 32 bits compared,
    which is what the kernel reads of an int argument (a pid, an option, a command)."""
    me = template & 0xFFFFFFFF
    group = (-template) & 0xFFFFFFFF  # the template leads its own process group
    everyone = 0xFFFFFFFF  # -1
    protected = (me, 1)
    return [
        ("kill", 0, (everyone, me, group)),
        ("tkill", 0, (me,)),
        ("tgkill", 0, (me,)),
        ("rt_sigqueueinfo", 0, (me,)),
        ("rt_tgsigqueueinfo", 0, (me,)),
        ("fcntl", 1, (_F_SETOWN, _F_SETOWN_EX)),
        ("ioctl", 1, (_FIOSETOWN, _SIOCSPGRP, _TIOCSPGRP)),
        ("prlimit64", 0, protected),
        ("setpriority", 0, (_PRIO_USER,)),
        ("setpriority", 1, protected),
        ("sched_setscheduler", 0, protected),
        ("sched_setparam", 0, protected),
        ("sched_setattr", 0, protected),
        ("sched_setaffinity", 0, protected),
        ("ioprio_set", 0, (_IOPRIO_WHO_USER,)),
        ("ioprio_set", 1, protected),
    ]


def program(template: int, machine: str | None = None) -> list[tuple[int, int, int, int]]:
    """The filter as BPF instructions (code, jt, jf, k)."""
    name = (machine or platform.machine()).lower()
    name = {"amd64": "x86_64", "arm64": "aarch64"}.get(name, name)
    if name not in ARCHES:
        raise OSError(f"no session filter for the architecture {name!r}")
    arch, nr = ARCHES[name]
    ops: list[list] = []  # [code, jt, jf, k]; jt/jf are labels ("allow", "deny", "next", ...)
    labels: dict[str, int] = {}

    def emit(code: int, k: int = 0, jt: str | int = 0, jf: str | int = 0) -> None:
        ops.append([code, jt, jf, k])

    def arg(index: int) -> int:
        return 16 + 8 * index  # seccomp_data.args[index], its low half (little-endian)

    emit(_LD_ABS, 4)  # arch
    emit(_JEQ, arch, 0, "deny")
    emit(_LD_ABS, 0)  # syscall number
    if name == "x86_64":
        emit(_JGE, _X32_BIT, "deny", 0)
    for call in DENIED:
        emit(_JEQ, nr[call], "deny", 0)
    emit(_JEQ, nr["prctl"], "prctl", 0)
    grouped: dict[str, list[tuple[int, tuple[int, ...]]]] = {}
    for call, index, values in rules(template):
        grouped.setdefault(call, []).append((index, values))
    for call in grouped:
        emit(_JEQ, nr[call], call, 0)
    emit(_RET, _ALLOW)
    labels["prctl"] = len(ops)  # prctl(PR_SET_DUMPABLE, x): refused unless x == 0
    emit(_LD_ABS, arg(0))
    emit(_JEQ, _PR_SET_DUMPABLE, 0, "allow")
    emit(_LD_ABS, arg(1))
    emit(_JEQ, 0, "allow", "deny")
    for call, checks in grouped.items():
        labels[call] = len(ops)
        for index, values in checks:
            emit(_LD_ABS, arg(index))
            for v in values:
                emit(_JEQ, v, "deny", 0)
        emit(_RET, _ALLOW)
    labels["allow"] = len(ops)
    emit(_RET, _ALLOW)
    labels["deny"] = len(ops)
    emit(_RET, _DENY)
    out = []
    for i, (code, jt, jf, k) in enumerate(ops):
        jumps = []
        for target in (jt, jf):
            if isinstance(target, str):
                target = labels[target] - (i + 1)
                if not 0 <= target <= 255:
                    raise ValueError("session filter jump out of range")
            jumps.append(target)
        out.append((code, jumps[0], jumps[1], k))
    return out


class _SockFilter(ctypes.Structure):
    _fields_ = [
        ("code", ctypes.c_ushort),
        ("jt", ctypes.c_ubyte),
        ("jf", ctypes.c_ubyte),
        ("k", ctypes.c_uint),
    ]


class _SockFprog(ctypes.Structure):
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.POINTER(_SockFilter))]


def install(template: int) -> None:
    """Install the filter on the calling thread (and everything it starts from now on);
    raises OSError when the kernel refuses it."""
    ops = program(template)
    array = (_SockFilter * len(ops))(*[_SockFilter(*op) for op in ops])
    fprog = _SockFprog(len(ops), array)
    libc = ctypes.CDLL(None, use_errno=True)
    prctl = libc.prctl
    prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_void_p, ctypes.c_ulong, ctypes.c_ulong]
    if prctl(_PR_SET_NO_NEW_PRIVS, 1, None, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_NO_NEW_PRIVS) failed")
    if prctl(_PR_SET_SECCOMP, _SECCOMP_MODE_FILTER, ctypes.addressof(fprog), 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_SECCOMP) failed")


def make_undumpable() -> None:
    """Make the calling process non-dumpable: its /proc files become root's."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(_PR_SET_DUMPABLE, 0, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_DUMPABLE, 0) failed")


def find_library(name: str) -> str | None:
    """What `ctypes.util.find_library` answers on Linux (a library's file name, e.g.
    ``libGL.so.1``), found by listing the linker's directories instead of running ldconfig."""
    if not name or "/" in name:
        return None
    best: tuple[tuple[int, int], str] | None = None
    for folder in _library_dirs():
        for path in glob.glob(os.path.join(glob.escape(folder), f"lib{glob.escape(name)}.so*")):
            base = os.path.basename(path)
            suffix = base[len(f"lib{name}.so") :]
            if suffix and not suffix.startswith("."):
                continue
            # prefer a versioned soname (libGL.so.1) over the development link (libGL.so)
            rank = (0 if suffix.count(".") == 1 else 1 if suffix else 2, len(base))
            if best is None or rank < best[0]:
                best = (rank, base)
    return None if best is None else best[1]


def _library_dirs() -> list[str]:
    dirs: list[str] = []

    def read(path: str, depth: int) -> None:
        try:
            with open(path) as f:
                lines = f.read().splitlines()
        except OSError:
            return
        for line in lines:
            line = line.split("#", 1)[0].strip()
            if line.startswith("include ") and depth < 4:
                for inc in sorted(glob.glob(line.split(None, 1)[1].strip())):
                    read(inc, depth + 1)
            elif line:
                dirs.append(line)

    read("/etc/ld.so.conf", 0)
    arch = sysconfig.get_config_var("MULTIARCH") or ""
    for base in ("/usr/local/lib", "/lib", "/usr/lib", "/lib64", "/usr/lib64"):
        if arch:
            dirs.append(os.path.join(base, arch))
        dirs.append(base)
    return list(dict.fromkeys(d for d in dirs if os.path.isdir(d)))
