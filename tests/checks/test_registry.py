"""Checks as a registry (`checks.registry`): each check one function with its rule, a suite the
list of them in order, and every check with a test of its own."""

from __future__ import annotations

import functools
import re
from pathlib import Path

import pytest

from checks import registry
from checks.report import CheckResult
from checks.suites import RULES, SUITES
from checks.suites._common import selecting
from contracts.functions import FUNCTIONS

REPO = Path(__file__).resolve().parents[2]
TOY = "toy_function"


@pytest.fixture
def toy():
    """A suite of three checks for a made-up function, removed again afterwards."""
    ran: list[str] = []

    @registry.register(TOY, "schema.output", rule="returns a dict")
    def schema(ctx, r: CheckResult) -> None:
        ran.append("schema.output")
        r.examples = 1
        if ctx["schema_fails"]:
            from checks.hypo import Failure

            raise Failure(message="not a dict")

    @registry.register(TOY, "property.keeps_running", rule="runs whatever the schema")
    def keeps_running(ctx, r: CheckResult) -> None:
        ran.append("property.keeps_running")

    @registry.register(TOY, "property.needs_it", rule="needs the schema", needs_schema=True)
    def needs_it(ctx, r: CheckResult) -> None:
        ran.append("property.needs_it")

    @registry.register(TOY, "image.on_host", rule="judged after the session", on="host")
    def on_host(ctx) -> CheckResult:  # pragma: no cover - never called by run_suite
        raise AssertionError

    yield ran
    del registry.SUITE[TOY]


def test_a_suite_runs_its_checks_in_order_and_states_their_rules(toy):
    results = registry.run_suite(TOY, {"schema_fails": False})
    assert [r.name for r in results] == [
        "schema.output",
        "property.keeps_running",
        "property.needs_it",
    ]
    assert toy == [r.name for r in results]
    assert all(r.status == "passed" for r in results)
    assert [r.category for r in results] == ["schema", "property", "property"]
    assert [r.check for r in registry.rules(TOY)] == [
        "schema.output", "property.keeps_running", "property.needs_it", "image.on_host",
    ]  # fmt: skip


def test_a_failed_schema_skips_what_needs_it_only(toy):
    results = {r.name: r for r in registry.run_suite(TOY, {"schema_fails": True})}
    assert results["schema.output"].status == "failed"
    assert results["property.keeps_running"].status == "passed"
    assert results["property.needs_it"].status == "skipped"
    assert "property.needs_it" not in toy


def test_one_check_runs_alone(toy):
    with selecting(["property.needs_it"]):
        results = {r.name: r for r in registry.run_suite(TOY, {"schema_fails": False})}
    assert toy == ["schema.output", "property.needs_it"]  # the schema check always runs
    assert results["property.keeps_running"].status == "skipped"


def test_a_name_is_registered_once_and_an_unknown_suite_is_named(toy):
    with pytest.raises(ValueError, match="registered already"):
        registry.register(TOY, "schema.output", rule="again")(lambda ctx, r: None)
    with pytest.raises(KeyError, match="no check suite for 'nothing'; suites: "):
        registry.suite("nothing")
    host = next(c for c in registry.suite(TOY) if c.on == "host")
    with pytest.raises(TypeError, match="judged on the host"):
        host.run({})


def test_every_function_has_its_suite_from_the_registry():
    assert list(SUITES) == list(FUNCTIONS)
    for function in FUNCTIONS:
        checks = registry.suite(function)
        assert [r.check for r in RULES[function]] == [c.name for c in checks]
        assert checks[0].name == "schema.output"
        assert all(c.rule.strip() for c in checks)
        assert len({c.name for c in checks}) == len(checks)


@functools.cache
def _tests_text() -> str:
    """Every other test file's text, read once for all the checks."""
    mine = Path(__file__).resolve()
    return "\n".join(
        p.read_text() for p in (REPO / "tests").rglob("test_*.py") if p.resolve() != mine
    )


@pytest.mark.parametrize(
    "check",
    [c for f in FUNCTIONS for c in registry.suite(f)],
    ids=lambda c: f"{c.function}:{c.name}",
)
def test_every_check_has_a_test_of_its_own(check):
    """Some other test names the check. A proxy only: it does not see whether that test makes
    the check fail on a draft with its bug (the tests in `test_suites.py` do, for the checks
    nothing else named)."""
    text = _tests_text()
    assert re.search(re.escape(f'"{check.name}"'), text), f"no test names {check.name}"
