"""`rivet sandbox doctor`: the isolation actually in force, every item tested live.

Design rule: nothing is inferred from configuration alone. The probe entry point
(`sandbox.harness.probe`) runs as a real job and tries each escape; then real jobs check that
the limits bite (a sleeper is killed, a memory bomb is stopped, a thread bomb hits the pids
limit, an oversized output is refused, a fake secret set on the host is not visible). The
container's configuration is listed beside them for reference.
"""

from __future__ import annotations

import os
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sandbox.base import Job
from sandbox.docker_backend import DockerExecutor

CANARY_VAR = "RIVET_DOCTOR_CANARY"


@dataclass(frozen=True, kw_only=True)
class Item:
    """One isolation item: what was tried, whether the sandbox held, what was seen."""

    name: str
    ok: bool
    detail: str


def run_doctor(executor: DockerExecutor | None = None) -> list[Item]:
    """Run every live check; starts (and closes) its own Docker executor unless given one."""
    canary = secrets.token_hex(16)
    os.environ[CANARY_VAR] = canary  # set on the host: the probe must not see it
    own = executor is None
    ex = executor or DockerExecutor(memory_mb=2048, pids_limit=128)
    try:
        return _checks(ex, canary)
    finally:
        os.environ.pop(CANARY_VAR, None)
        if own:
            ex.close()


def _checks(ex: DockerExecutor, canary: str) -> list[Item]:
    items = [Item(name="sandbox image present", ok=True, detail=ex.image)]
    host_paths = sorted({str(Path.cwd()), str(ex.stage_root), str(Path(__file__).resolve())})
    probe = ex.run(
        Job(
            source="",
            function="probe",
            entry="sandbox.harness.probe:run",
            inputs={"host_paths": host_paths, "canary": canary},
            timeout_s=60,
        )
    )
    if probe.ok:
        items += [Item(**item) for item in probe.output["items"]]
    else:
        items.append(
            Item(name="isolation probe ran", ok=False, detail=f"{probe.verdict}: {probe.detail}")
        )
    items += [_enforced(ex, name, job, want, check) for name, job, want, check in _LIMIT_JOBS]
    items.append(_next_job_works(ex))
    items += _config(ex)
    return items


def _enforced(ex: DockerExecutor, name: str, job: Job, want: str, check: Any) -> Item:
    report = ex.run(job)
    ok = report.verdict == want and (check is None or check(report))
    out = "" if report.output is None else f" output={str(report.output)[:80]}"
    return Item(
        name=name, ok=ok, detail=f"verdict {report.verdict} (want {want}): {report.detail}{out}"
    )


def _next_job_works(ex: DockerExecutor) -> Item:
    report = ex.run(Job(source="def f(x):\n    return x + 1\n", function="f", inputs={"x": 41}))
    return Item(
        name="the next job still works",
        ok=report.ok and report.output == 42,
        detail=f"{report.verdict} in {report.wall_time_s * 1000:.0f} ms",
    )


_THREAD_BOMB = """
import threading, time
def f():
    threading.stack_size(64 * 1024)
    n = 0
    try:
        while n < 100000:
            threading.Thread(target=time.sleep, args=(60,), daemon=True).start()
            n += 1
    except RuntimeError:
        pass
    return n
"""

_LIMIT_JOBS: list[tuple[str, Job, str, Any]] = [
    (
        "time budget enforced from outside",
        Job(source="import time\ndef f():\n    time.sleep(3600)\n", function="f", timeout_s=1),
        "timeout",
        None,
    ),
    (
        "job memory limit enforced",
        Job(source="def f():\n    return bytearray(4 << 30)\n", function="f", memory_mb=256),
        "oom",
        None,
    ),
    ("pids limit enforced", Job(source=_THREAD_BOMB, function="f"), "ok", lambda r: r.output < 200),
    (
        "output size capped",
        Job(source="def f():\n    return 'x' * (80 << 20)\n", function="f", memory_mb=1024),
        "bad_output",
        None,
    ),
]


def _config(ex: DockerExecutor) -> list[Item]:
    """The container's hardening as the engine reports it (reference, next to the live items)."""
    if ex.container is None:
        return []
    ex.container.reload()
    host = ex.container.attrs["HostConfig"]
    env = ex.container.attrs["Config"].get("Env") or []
    checks = [
        ("config: network none", host.get("NetworkMode") == "none", host.get("NetworkMode")),
        ("config: read-only root", host.get("ReadonlyRootfs") is True, host.get("ReadonlyRootfs")),
        ("config: capabilities dropped", host.get("CapDrop") == ["ALL"], host.get("CapDrop")),
        (
            "config: no-new-privileges",
            "no-new-privileges:true" in (host.get("SecurityOpt") or []),
            host.get("SecurityOpt"),
        ),
        (
            "config: memory = memory+swap",
            host.get("Memory") and host.get("Memory") == host.get("MemorySwap"),
            f"{host.get('Memory')} / {host.get('MemorySwap')}",
        ),
        ("config: CPU limit", bool(host.get("NanoCpus")), host.get("NanoCpus")),
        ("config: pids limit", bool(host.get("PidsLimit")), host.get("PidsLimit")),
        (
            "config: user",
            ex.container.attrs["Config"].get("User") == "10001:10001",
            ex.container.attrs["Config"].get("User"),
        ),
        (
            "config: no host variables",
            not any(e.startswith(CANARY_VAR) for e in env),
            f"{len(env)} image variables",
        ),
    ]
    return [Item(name=n, ok=bool(ok), detail=str(d)) for n, ok, d in checks]


def format_items(items: list[Item]) -> str:
    width = max(len(i.name) for i in items)
    lines = [f"{'PASS' if i.ok else 'FAIL'}  {i.name:<{width}}  {i.detail}" for i in items]
    failed = sum(not i.ok for i in items)
    lines.append(
        f"{len(items) - failed}/{len(items)} items hold" + (f"; {failed} FAIL" if failed else "")
    )
    return "\n".join(lines)
