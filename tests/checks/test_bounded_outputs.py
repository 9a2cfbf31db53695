"""Host work on a draft's answers is bounded (issue 35, item 4), through the real checks.

Three hostile drafts (`drafts/perceive_stacked.py`, `relate_duplicates.py`, `plan_long.py`)
return schema-shaped answers far over what the domain can hold: 4,000 records stacked in one
place, one edge 200,000 times, a plan of 40,000 steps. Each must end as a `bad_output` call
(an errored schema check naming the count and the limit) within a deadline, with the judge's
process growing by less than 1 GiB, and with no traceback: the answers are refused on their
counts before any geometry, and after the first such answer the draft's later calls are not
made. The drafts run in the local sandbox backend (ours; the same harness) and under Docker;
the checks get a small case budget, since the answers are refused on their first call anyway.
"""

from __future__ import annotations

import dataclasses
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from checks import DEFAULT, Budget, run_checks
from contracts import validate
from rivet.cli import main

from .conftest import by_name, deps_of

DRAFTS = Path(__file__).parent / "drafts"
DEADLINE_S = 120.0  # [s] one draft's checks, on a busy 2-core runner (they take 5-20 s)
MEMORY_MB = 1024.0  # [MiB] the judge's process may grow by less than this


def few_cases(budget: Budget) -> Budget:
    """`budget` with the fewest cases of each kind it counts (the drafts fail on every case)."""
    fewest = {"instances": 2, "composed": 0, "observations": 2, "hidden": 0, "infeasible": 1}
    counts = {k: v for k, v in fewest.items() if isinstance(getattr(budget, k, None), int)}
    return dataclasses.replace(budget, name="few", **counts)


def _status() -> dict[str, float]:
    text = Path("/proc/self/status").read_text()
    return {k: int(re.search(rf"{k}:\s+(\d+)", text).group(1)) / 1024 for k in ("VmHWM", "VmRSS")}


def peak_growth(run: Callable[[], Any]) -> tuple[Any, float, float]:
    """(what `run()` returned, its wall time [s], how far this process's peak RSS rose above
    its RSS at the start [MiB])."""
    try:
        Path("/proc/self/clear_refs").write_text("5")  # the peak RSS starts again from now
    except OSError as e:
        pytest.skip(f"cannot reset this process's peak RSS here ({e})")
    before = _status()["VmRSS"]
    t0 = time.perf_counter()
    value = run()
    return value, time.perf_counter() - t0, _status()["VmHWM"] - before


CASES = {
    "perceive": ("perceive_stacked.py", "4000 records, but the domain's catalogue holds 6 objects"),
    "relate": ("relate_duplicates.py", "200000 edges, over the 480 that 16 edge types could give"),
    "plan": ("plan_long.py", "40000 plan steps, over the plan contract's cap of 1000"),
}


@pytest.fixture(scope="module")
def docker_executor():
    from sandbox.docker_backend import DockerExecutor
    from sandbox.image import ensure_image
    from tests.sandbox.conftest import require_docker

    require_docker()
    with DockerExecutor(image=ensure_image(quiet=True)) as ex:
        ex.warm()
        yield ex


@pytest.mark.parametrize(
    ("function", "backend"),
    [
        *((f, "local") for f in sorted(CASES)),
        *(pytest.param(f, "docker", marks=pytest.mark.docker) for f in sorted(CASES)),
    ],
)
def test_an_answer_over_its_counts_is_refused_in_time_and_memory(request, function, backend):
    executor = request.getfixturevalue("executor" if backend == "local" else "docker_executor")
    draft, limit = CASES[function]
    report, seconds, grew = peak_growth(
        lambda: run_checks(
            "cubes",
            function,
            (DRAFTS / draft).read_text(),
            deps=deps_of(function),
            executor=executor,
            budget=few_cases(DEFAULT),
        )
    )
    validate("check_report", report)
    assert not report["passed"]
    assert seconds < DEADLINE_S, f"{function}: {seconds:.0f} s"
    assert grew < MEMORY_MB, f"{function}: the judge grew by {grew:.0f} MiB"
    schema = by_name(report, "schema.output")
    assert schema["status"] == "error"
    assert f"returned a value that cannot be used ({limit}" in schema["message"]
    for check in report["checks"]:  # refused answers, not checks broken by them
        assert not check.get("traceback"), (check["name"], check["traceback"])
        assert "could not evaluate" not in check.get("message", ""), check


def test_after_an_answer_over_its_counts_later_calls_are_not_made(executor):
    report = run_checks(
        "cubes",
        "plan",
        (DRAFTS / "plan_long.py").read_text(),
        deps=deps_of("plan"),
        executor=executor,
        budget=few_cases(DEFAULT),
    )
    identity = by_name(report, "property.identity_plan_empty")
    assert (
        "was not run: an earlier call returned more than the contract allows"
        in (identity["message"])
    )
    assert "40000 plan steps" in identity["message"]


@pytest.mark.slow
def test_rivet_check_reports_the_flood_without_a_traceback(capsys, tmp_path):
    code, grew = None, 0.0

    def check() -> int:
        return main(
            [
                "check",
                "cubes",
                "relate",
                str(DRAFTS / "relate_duplicates.py"),
                "--sandbox",
                "local",
                "--out",
                str(tmp_path),
            ]
        )

    code, seconds, grew = peak_growth(check)
    captured = capsys.readouterr()
    assert code == 1
    assert seconds < DEADLINE_S and grew < MEMORY_MB, (seconds, grew)
    assert "Traceback" not in captured.out + captured.err
    assert "200000 edges" in captured.out
