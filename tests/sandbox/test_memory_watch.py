"""A job's memory limit counts shared memory and every process of the session (PID 1's
`MemoryWatch`), and the cgroup's high-water marks do not carry from one job to the next
(issue 35). Real engine; the container has 2 GiB, so each job here stays under what the
container could hold and only the job's own limit can stop it."""

from __future__ import annotations

import pytest

from sandbox import Job, Program

pytestmark = pytest.mark.docker

HOLD = """
import mmap, os, time
def f(route, mb):
    chunk = b"\\1" * (1 << 20)
    if route == "shared map":
        m = mmap.mmap(-1, mb << 20, flags=mmap.MAP_SHARED)
        for i in range(0, mb << 20, 4096):
            m[i] = 1
    elif route == "memfd":
        fd = os.memfd_create("hold")
        for _ in range(mb):
            os.write(fd, chunk)
    elif route == "tmp file":
        with open("/tmp/hold", "wb") as fh:
            for _ in range(mb):
                fh.write(chunk)
    elif route == "forked processes":  # each under its own RLIMIT_DATA, together over
        for _ in range(4):
            if os.fork() == 0:
                try:
                    block = bytearray(mb << 18)  # a quarter each
                    time.sleep(60)
                finally:
                    os._exit(0)
        time.sleep(3)
    return "held"
"""


@pytest.mark.parametrize("route", ["shared map", "memfd", "forked processes"])
def test_memory_beyond_the_limit_ends_the_job(docker_executor, route):
    ex = docker_executor
    restarts = ex.restarts
    got = ex.run(
        Job(
            source=HOLD,
            function="f",
            inputs={"route": route, "mb": 800},
            memory_mb=256,
            timeout_s=60,
        )
    )
    assert got.verdict == "oom", got
    assert "over its limit" in got.detail, got
    after = ex.run(Job(source="def f():\n    return 1\n", function="f"))
    assert after.ok and ex.restarts == restarts


def test_tmp_files_count_too(docker_executor):
    """/tmp is a 256 MiB tmpfs: 250 MiB of files there are memory the job holds, over its
    16 MiB plus the template's anonymous memory (its allowance for copy-on-write copies)."""
    got = docker_executor.run(
        Job(
            source=HOLD,
            function="f",
            inputs={"route": "tmp file", "mb": 250},
            memory_mb=16,
            timeout_s=60,
        )
    )
    assert got.verdict == "oom" and "over its limit" in got.detail, got


@pytest.mark.parametrize("route", ["shared map", "memfd"])
def test_shared_memory_within_the_limit_is_fine(docker_executor, route):
    got = docker_executor.run(
        Job(
            source=HOLD,
            function="f",
            inputs={"route": route, "mb": 128},
            memory_mb=512,
            timeout_s=60,
        )
    )
    assert got.ok and got.output == "held", got


BACKGROUND = """
import os, time
def start(mb):
    if os.fork() == 0:  # holds shared memory after its call has answered
        fd = os.memfd_create("later")
        chunk = b"\\1" * (1 << 20)
        for _ in range(mb):
            os.write(fd, chunk)
        time.sleep(60)
        os._exit(0)
    return "started"
def later():
    return "answered"
"""


def test_memory_held_between_calls_is_seen_at_the_next_call(docker_executor):
    with docker_executor.open_session(Program(modules={"bg": BACKGROUND}), memory_mb=256) as s:
        first = s.call("bg", "start", 768, timeout_s=10)
        assert first.ok, first
        import time

        time.sleep(3)  # the background process fills its memfd meanwhile
        second = s.call("bg", "later", timeout_s=10)
        assert second.verdict == "oom" and "over its limit" in second.detail, second
        third = s.call("bg", "later", timeout_s=10)
        assert third.verdict == "closed", third


HIGH_WATER = """
import glob
def f():
    out = {}
    for path in glob.glob("/sys/fs/cgroup/memory/memory*max_usage_in_bytes") + glob.glob(
        "/sys/fs/cgroup/memory/memory*failcnt"
    ) + glob.glob("/sys/fs/cgroup/memory.peak") + glob.glob("/sys/fs/cgroup/pids*.peak"):
        try:
            out[path] = open(path).read().strip()
        except OSError as e:
            out[path] = "unreadable: " + e.strerror
    usage = "/sys/fs/cgroup/memory/memory.stat"
    out["stat readable"] = bool(open(usage).read()) if glob.glob(usage) else None
    return out
"""


def test_the_high_water_mark_is_not_readable(docker_executor):
    big = docker_executor.run(
        Job(source="def f():\n    return len(bytearray(512 << 20))\n", function="f")
    )
    assert big.ok, big
    seen = docker_executor.run(Job(source=HIGH_WATER, function="f"))
    assert seen.ok, seen
    marks = {k: v for k, v in seen.output.items() if k != "stat readable"}
    assert marks, seen.output  # the files exist (masked), or this says nothing
    assert all(v == "" or v.startswith("unreadable") for v in marks.values()), marks
