"""A dry run of the prompts against the checks: every check a draft gets has its rule stated in
the prompt, and every number a rule or the domain section states is its source's.

The checks a suite runs are read from the check code itself (every check name the suite
modules and the interface checks spell, plus the domain properties each domain declares), not
from the rules, so a check added without a rule fails here. Numbers are re-read here from the
constant each placeholder names, with this test's own resolver and unit conversions.
"""

from __future__ import annotations

import ast
import importlib
import math
import re
from pathlib import Path

import numpy as np
import pytest

import domains
from agent.context import build_context, domain_facts
from agent.prompt import build_request, template
from checks import properties
from checks.rules import OPTIONAL, PLACEHOLDER, Stated, render, rules_for
from checks.suites import RULES, interface_rules
from contracts.functions import CODE_DEPS, FUNCTIONS

REPO = Path(__file__).resolve().parents[2]
DOMAINS = ("cubes", "tangram", "assembly")
CHECK_NAME = re.compile(r"^(interface|schema|property|image)\.[a-z_]+$")

# Where a stated number may come from: the constants the checks, the scoring, the executor's
# hand model and the toolbox define (a domain's own values, a property's declared parameters).
SOURCES = (
    "geometry.tolerances:",
    "geometry.hand:",
    "toolbox.robot:",
    "checks.images:",
    "checks.budget:",
    "checks.inputs:",
    "sim.realism:",  # what the observations are like
    "checks.suites.render:",
    "checks.suites.perceive:",
    "checks.suites.plan:",
    "checks.properties.library:",
    "contracts.functions:",
    "domain.",
    "params.",
)
# Digits a rule may spell: names and the contract's own shapes and values, no tolerance.
LITERALS = re.compile(r"2F-85|FR3|\(4, 4\)|\(H, W, 3\)|\bu?int(8|16|32|64)\b|-1\b|`depth` is 0|6D")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:e-?\d+)?")


