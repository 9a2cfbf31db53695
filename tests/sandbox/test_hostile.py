"""The hostile-draft suite: every catalogue entry, its verdict, the host intact, the next job clean.

The catalogue (`hostile_drafts.toml`) is the data; this module only runs it.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sandbox import VERDICTS, Job
from tests.sandbox.conftest import HostGuard, assert_clean_next_job

CATALOGUE: list[dict[str, Any]] = tomllib.loads(
    (Path(__file__).parent / "hostile_drafts.toml").read_text()
)["draft"]
FAKE_KEY = "sk-ant-api03-FAKE-rivet-sandbox-test-key-do-not-use"


def test_catalogue_is_complete():
    names = [d["name"] for d in CATALOGUE]
    assert len(names) >= 25 and len(set(names)) == len(names)
    for draft in CATALOGUE:
        assert draft["expect"] in VERDICTS, draft["name"]
        assert draft["threat"] and "def f" in draft["source"], draft["name"]
    assert {d["expect"] for d in CATALOGUE} == set(VERDICTS), "every verdict is exercised"


def _inputs(draft: dict[str, Any], guard: HostGuard) -> dict[str, Any]:
    values = {
        "host_paths": guard.host_paths,
        "canary_name": "ANTHROPIC_API_KEY",
        "host_marker": str(guard.marker),
        "array": np.arange(12.0),  # a call's arrays travel in a staged file
    }
    return {arg: values[what] for arg, what in draft.get("inputs", {}).items()}


def _check(draft: dict[str, Any], report) -> None:
    assert report.verdict == draft["expect"], f"{draft['name']}: {report}"
    if "output" in draft:
        assert report.output == draft["output"], report
    if "exception" in draft:
        assert report.exception is not None and report.exception.type == draft["exception"], report
    if "detail" in draft:
        assert draft["detail"] in report.detail, report
    if "stdout_min_bytes" in draft:
        assert report.stdout_bytes >= draft["stdout_min_bytes"], report
        assert 0 < len(report.stdout_tail) <= 8192
    if FAKE_KEY in repr(report):
        pytest.fail("the fake API key leaked into the report")


@pytest.mark.docker
@pytest.mark.parametrize("draft", CATALOGUE, ids=[d["name"] for d in CATALOGUE])
def test_hostile_draft(draft, docker_executor, host_guard, sandbox_image, monkeypatch):
    job = Job(
        source=draft["source"],
        function="f",
        inputs=_inputs(draft, host_guard),
        timeout_s=draft.get("timeout_s", 10),
        memory_mb=draft.get("memory_mb", 1024),
    )
    if "canary_name" in draft.get("inputs", {}).values():
        # A fresh executor started while the host has a (fake) secret in its environment.
        from sandbox.docker_backend import DockerExecutor

        monkeypatch.setenv("ANTHROPIC_API_KEY", FAKE_KEY)
        with DockerExecutor(image=sandbox_image, preload="none", memory_mb=2048) as fresh:
            _check(draft, fresh.run(job))
            assert_clean_next_job(fresh)
        return
    restarts = docker_executor.restarts
    _check(draft, docker_executor.run(job))
    host_guard.assert_intact(docker_executor)
    assert_clean_next_job(docker_executor)
    assert docker_executor.restarts == restarts, "the harness had to be restarted"
