"""The isolation probe: a program that tests, from inside the sandbox, what a draft can reach.

`rivet sandbox doctor` sends this file's source as an ordinary draft (it runs exactly where and
as a draft would) and calls `run`. Every item is tried for real (connect, write, open,
syscall), not read from configuration, and reports whether the sandbox held. Inputs:
``host_paths`` (paths that exist on the host and must not exist here), ``canary`` (a value the
host put in its own environment that must not appear here) and ``env_keep`` (the variables
the harness passes on).

Standard library only: it must import wherever a draft does.
"""

from __future__ import annotations

import ctypes
import errno
import os
import socket
from collections.abc import Callable
from typing import Any

_SECRETISH = ("KEY", "TOKEN", "SECRET", "PASSWORD", "CREDENTIAL", "AUTH")


def run(host_paths: list[str], canary: str, env_keep: list[str]) -> dict[str, Any]:
    """Every probe item as ``{"name", "ok", "detail"}``, in a fixed order."""
    inputs = {"host_paths": host_paths, "canary": canary, "env_keep": env_keep}
    items = []
    for name, probe in _PROBES:
        try:
            ok, detail = probe(inputs)
        except Exception as e:
            ok, detail = False, f"probe failed: {type(e).__name__}: {e}"
        items.append({"name": name, "ok": bool(ok), "detail": str(detail)[:300]})
    return {"items": items}


def _connect(host: str) -> None:
    socket.create_connection((host, 53), timeout=1).close()


def _open(path: str, mode: str) -> None:
    open(path, mode).close()


def _fails(fn: Callable[..., Any], *args: Any) -> tuple[bool, str]:
    try:
        fn(*args)
    except OSError as e:
        return True, f"{type(e).__name__}: {e.strerror or e}"
    return False, "succeeded"


def _network(_: dict[str, Any]) -> tuple[bool, str]:
    results = []
    for host in ("1.1.1.1", "8.8.8.8", "172.17.0.1"):
        ok, why = _fails(_connect, host)
        results.append((ok, f"{host}:53 {why}"))
    ifaces = sorted(os.listdir("/sys/class/net"))
    only_lo = ifaces == ["lo"]
    return all(ok for ok, _ in results) and only_lo, f"interfaces {ifaces}; " + "; ".join(
        w for _, w in results
    )


def _dns(_: dict[str, Any]) -> tuple[bool, str]:
    return _fails(socket.getaddrinfo, "deb.debian.org", 80)


def _root_fs(_: dict[str, Any]) -> tuple[bool, str]:
    out = []
    for path in ("/etc/rivet-probe", "/opt/rivet/lib/probe.py", "/usr/local/probe"):
        ok, why = _fails(_open, path, "w")
        out.append((ok, f"{path}: {why}"))
    return all(ok for ok, _ in out), "; ".join(w for _, w in out)


def _tmpfs(_: dict[str, Any]) -> tuple[bool, str]:
    mounts: dict[str, tuple[str, str]] = {}
    with open("/proc/mounts") as f:
        for line in f:
            fields = line.split()
            mounts[fields[1]] = (fields[2], fields[3])
    kind, opts = mounts.get("/tmp", ("?", ""))
    st = os.statvfs("/tmp")
    size_mb = st.f_blocks * st.f_frsize / (1 << 20)
    ok = kind == "tmpfs" and "noexec" in opts.split(",") and size_mb <= 4096
    return ok, f"/tmp is {kind} ({opts}), {size_mb:.0f} MiB"


def _inputs_ro(_: dict[str, Any]) -> tuple[bool, str]:
    return _fails(_open, "/in/probe", "w")


def _user(_: dict[str, Any]) -> tuple[bool, str]:
    ids = (os.getuid(), os.geteuid(), os.getgid(), os.getegid())
    return 0 not in ids, f"uid/euid/gid/egid = {ids}"


def _status() -> dict[str, str]:
    with open("/proc/self/status") as f:
        return dict(line.rstrip("\n").split(":\t", 1) for line in f if ":\t" in line)


def _caps(_: dict[str, Any]) -> tuple[bool, str]:
    st = _status()
    caps = {k: st.get(k, "?") for k in ("CapInh", "CapPrm", "CapEff", "CapBnd", "CapAmb")}
    return all(v.strip("0") == "" for v in caps.values()), str(caps)


