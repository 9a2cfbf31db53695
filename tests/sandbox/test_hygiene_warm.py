"""Two sessions in one warm container share nothing (issue 16, part 5), against the real engine.

Each test has one job leave something behind — IPC objects, scratch files the wipe finds hard
to remove, processes and threads, memory, its own data in memory — and checks what the next
job of the same container sees, and that the harness (PID 1) did not have to be restarted.
"""

from __future__ import annotations

import secrets

import pytest

from sandbox import Job, Program
from sandbox.docker_backend import DockerExecutor
from sandbox.doctor import MEMORY_MARK, MEMORY_SCAN
from tests.sandbox.conftest import assert_clean_next_job

pytestmark = pytest.mark.docker

IPC_SEEN = """
import os
def f():
    out = {}
    for kind in ("shm", "msg", "sem"):
        with open(f"/proc/sysvipc/{kind}") as fh:
            out[kind] = len(fh.read().splitlines()) - 1
    out["mqueue"] = sorted(os.listdir("/dev/mqueue"))
    out["dev_shm"] = sorted(os.listdir("/dev/shm"))
    return out
"""
NO_IPC = {"shm": 0, "msg": 0, "sem": 0, "mqueue": [], "dev_shm": []}

# Creates one object of each kind of IPC (1 GiB of System V shared memory, touched and
# detached, so that it outlives the process), and a POSIX shared-memory file; says what the
# kernel let it do.
LEAVE_IPC = """
import ctypes, errno, mmap, os
def f(shm_bytes):
    libc = ctypes.CDLL(None, use_errno=True)
    libc.shmat.restype = ctypes.c_void_p
    out = {}
    shm = libc.shmget(0, ctypes.c_size_t(shm_bytes), 0o1600)  # IPC_PRIVATE, IPC_CREAT | 0600
    out["shmget"] = shm if shm < 0 else "created"
    if shm >= 0:
        addr = libc.shmat(shm, None, 0)
        ctypes.memset(addr, 1, shm_bytes)  # make it resident: charged to the container
        libc.shmdt(ctypes.c_void_p(addr))
    out["msgget"] = "created" if libc.msgget(0, 0o1600) >= 0 else errno.errorcode[ctypes.get_errno()]
    out["semget"] = "created" if libc.semget(0, 4, 0o1600) >= 0 else errno.errorcode[ctypes.get_errno()]
    mq = libc.mq_open(b"/rivet-left", os.O_CREAT | os.O_RDWR, 0o600, None)
    out["mq_open"] = "created" if mq >= 0 else errno.errorcode[ctypes.get_errno()]
    with open("/dev/shm/left", "wb") as fh:
        fh.write(b"x" * (8 << 20))
    return out
"""

# Allocates and touches `n` bytes: fails (oom) if what an earlier job left still holds memory.
ALLOCATE = """
def f(n):
    block = bytearray(n)
    for i in range(0, n, 4096):
        block[i] = 1
    return len(block)
"""


def test_ipc_is_refused_and_nothing_of_it_reaches_the_next_job(docker_executor):
    report = docker_executor.run(
        Job(source=LEAVE_IPC, function="f", inputs={"shm_bytes": 1 << 30}, timeout_s=60)
    )
    assert report.verdict == "ok", report
    assert report.output == {
        "shmget": -1,
        "msgget": "EPERM",
        "semget": "EPERM",
        "mq_open": "EPERM",
    }, report.output
    seen = docker_executor.run(Job(source=IPC_SEEN, function="f"))
    assert seen.output == NO_IPC, seen


class _DefaultSeccomp(DockerExecutor):
    """The same container with Docker's default seccomp profile instead of the project's,
    which lets System V IPC and POSIX queues through: what the post-session cleanup (not
    the profile) must make safe."""

    def container_options(self):
        options = super().container_options()
        options["security_opt"] = [o for o in options["security_opt"] if "seccomp" not in o]
        return options


@pytest.fixture(scope="module")
def permissive_executor(sandbox_image):
    with _DefaultSeccomp(image=sandbox_image, memory_mb=2048, preload="none") as ex:
        yield ex


def test_ipc_left_behind_is_removed_and_its_memory_freed(permissive_executor):
    ex = permissive_executor
    # 900 MiB of shared memory: within the job's default 1 GiB, which counts it
    left = ex.run(
        Job(source=LEAVE_IPC, function="f", inputs={"shm_bytes": 900 << 20}, timeout_s=60)
    )
    assert left.output == dict.fromkeys(("shmget", "msgget", "semget", "mq_open"), "created"), left
    restarts = ex.restarts
    seen = ex.run(Job(source=IPC_SEEN, function="f"))
    assert seen.output == NO_IPC, seen
    # A 2 GiB container, a small harness (nothing preloaded): with the 900 MiB segment still
    # there, this runs out of memory.
    big = ex.run(Job(source=ALLOCATE, function="f", inputs={"n": 1000 << 20}, timeout_s=60))
    assert big.verdict == "ok" and big.output == 1000 << 20, big
    assert ex.restarts == restarts


