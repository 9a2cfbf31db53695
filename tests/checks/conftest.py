"""Shared pieces for the checks tests: the reference programs and a local sandbox executor."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PROGRAMS = REPO / "domains" / "cubes" / "programs"
CASES_SEED = 1  # the tests draw their check cases from one seed: the same cases every run
# For tests of what one check finds, not of how many cases it takes: 12 observations, the first
# three the hiding case as in the default budget (whose 45 the rejection arithmetic is about:
# docs/checks.md).
FEW = {"observations": 12, "hidden": 3}

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("MUJOCO_GL", "egl")


def program(name: str) -> str:
    return (PROGRAMS / f"{name}.py").read_text()


def deps_of(function: str) -> dict[str, str]:
    from contracts.functions import CODE_DEPS

    return {d: program(d) for d in CODE_DEPS[function]}


@pytest.fixture(scope="session")
def executor():
    """The local harness (isolates nothing: these drafts are ours)."""
    from sandbox.local_backend import LocalExecutor

    with LocalExecutor(quiet=True) as ex:
        yield ex


@pytest.fixture(scope="session")
def check(executor, tmp_path_factory):
    """check(function, source, deps=None, few=False, only=None) -> report, through the local
    sandbox; `few`: the default budget with `FEW` observations; `only`: these checks alone
    (`rivet check --only`)."""
    from checks import run_checks
    from checks.budget import Budget

    out = tmp_path_factory.mktemp("check-images")

    def run(
        function: str,
        source: str,
        deps: dict | None = None,
        few: bool = False,
        only: list[str] | None = None,
    ) -> dict:
        return run_checks(
            "cubes",
            function,
            source,
            deps=deps_of(function) if deps is None else deps,
            executor=executor,
            out_dir=out,
            cases_seed=CASES_SEED,
            budget=Budget(name="few", **FEW) if few else None,
            only=only,
        )

    return run


def failing(report: dict) -> list[str]:
    """Every check that did not pass (a required check skipped included)."""
    from checks.report import passes

    return [c["name"] for c in report["checks"] if not passes(c)]


def by_name(report: dict, name: str) -> dict:
    return next(c for c in report["checks"] if c["name"] == name)