def _no_new_privs(_: dict[str, Any]) -> tuple[bool, str]:
    st = _status()
    return st.get(
        "NoNewPrivs"
    ) == "1", f"NoNewPrivs={st.get('NoNewPrivs')} Seccomp={st.get('Seccomp')}"


def _seccomp(_: dict[str, Any]) -> tuple[bool, str]:
    mode = _status().get("Seccomp")
    return mode == "2", f"Seccomp mode {mode} (2 = filter)"


def _cgroup(*names: str) -> str | None:
    for name in names:
        try:
            with open(f"/sys/fs/cgroup/{name}") as f:
                return f.read().strip()
        except OSError:
            continue
    return None


def _pids(_: dict[str, Any]) -> tuple[bool, str]:
    value = _cgroup("pids.max", "pids/pids.max")
    return value is not None and value.isdigit(), f"pids.max = {value}"


def _memory(_: dict[str, Any]) -> tuple[bool, str]:
    limit = _cgroup("memory.max", "memory/memory.limit_in_bytes")
    swap = _cgroup("memory.swap.max")
    memsw = _cgroup("memory/memory.memsw.limit_in_bytes")
    ok = limit is not None and limit.isdigit() and int(limit) < 1 << 50
    if swap is not None:
        ok = ok and swap == "0"
    elif memsw is not None:
        ok = ok and memsw == limit
    return ok, f"memory limit {limit}, swap.max {swap}, memsw {memsw}"


def _cpu(_: dict[str, Any]) -> tuple[bool, str]:
    v2 = _cgroup("cpu.max")
    if v2 is not None:
        return not v2.startswith("max"), f"cpu.max = {v2}"
    quota = _cgroup("cpu/cpu.cfs_quota_us", "cpu,cpuacct/cpu.cfs_quota_us")
    period = _cgroup("cpu/cpu.cfs_period_us", "cpu,cpuacct/cpu.cfs_period_us")
    ok = quota is not None and quota.lstrip("-").isdigit() and int(quota) > 0
    return ok, f"cfs quota {quota} / period {period} us"


def _env(inputs: dict[str, Any]) -> tuple[bool, str]:
    canary = str(inputs.get("canary", ""))
    extra = sorted(set(os.environ) - set(inputs.get("env_keep", [])) - {"HOME", "TMPDIR"})
    secretish = sorted(k for k in os.environ if any(s in k.upper() for s in _SECRETISH))
    try:  # a session's process is non-dumpable in the container: its environ is root's
        with open("/proc/self/environ", "rb") as f:
            initial = f.read()
    except PermissionError:
        initial = b""
    leaked = bool(canary) and (canary in str(dict(os.environ)) or canary.encode() in initial)
    ok = not extra and not secretish and not leaked
    return (
        ok,
        f"variables {sorted(os.environ)}; unexpected {extra}; secret-like {secretish}; canary seen: {leaked}",
    )


def _docker_socket(_: dict[str, Any]) -> tuple[bool, str]:
    paths = ["/var/run/docker.sock", "/run/docker.sock", "/run/containerd/containerd.sock"]
    present = [p for p in paths if os.path.exists(p)]
    with open("/proc/net/unix") as f:
        named = [line.split()[-1] for line in f.readlines()[1:] if len(line.split()) >= 8]
    dockerish = [n for n in named if "docker" in n or "containerd" in n]
    return not present and not dockerish, f"present {present}; docker-like unix sockets {dockerish}"


def _host_files(inputs: dict[str, Any]) -> tuple[bool, str]:
    seen = [p for p in inputs.get("host_paths", []) if os.path.exists(p)]
    home = [p for p in ("/root", "/home") if os.path.isdir(p) and _listable(p)]
    return not seen and not home, f"host paths visible: {seen}; home dirs listable: {home}"


def _listable(path: str) -> bool:
    try:
        return bool(os.listdir(path))
    except OSError:
        return False


def _harness_memory(_: dict[str, Any]) -> tuple[bool, str]:
    out = []
    for path in ("/proc/1/environ", "/proc/1/mem", "/proc/1/fd/0", "/proc/1/fd/1"):
        ok, why = _fails(_open, path, "rb")
        out.append((ok, f"{path}: {why}"))
    return all(ok for ok, _ in out), "; ".join(w for _, w in out)


def _syscall(name: str, *args: Any) -> tuple[int, int]:
    libc = ctypes.CDLL(None, use_errno=True)
    fn = getattr(libc, name)
    rc = fn(*args)
    return rc, ctypes.get_errno()