MESSY_FILES = """
import os
def f():
    made = []
    # 1,100 levels (Python's recursive rmtree dies at ~1,000) ...
    here = os.open("/tmp", os.O_RDONLY)
    for _ in range(1100):
        os.mkdir("d", dir_fd=here)
        nxt = os.open("d", os.O_RDONLY, dir_fd=here)
        os.close(here)
        here = nxt
    with open(os.open("leaf", os.O_CREAT | os.O_WRONLY, 0o600, dir_fd=here), "w") as fh:
        fh.write("deep")
    os.close(here)
    made.append("d")
    # ... a path longer than PATH_MAX (4096 bytes), in /dev/shm too ...
    for root in ("/tmp", "/dev/shm"):
        here = os.open(root, os.O_RDONLY)
        name = "L" * 200
        for _ in range(30):
            os.mkdir(name, dir_fd=here)
            nxt = os.open(name, os.O_RDONLY, dir_fd=here)
            os.close(here)
            here = nxt
        os.close(here)
    made.append("L" * 200)
    # ... locked trees: directories and files of mode 000 and 500, a file in each
    for top, mode in (("locked000", 0), ("locked500", 0o500)):
        os.makedirs(f"/tmp/{top}/inner")
        for d in (f"/tmp/{top}/inner", f"/tmp/{top}"):
            with open(f"{d}/file", "w") as fh:
                fh.write("x")
            os.chmod(f"{d}/file", 0)
        os.chmod(f"/tmp/{top}/inner", mode)
        os.chmod(f"/tmp/{top}", mode)
        made.append(top)
    # ... a fifo, a socket, a symlink out, hard links, a file held open by nothing
    os.mkfifo("/tmp/fifo")
    import socket
    s = socket.socket(socket.AF_UNIX)
    s.bind("/tmp/sock")
    os.symlink("/etc/passwd", "/tmp/link")
    with open("/tmp/target", "w") as fh:
        fh.write("y")
    for k in range(100):
        os.link("/tmp/target", f"/tmp/hard{k}")
    # ... and files in its own scratch directory
    with open("scratch.bin", "wb") as fh:
        fh.write(os.urandom(1 << 20))
    return sorted(os.listdir("/tmp"))
"""


def test_undeletable_scratch_trees_are_gone_for_the_next_job(docker_executor):
    restarts = docker_executor.restarts
    report = docker_executor.run(Job(source=MESSY_FILES, function="f", timeout_s=60))
    assert report.verdict == "ok", report
    assert {"d", "locked000", "locked500", "fifo", "sock", "link"} <= set(report.output)
    assert_clean_next_job(docker_executor)  # nothing in /tmp, /dev/shm or its own scratch dir
    assert docker_executor.restarts == restarts, "the wipe failed or killed the harness"


MESSY_PROCESSES = """
import os, signal, threading, time
def spin():
    while True:
        pass
def f():
    for _ in range(3):
        threading.Thread(target=spin).start()  # non-daemon threads, still running
    kinds = []
    for kind in ("daemon", "stopped", "ignores_signals", "group"):
        pid = os.fork()
        if pid == 0:
            if kind == "daemon":
                os.setsid()
                if os.fork():
                    os._exit(0)
            elif kind == "stopped":
                os.kill(os.getpid(), signal.SIGSTOP)
            elif kind == "ignores_signals":
                for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
                    signal.signal(sig, signal.SIG_IGN)
            elif kind == "group":
                os.setpgid(0, 0)
                for _ in range(3):
                    if os.fork() == 0:
                        break
            while True:
                time.sleep(0.01)
        kinds.append(kind)
    time.sleep(0.2)
    return kinds
"""


def test_leftover_processes_and_threads_are_gone_for_the_next_job(docker_executor):
    restarts = docker_executor.restarts
    report = docker_executor.run(Job(source=MESSY_PROCESSES, function="f", timeout_s=30))
    assert report.verdict == "ok" and len(report.output) == 4, report
    assert_clean_next_job(docker_executor)
    assert docker_executor.restarts == restarts


# Tries to lower its OOM preference, then fills the container's memory through a memfd (pages
# no process's resident size shows, which the memory limit of the job does not count), from a
# helper process and from itself.
OOM_ESCAPE = """
import os
def fill():
    fd = os.memfd_create("hold")
    chunk = b"\\1" * (16 << 20)
    while True:
        os.write(fd, chunk)
def f():
    for path, value in (("/proc/self/oom_score_adj", "0"), ("/proc/self/oom_adj", "0"),
                        ("/proc/1/oom_score_adj", "1000"),
                        (f"/proc/{os.getppid()}/oom_score_adj", "1000")):
        try:  # refused: the session's process is non-dumpable, its /proc files are root's
            with open(path, "w") as fh:
                fh.write(value)
        except OSError:
            pass
    if os.fork() == 0:
        fill()
    fill()
"""


