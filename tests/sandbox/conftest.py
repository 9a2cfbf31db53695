"""Sandbox fixtures: the image (built once if missing), a warm Docker executor, a host guard.

Tests marked `docker` need the real engine. They FAIL when it is unavailable, because CI runs
them against the real engine; set RIVET_SKIP_DOCKER=1 to skip them instead on a machine
without Docker.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from pathlib import Path

import pytest

from sandbox import Job, SandboxUnavailable
from sandbox.image import LABEL

_ENGINE: list[str] = []  # "" when reachable, else why not; checked once per session


def require_docker() -> None:
    """Fail (or skip with RIVET_SKIP_DOCKER=1) when the Docker engine is unreachable."""
    from sandbox.image import docker_client

    if not _ENGINE:
        try:
            docker_client(timeout=30).close()
            _ENGINE.append("")
        except SandboxUnavailable as e:
            _ENGINE.append(str(e))
    if _ENGINE[0]:
        if os.environ.get("RIVET_SKIP_DOCKER") == "1":
            pytest.skip(f"RIVET_SKIP_DOCKER=1: {_ENGINE[0]}")
        pytest.fail(
            f"the sandbox tests need Docker (set RIVET_SKIP_DOCKER=1 to skip): {_ENGINE[0]}"
        )


def pytest_runtest_setup(item: pytest.Item) -> None:
    if item.get_closest_marker("docker") is not None:
        require_docker()


@pytest.fixture(scope="session")
def sandbox_image() -> str:
    require_docker()
    from sandbox.image import ensure_image

    return ensure_image(quiet=True)


@pytest.fixture(scope="session")
def docker_executor(sandbox_image: str) -> Iterator:
    from sandbox.docker_backend import DockerExecutor

    # 2 GiB for the container keeps the memory bombs small on a shared machine.
    with DockerExecutor(image=sandbox_image, memory_mb=2048) as ex:
        ex.warm()
        yield ex


@pytest.fixture(scope="session")
def local_executor() -> Iterator:
    from sandbox.local_backend import LocalExecutor

    with LocalExecutor(preload="numpy", quiet=True) as ex:
        yield ex


AFTERCHECK = """
import os
def f():
    me = os.getpid()
    pids = sorted(int(p) for p in os.listdir("/proc") if p.isdigit())
    tmp = sorted(set(os.listdir("/tmp")) - {os.path.basename(os.getcwd())})
    spare = (1, me, os.getppid())  # the harness and the template this process was forked from
    return {"others": [p for p in pids if p not in spare], "tmp": tmp,
            "shm": sorted(os.listdir("/dev/shm")), "cwd_empty": not os.listdir(os.getcwd())}
"""


def assert_clean_next_job(executor) -> None:
    """The next job runs, alone in the container, with empty scratch space."""
    report = executor.run(Job(source=AFTERCHECK, function="f", timeout_s=20))
    assert report.verdict == "ok", report
    assert report.output == {"others": [], "tmp": [], "shm": [], "cwd_empty": True}, report.output


class HostGuard:
    """Things on the host a draft must not touch, checked after every hostile job."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.canary = root / "canary.txt"
        self.content = secrets.token_hex(32)
        self.canary.write_text(self.content)
        self.marker = root / "pwned"  # a pickle payload would create it if ever unpickled
        self.repo = Path(__file__).resolve().parents[2]

    @property
    def host_paths(self) -> list[str]:
        return [str(self.root), str(self.canary), str(self.repo), str(self.repo / "sandbox")]

    def assert_intact(self, executor) -> None:
        assert self.canary.read_text() == self.content
        assert sorted(p.name for p in self.root.iterdir()) == ["canary.txt"]
        assert not self.marker.exists()
        ours = {executor.container.id} if executor.container is not None else set()
        client = executor.client
        running = client.containers.list(filters={"label": f"{LABEL}=1"})
        mine = [c for c in running if c.labels.get(f"{LABEL}.owner") == _owner()]
        assert {c.id for c in mine} <= ours, "a draft left a sandbox container behind"


def _owner() -> str:
    from sandbox.docker_backend import _owner as owner

    return owner()


@pytest.fixture(scope="session")
def host_guard(tmp_path_factory: pytest.TempPathFactory) -> HostGuard:
    return HostGuard(tmp_path_factory.mktemp("host-guard"))