def _ptrace(_: dict[str, Any]) -> tuple[bool, str]:
    rc, err = _syscall("ptrace", ctypes.c_long(16), ctypes.c_long(1), None, None)  # ATTACH to 1
    if rc == 0:
        _syscall("ptrace", ctypes.c_long(17), ctypes.c_long(1), None, None)  # DETACH
    return rc != 0, f"ptrace(PTRACE_ATTACH, 1) -> {rc} ({errno.errorcode.get(err, err)})"


def _mount(_: dict[str, Any]) -> tuple[bool, str]:
    rc, err = _syscall("mount", b"none", b"/tmp", b"tmpfs", ctypes.c_ulong(0), None)
    return rc != 0, f"mount(tmpfs, /tmp) -> {rc} ({errno.errorcode.get(err, err)})"


def _signal_harness(_: dict[str, Any]) -> tuple[bool, str]:
    import signal

    if not _in_container():  # never signal PID 1 outside the container (the local backend)
        return False, "not inside the sandbox container (PID 1 is not the harness); skipped"
    os.kill(1, signal.SIGKILL)  # a no-op for PID 1 of the namespace, which has no handler
    os.kill(1, signal.SIGTERM)
    alive = os.path.exists("/proc/1/stat")
    return alive, f"harness (PID 1) alive after SIGKILL and SIGTERM from the job: {alive}"


def _in_container() -> bool:
    try:
        with open("/proc/1/cmdline", "rb") as f:
            return b"sandbox.harness.server" in f.read()
    except OSError:
        return False


def _exec(_: dict[str, Any]) -> tuple[bool, str]:
    import subprocess

    return _fails(subprocess.run, ["/bin/true"])


def _template_unreachable(_: dict[str, Any]) -> tuple[bool, str]:
    """Signal 0 (a permission test that delivers nothing) to the template and to everyone,
    reading the template's limits, and asking for I/O signals to be sent to it."""
    import fcntl
    import resource

    if not _in_container():
        return False, "not inside the sandbox container; skipped"
    template = os.getppid()
    out = []
    for what, fn in (
        ("kill(template, 0)", lambda: os.kill(template, 0)),
        ("kill(-1, 0)", lambda: os.kill(-1, 0)),
        ("prlimit(template)", lambda: resource.prlimit(template, resource.RLIMIT_NOFILE)),
        ("prlimit(1)", lambda: resource.prlimit(1, resource.RLIMIT_NOFILE)),
    ):
        ok, why = _fails(fn)
        out.append((ok, f"{what}: {why}"))
    r, w = os.pipe()
    try:
        ok, why = _fails(fcntl.fcntl, r, fcntl.F_SETOWN, template)
        out.append((ok, f"F_SETOWN(template): {why}"))
    finally:
        os.close(r)
        os.close(w)
    return all(ok for ok, _ in out), "; ".join(w for _, w in out)


def _oom_locked(_: dict[str, Any]) -> tuple[bool, str]:
    if not _in_container():
        return False, "not inside the sandbox container; skipped"
    try:
        with open("/proc/self/oom_score_adj", "w") as f:
            f.write("0")
    except OSError as e:
        return True, f"writing 0 to its oom_score_adj: {type(e).__name__}: {e.strerror}"
    with open("/proc/self/oom_score_adj", "w") as f:
        f.write("1000")
    return False, "the job lowered its OOM preference to 0"


def _denied(rc: int, err: int) -> bool:
    return rc < 0 and err in (errno.EPERM, errno.ENOSYS, errno.EACCES)


def _io_uring(_: dict[str, Any]) -> tuple[bool, str]:
    params = ctypes.create_string_buffer(120)  # struct io_uring_params
    libc = ctypes.CDLL(None, use_errno=True)
    rc = libc.syscall(425, 4, params)  # io_uring_setup(4, &params), x86_64 and aarch64
    err = ctypes.get_errno()
    if rc >= 0:
        os.close(rc)
    return _denied(rc, err), f"io_uring_setup -> {rc} ({errno.errorcode.get(err, err)})"