def test_a_job_that_lowers_its_oom_preference_cannot_get_pid1_killed(docker_executor):
    restarts = docker_executor.restarts
    report = docker_executor.run(Job(source=OOM_ESCAPE, function="f", timeout_s=120))
    assert report.verdict == "oom", report
    assert docker_executor.restarts == restarts, "the OOM killer took the harness"
    assert docker_executor.status()["sessions"] > 0  # the same harness, still answering
    assert_clean_next_job(docker_executor)


HOLD = """
import sys
import numpy as np
def echo(x):
    print(x)
    sys.stderr.write(x)
    return {"again": x, "blob": np.frombuffer(x.encode() * 1000, np.uint8)}
def fail(x):
    raise ValueError(x)
def keep(x):
    return x
"""


def test_a_session_starts_with_nothing_of_an_earlier_one_in_its_memory(docker_executor):
    """A session gets a marker as an argument, returns it, prints it and raises it; the next
    session searches all of its heap, stack and anonymous memory and must not find it."""
    import numpy as np

    marker = secrets.token_hex(16)
    text = MEMORY_MARK + marker
    with docker_executor.open_session(Program(modules={"hold": HOLD})) as session:
        assert session.call("hold", "echo", text, timeout_s=10).ok
        assert session.call("hold", "fail", text, timeout_s=10).verdict == "exception"
        array = np.frombuffer((text * 64).encode(), np.uint8)
        assert session.call("hold", "keep", {"text": text, "array": array}, timeout_s=10).ok
    scan = docker_executor.run(Job(source=MEMORY_SCAN, function="scan", timeout_s=60))
    assert scan.verdict == "ok", scan
    assert scan.output["bytes"] > 50 << 20, scan.output  # it did search its memory
    assert marker not in scan.output["found"], "an earlier session's data was in memory"


def test_the_session_process_is_locked_down(docker_executor):
    """What keeps the harness out of a program's reach: no exec, no becoming dumpable again,
    no signal to the template or to everyone."""
    source = """
import ctypes, os, signal
def f():
    out = {}
    libc = ctypes.CDLL(None, use_errno=True)
    out["dumpable"] = libc.prctl(3, 0, 0, 0, 0)  # PR_GET_DUMPABLE
    out["set_dumpable"] = libc.prctl(4, 1, 0, 0, 0)  # PR_SET_DUMPABLE, 1
    out["adj"] = open("/proc/self/oom_score_adj").read().strip()
    for name, fn in (("exec", lambda: os.execv("/bin/true", ["true"])),
                     ("kill_template", lambda: os.kill(os.getppid(), signal.SIGKILL)),
                     ("kill_all", lambda: os.kill(-1, signal.SIGKILL)),
                     ("kill_group", lambda: os.killpg(os.getppid(), signal.SIGKILL))):
        try:
            fn()
            out[name] = "allowed"
        except OSError as e:
            out[name] = e.errno
    if os.fork() == 0:  # what it starts is locked down the same way
        os._exit(0 if libc.prctl(4, 1, 0, 0, 0) == -1 else 1)
    out["child"] = os.waitstatus_to_exitcode(os.wait()[1])
    return out
"""
    report = docker_executor.run(Job(source=source, function="f"))
    assert report.output == {
        "dumpable": 0,
        "set_dumpable": -1,
        "adj": "1000",
        "exec": 1,
        "kill_template": 1,
        "kill_all": 1,
        "kill_group": 1,
        "child": 0,
    }, report


PLANT = """
import os, sys
from sandbox.harness.server import DEFAULT_PRELOAD
NAMES = sorted({m.split(".")[0] for m in DEFAULT_PRELOAD} | {"colorsys", "csv", "sitecustomize"})
def f():
    for name in NAMES:  # where an import would find them if the scratch root were on the path
        for folder in ("/tmp", os.getcwd()):
            with open(os.path.join(folder, f"{name}.py"), "w") as fh:
                fh.write("import os\\nos.environ['RIVET_PLANTED'] = 'yes'\\n")
    return sorted(p for p in sys.path if p.startswith("/tmp"))
"""
PLANTED = """
import os, sys
def f():
    import colorsys, csv
    return {"env": os.environ.get("RIVET_PLANTED"), "path": [p for p in sys.path if p.startswith("/tmp")],
            "from_tmp": sorted(m for m, mod in list(sys.modules.items())
                               if str(getattr(mod, "__file__", "") or "").startswith("/tmp"))}
"""


def test_modules_planted_in_scratch_space_are_never_imported(sandbox_image):
    """A job plants modules named like everything the template has yet to import (and some
    of the standard library) in /tmp and its own scratch directory; the template imports the
    rest of its preload list after that session, and no later session sees a planted one."""
    with DockerExecutor(image=sandbox_image, memory_mb=2048) as ex:  # cold: little preloaded
        planted = ex.run(Job(source=PLANT, function="f", timeout_s=60))
        assert planted.verdict == "ok" and planted.output == [], planted
        ex.warm()
        seen = ex.run(Job(source=PLANTED, function="f", timeout_s=60))
        assert seen.output == {"env": None, "path": [], "from_tmp": []}, seen
