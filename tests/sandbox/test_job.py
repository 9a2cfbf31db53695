"""Jobs are validated up front; reports are plain data; backends are chosen by name only."""

from __future__ import annotations

import json

import numpy as np
import pytest

import sandbox
from sandbox import BadJob, ExceptionInfo, Job, Report, open_executor


def test_public_names_resolve():
    for name in sandbox.__all__:
        assert hasattr(sandbox, name), name


@pytest.mark.parametrize(
    ("kwargs", "problem"),
    [
        ({"function": "not a name"}, "not a Python identifier"),
        ({"function": "class"}, "not a Python identifier"),
        ({"module_name": "json"}, "would shadow"),
        ({"modules": {"numpy": "x = 1"}}, "would shadow"),
        ({"modules": {"contracts": "x = 1"}}, "would shadow"),
        ({"modules": {"draft": "x = 1"}}, "both the draft"),
        ({"modules": {"helper": 3}}, "source strings"),
        ({"inputs": {1: 2}}, "argument names"),
        ({"timeout_s": 0}, "timeout_s"),
        ({"memory_mb": 1}, "memory_mb"),
        ({"source": b"def f(): pass"}, "must be a str"),
    ],
)
def test_bad_jobs_are_refused_with_a_reason(kwargs, problem):
    args = {"source": "def f():\n    pass\n", "function": "f", **kwargs}
    with pytest.raises(BadJob, match=problem):
        Job(**args)


def test_bad_job_is_a_usage_error():
    from contracts.errors import UsageError

    assert issubclass(BadJob, UsageError)


def test_job_sources_put_the_draft_first():
    job = Job(source="a = 1", function="f", modules={"helper": "b = 2"}, module_name="render")
    assert list(job.sources) == ["render", "helper"]


def test_report_to_dict_is_json():
    report = Report(
        verdict="exception",
        output={"a": np.arange(3), "b": [np.float32(1.5)]},
        exception=ExceptionInfo(type="ValueError", message="m", traceback="t"),
        backend="local",
    )
    data = json.loads(json.dumps(report.to_dict()))
    assert data["output"] == {"a": [0, 1, 2], "b": [1.5]}
    assert data["exception"]["type"] == "ValueError" and data["verdict"] == "exception"
    assert not report.ok


def test_unknown_backend_lists_the_known_ones():
    with pytest.raises(BadJob, match="known: docker, local"):
        open_executor("firecracker")


def test_docker_unavailable_fails_loudly_and_never_falls_back(monkeypatch):
    monkeypatch.setenv("DOCKER_HOST", "unix:///nonexistent/docker.sock")
    with pytest.raises(sandbox.SandboxUnavailable, match="make system") as err:
        open_executor("docker")
    assert "never chosen for you" in str(err.value)