def _socket_families(_: dict[str, Any]) -> tuple[bool, str]:
    out, ok = [], True
    for name, family, kind in (
        ("AF_VSOCK", 40, socket.SOCK_STREAM),
        ("AF_PACKET", 17, socket.SOCK_RAW),
        ("AF_NETLINK", 16, socket.SOCK_RAW),
        ("AF_ALG", 38, socket.SOCK_SEQPACKET),
        ("AF_BLUETOOTH", 31, socket.SOCK_STREAM),
        ("AF_KEY", 15, socket.SOCK_RAW),
    ):
        try:
            socket.socket(family, kind).close()
            ok = False
            out.append(f"{name} opened")
        except OSError as e:
            ok = ok and e.errno in (errno.EPERM, errno.EACCES)
            out.append(f"{name}: {errno.errorcode.get(e.errno or 0, str(e.errno))}")
    return ok, "; ".join(out)


def _sysv_ipc(_: dict[str, Any]) -> tuple[bool, str]:
    libc = ctypes.CDLL(None, use_errno=True)
    out, ok = [], True
    for name, args in (
        ("shmget", (0, 1 << 20, 0o1600)),  # IPC_PRIVATE, 1 MiB, IPC_CREAT | 0600
        ("msgget", (0, 0o1600)),
        ("semget", (0, 1, 0o1600)),
    ):
        rc = getattr(libc, name)(*args)
        err = ctypes.get_errno()
        ok = ok and _denied(rc, err)
        out.append(f"{name} -> {rc} ({errno.errorcode.get(err, err)})")
    rc = libc.mq_open(b"/rivet-probe", os.O_CREAT | os.O_RDWR, 0o600, None)
    err = ctypes.get_errno()
    ok = ok and _denied(rc, err)
    out.append(f"mq_open -> {rc} ({errno.errorcode.get(err, err)})")
    return ok, "; ".join(out)


def _namespaces(_: dict[str, Any]) -> tuple[bool, str]:
    libc = ctypes.CDLL(None, use_errno=True)
    out, ok = [], True
    for name, flag in (("CLONE_NEWUSER", 0x10000000), ("CLONE_NEWNS", 0x00020000),
                       ("CLONE_NEWNET", 0x40000000)):  # fmt: skip
        rc = libc.unshare(flag)
        err = ctypes.get_errno()
        ok = ok and _denied(rc, err)
        out.append(f"unshare({name}) -> {rc} ({errno.errorcode.get(err, err)})")
    return ok, "; ".join(out)


def _ipc_namespace(_: dict[str, Any]) -> tuple[bool, str]:
    return True, os.readlink("/proc/self/ns/ipc")  # the doctor compares it with the host's


def _oom_preference(_: dict[str, Any]) -> tuple[bool, str]:
    def read(pid: str) -> int:
        with open(f"/proc/{pid}/oom_score_adj") as f:
            return int(f.read())

    own, harness, template = read("self"), read("1"), read(str(os.getppid()))
    return (
        own > harness and own > template,
        f"this process {own}, the harness (PID 1) {harness}, the template {template}",
    )


_PROBES: list[tuple[str, Callable[[dict[str, Any]], tuple[bool, str]]]] = [
    ("network unreachable", _network),
    ("DNS unavailable", _dns),
    ("root file system read-only", _root_fs),
    ("/tmp is a capped noexec tmpfs", _tmpfs),
    ("inputs mounted read-only", _inputs_ro),
    ("user is not root", _user),
    ("capabilities empty", _caps),
    ("no-new-privileges", _no_new_privs),
    ("seccomp filter active", _seccomp),
    ("pids limit", _pids),
    ("memory limit, no swap", _memory),
    ("CPU limit", _cpu),
    ("environment clean", _env),
    ("docker socket absent", _docker_socket),
    ("host files absent", _host_files),
    ("harness memory and channel unreachable", _harness_memory),
    ("ptrace denied", _ptrace),
    ("mount denied", _mount),
    ("harness survives signals", _signal_harness),
    ("io_uring denied", _io_uring),
    ("socket families beyond unix/inet denied (vsock, packet, netlink, alg, …)", _socket_families),
    ("System V IPC and POSIX message queues denied", _sysv_ipc),
    ("new namespaces denied", _namespaces),
    ("IPC namespace", _ipc_namespace),
    ("the OOM killer prefers the program to the harness", _oom_preference),
    ("the program cannot lower its OOM preference", _oom_locked),
    ("programs cannot be executed", _exec),
    ("the template and PID 1 out of reach (signals, limits, I/O owners)", _template_unreachable),
]