def _checks_in(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    return {
        n.value
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and CHECK_NAME.match(n.value)
    }


def suite_checks(domain, function: str) -> set[str]:
    """Every check a draft of `function` gets, as the check code names them."""
    names = _checks_in(REPO / "checks" / "context.py")  # the interface checks, every function
    names |= _checks_in(REPO / "checks" / "suites" / f"{function}.py")
    names |= {p.check_name for p in properties.properties_for(domain, function)}
    return names


def prompt_text(domain, function: str) -> str:
    ctx = build_context(domain, (), "(toolbox docs)")
    frozen = {d: f"def {d}(*args):\n    pass\n" for d in CODE_DEPS[function]}
    request = build_request(ctx, function, 1, frozen=frozen)
    return "\n".join(b.text for b in (*request.system, *request.content) if hasattr(b, "text"))


# -- an independent reading of the sources ----------------------------------------------------


def source_value(path: str, domain, params):
    if ":" in path:
        module, _, rest = path.partition(":")
        value = importlib.import_module(module)
        steps = re.findall(r"([A-Za-z_]\w*)|\[([^\]]+)\]", rest)
    else:
        root, _, rest = path.partition(".")
        value = {"domain": domain, "params": dict(params or {})}[root]
        steps = re.findall(r"([A-Za-z_]\w*)|\[([^\]]+)\]", rest)
    for attr, key in steps:
        if attr:
            value = value[attr] if isinstance(value, dict) else getattr(value, attr)
        else:
            value = value[int(key)] if re.fullmatch(r"-?\d+", key) else value[key]
    return value


def shown_values(value, unit: str, domain) -> list[float]:
    """The numbers a value may show as, in its unit."""
    if unit == "vocab":  # the domain's words for its relations may state its gaps [mm]
        return [1000 * g for g in (domain.on_gap, domain.adjacent_gap) if g is not None]
    if value is None or isinstance(value, str | bool):
        return []
    if unit == "region":
        return [*value.x, *value.y, value.reach]
    if isinstance(value, list | tuple):
        return [v for x in value for v in shown_values(x, unit, domain)]
    if isinstance(value, dict):
        return []
    x = float(value)
    return [
        {"mm": x * 1000, "deg": math.degrees(x), "pct": x * 100}.get(unit, x),
    ]


def assert_numbers_match(stated: Stated, template_text: str, domain, params=None) -> None:
    # the template itself spells no number but names and contract literals
    bare = OPTIONAL.sub(lambda m: m.group(3), template_text)
    bare = PLACEHOLDER.sub("", bare)
    bare = LITERALS.sub("", bare)
    assert not re.search(r"\d", bare), (
        f"{stated.check}: the rule spells a number instead of naming its source: {bare!r}"
    )
    rest = stated.text
    for n in stated.numbers:
        assert n.source.startswith(SOURCES), f"{stated.check}: {n.source} is not a known source"
        value = source_value(n.source, domain, params)
        if isinstance(value, np.ndarray | float | int) and not isinstance(value, bool):
            assert float(value) == pytest.approx(float(n.value)), n.source
        else:
            assert value == n.value, n.source
        allowed = shown_values(value, n.unit, domain)
        for token in [] if isinstance(value, str) else NUMBER.findall(n.shown):
            got = float(token)
            decimals = len(token.split(".")[1]) if "." in token and "e" not in token else 0
            assert any(
                abs(got - v) <= 0.5 * 10**-decimals + 1e-9 * abs(v) or math.isclose(got, v)
                for v in allowed
            ), f"{stated.check}: {token} shown for {n.source} = {value!r} ({n.unit})"
        assert n.shown in rest, f"{stated.check}: {n.shown!r} not in the rule"
        rest = rest.replace(n.shown, " ", 1)
    left = LITERALS.sub("", rest)
    assert not re.search(r"\d", left), f"{stated.check}: a number without a source in {left!r}"


# -- the dry run ------------------------------------------------------------------------------


@pytest.fixture(scope="module", params=DOMAINS)
def domain(request):
    return domains.load(request.param)


@pytest.mark.parametrize("function", FUNCTIONS)
def test_every_check_is_stated_in_the_prompt(domain, function):
    expected = suite_checks(domain, function)
    stated = {s.check: s for s in rules_for(domain, function)}
    assert expected <= set(stated), f"checks without a rule: {sorted(expected - set(stated))}"
    assert set(stated) <= expected, f"rules of no check: {sorted(set(stated) - expected)}"
    text = prompt_text(domain, function)
    assert "## What your draft is checked for" in text
    for name in sorted(expected):
        assert f"- `{name}`: {stated[name].text}" in text, f"{name}: rule not in the prompt"


@pytest.mark.parametrize("function", FUNCTIONS)
def test_every_number_in_a_rule_is_its_source(domain, function):
    templates = {r.check: r.text for r in (*interface_rules(function), *RULES[function])}
    props = {p.check_name: p for p in properties.properties_for(domain, function)}
    for s in rules_for(domain, function):
        if s.check in props:
            p = props[s.check]
            assert_numbers_match(s, p.fn.rule, domain, p.params)
        else:
            assert_numbers_match(s, templates[s.check], domain)


def test_the_domain_section_states_its_numbers_from_their_sources(domain):
    text, numbers = render(template("facts.md"), domain=domain)
    stated = Stated(check="facts", text=text, numbers=numbers)
    assert_numbers_match(stated, template("facts.md"), domain)
    facts = domain_facts(domain)
    for kind in domain.REFERENCE_RELATIONS:
        assert f"`{kind}`" in facts  # the scoring's relation vocabulary
    assert "(`toolbox.robot.WORKSPACE`)" in facts and "placement region" in facts
    assert "perceive" in facts and "relate" in facts and "plan" in facts  # the time budgets


def test_the_task_text_copies_no_tolerance(domain):
    tol = domain.tolerance
    text = domain.task
    mm = f"{tol.translation * 1000:g} mm"
    assert not re.search(rf"(?<![\d.]){re.escape(mm)}", text), f"{mm} copied into task.md"
    if tol.rotation is not None:
        deg = f"{math.degrees(tol.rotation):g}°"
        assert not re.search(rf"(?<![\d.]){re.escape(deg)} of its goal", text)
    assert "every scene" in text.lower()  # what perceive reports: all of the scene's objects


def test_perceive_is_told_to_report_hidden_objects(domain):
    text = prompt_text(domain, "perceive")
    assert "rather than inventing" not in text  # the old text contradicted the ids check
    assert "hides entirely" in text or "hidden" in text
    assert "one per catalogue object that is visible" not in text


def test_a_declared_property_without_a_rule_is_refused(monkeypatch):
    from checks.properties import library
    from checks.rules import RuleError

    cubes = domains.load("cubes")
    fn = library.LIBRARY["temporary_places_clear"]
    monkeypatch.setattr(fn, "rule", "")
    with pytest.raises(RuleError, match="temporary_places_clear"):
        rules_for(cubes, "plan")


def test_sizes_are_printed(capsys):
    from agent.prompt import _main

    assert _main(["--sizes", "--domain", "cubes", "--no-images"]) == 0
    out = capsys.readouterr().out
    assert "characters / 3.5" in out
    rows = [line for line in out.splitlines() if line.startswith("| cubes |")]
    assert len(rows) == len(FUNCTIONS)
