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
from checks.rulebook import rules_for
from checks.rules import OPTIONAL, PLACEHOLDER, Stated, render
from checks.suites import RULES, interface_rules
from contracts.functions import CODE_DEPS, CONTRACT_DEPS, FUNCTIONS, authoring_order

REPO = Path(__file__).resolve().parents[2]
DOMAINS = domains.names()
CHECK_NAME = re.compile(r"^(interface|schema|property|image)\.[a-z_]+$")

# Where a stated number may come from: the constants the checks, the scoring, the executor's
# hand model and the toolbox define (a domain's own values, a property's declared parameters).
SOURCES = (
    "geometry.tolerances:",
    "geometry.robot:",
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
    from agent.prompt_sizes import _main

    assert _main(["--sizes", "--domain", "cubes", "--no-images"]) == 0
    out = capsys.readouterr().out
    assert "characters / 3.5" in out
    rows = [line for line in out.splitlines() if line.startswith("| cubes |")]
    assert len(rows) == len(FUNCTIONS)


# -- one statement per fact (issue 34, item 4) ------------------------------------------------
#
# Each test below stands for a contradiction model runs found in the prompts: it holds the
# text to one statement and, where it can, that statement to the code it describes.


def flat(text: str) -> str:
    """`text` with every run of whitespace one space (templates wrap their lines)."""
    return " ".join(text.split())


@pytest.fixture(scope="module")
def toolbox_text() -> str:
    from toolbox.docs import toolbox_docs

    return toolbox_docs()


def test_perceive_is_told_which_camera_and_resolution_it_gets(domain):
    text = prompt_text(domain, "perceive")
    task = flat(text[text.index("# Your task now: `perceive`") : text.index("Signature:")])
    for said in (
        "in the checks exactly as in the trials",
        "full resolution",
        "calibrated camera",
        "envelope around the domain's named cameras",
        "assume no fixed view, height, image size or image region",
        "half the observation's resolution",
    ):
        assert said in task, said
    assert "through the true camera" not in text
    assert "the checks do not hold it against a draft" not in text


def test_hidden_objects_have_one_rule(domain):
    facts = domain_facts(domain)
    assert "only when that object holds up another one" not in facts  # the old contradiction
    rule = facts[facts.index("**What `perceive` reports.**") :].split("\n\n")[0]
    held, free = rule.split("If it holds nothing up")
    assert "If it holds up another object" in held and "scored like any other" in held
    assert "where the camera cannot see it" in free and "its pose is not scored" in free
    # the checks say the same: accuracy leaves such an object's pose out, the re-render must
    # not show it
    stated = {s.check: s.text for s in rules_for(domain, "perceive")}
    assert "holds nothing up only has to be reported" in stated["property.accuracy"]
    assert "where the camera cannot see it" in stated["image.perceive_rerender"]
    # a task text that lets an object hide entirely says where one holding nothing up goes
    if "not show at all" in domain.task:
        assert "holds nothing up" in domain.task and "cannot see it" in domain.task


def test_relate_and_plan_are_told_which_states_the_checks_feed(domain):
    facts = domain_facts(domain)
    states = facts[facts.index("**True and perceived states.**") :].split("\n\n")[0]
    assert "exact records of generated scenes" in states
    assert "`toolbox.stability.PERCEIVED_OVERLAP`" in states
    assert "`toolbox.stability.PERCEIVED_GAP`" in states
    assert "(`TOUCHING`)" in states and "(`RESTING_GAP`)" in states
    for function in ("relate", "plan"):
        task = prompt_text(domain, function)
        task = flat(task[task.index(f"# Your task now: `{function}`") :])
        assert "exact records of generated scenes" in task, function
    # the plan rule judges with the step tolerances the facts name, not the perceived slack
    rule = rules_for(domain, "plan")
    reaches = next(s for s in rule if s.check == "property.reaches_goal")
    sources = {n.source for n in reaches.numbers}
    assert "geometry.tolerances:TOLERANCES.penetration" in sources
    assert "geometry.tolerances:TOLERANCES.contact" in sources
    assert not {s for s in sources if "perceived" in s}


@pytest.mark.parametrize(("name", "function"), [("cubes", "relate"), ("tangram", "plan")])
def test_the_states_relate_and_plan_are_checked_on_are_exact(name, function):
    """What the facts say: the checks of `relate` and `plan` give them exact scenes (every
    object resting on something to within a micrometre, nothing overlapping), not perceived
    ones (which are off by millimetres)."""
    import inspect

    from checks.budget import DEFAULT
    from checks.inputs import build_cases
    from geometry import collisions, supports

    dom = domains.load(name)
    drawn = {"seed": 5} if "seed" in inspect.signature(build_cases).parameters else {}
    cases = build_cases(dom, function, DEFAULT, **drawn)
    if function == "relate":
        states = [c["records"] for c in cases["scenes"]]
    else:
        states = [c[side] for c in cases["instances"] for side in ("start", "goal")]
    assert states
    for recs in states:
        assert all(supports(recs, dom.shapes, contact_tol=1e-6).values())
        assert collisions(recs, dom.shapes, tolerance=1e-6) == []


def test_every_section_a_prompt_points_to_is_there(domain):
    """'X below' / 'X in the domain section' names a section the prompt has (the relate
    prompt once promised `perceive`'s output contract below and showed none)."""
    for function in FUNCTIONS:
        text = prompt_text(domain, function)
        for m in re.finditer(r'"([^"\n]+)" (below|in the domain section)', text):
            title, where = m.groups()
            heads = [f"**{title}.**", f"## {title}\n"]
            at = [text.find(h) for h in heads if h in text]
            assert at, f"{function}: {title!r} is pointed to but no section has that title"
            if where == "below":
                assert max(at) > m.start(), f"{function}: {title!r} is not below"
    for function, deps in CONTRACT_DEPS.items():
        text = prompt_text(domain, function)
        for dep in deps:
            section = text[text.index(f"## Contract of `{dep}`") :].split("\n## ")[0]
            for key in ('"id"', '"mesh"', '"pose"', "T_world_object"):
                assert key in section, f"{function}: the contract of {dep} lacks {key}"


def test_the_plan_length_rule_defines_the_reference_order(domain):
    stated = {s.check: s.text for s in rules_for(domain, "plan")}
    text = stated["property.plan_length_bounded"]
    assert "reference construction order" in text
    assert "the order the generator found for the instance" in text


def test_the_online_pass_and_the_budgets_do_not_contradict(domain):
    from checks.budget import ONLINE_BUDGET, ONLINE_PASS_S

    facts = domain_facts(domain)
    time = facts[facts.index("**Time.**") :]
    assert "a gate (`interface.fast_enough`)" in time
    one_pass = 2 * ONLINE_BUDGET["perceive"] + 2 * ONLINE_BUDGET["relate"] + ONLINE_BUDGET["plan"]
    if one_pass > ONLINE_PASS_S:  # the budgets allow a slower pass: the pass is no check
        assert "That is a target, not a check" in time


def test_the_answer_format_the_prompt_allows_is_what_extraction_takes(domain):
    from agent.extract import DraftFormatError, extract_draft

    text = prompt_text(domain, "render")
    assert "fences in other languages (a diagram in a\n  ```text block): they are not read" in text
    assert "A second ```python block fails the answer" in text
    module = "```python\ndef render(records, meshes, camera):\n    return {}\n```\n"
    diagram = "The layout:\n```\nrecords -> [render] -> mask\n```\n"
    drawing = "```text\n+---+\n| a |\n+---+\n```\n"
    source = "def render(records, meshes, camera):\n    return {}\n"
    assert extract_draft(diagram + module, "render") == source
    assert extract_draft(drawing + module + diagram, "render") == source
    assert extract_draft("```\n" + source + "```\n", "render") == source  # no python fence
    with pytest.raises(DraftFormatError, match="holds 2 code blocks"):
        extract_draft(module + module, "render")
    with pytest.raises(DraftFormatError, match="no ```python code block"):
        extract_draft(drawing, "render")


def test_a_frozen_function_is_offered_for_import_only_where_every_session_loads_it():
    """A check composes its sessions as the runtime does (`checks.calls.session_modules`):
    the draft beside every frozen program, and a frozen function called alone beside those
    before it. A frozen dependency the prompt offers for import is in every session that loads
    the function's module; here, every code dependency is."""
    from checks.calls import frozen_up_to, session_modules

    domain = domains.load("cubes")
    everything = {f: "" for f in FUNCTIONS}
    for function in FUNCTIONS:
        text = prompt_text(domain, function)
        loads = [session_modules(g, "", everything) for g in FUNCTIONS]  # checks, runtime
        loads += [  # a frozen function called alone (plan's relations, perceive's re-render)
            session_modules(g, "", frozen_up_to(g, everything))
            for g in authoring_order()[authoring_order().index(function) :]
        ]
        for dep in CODE_DEPS[function]:
            head = text[text.index(f"## Frozen `{dep}`") :].split("\n")[0]
            assert f"importable as `from {dep} import {dep}`" in head, head
            assert all(dep in modules for modules in loads if function in modules)
    relate = prompt_text(domain, "relate")
    assert "## Frozen `render` (already checked; importable as `from render import render`)" in (
        relate
    )


def test_the_toolbox_docs_name_only_what_a_program_can_reach(toolbox_text):
    for gone in ("DESIGN.md", "plan_grasps", "TOLERANCES.", "lives in `geometry/`"):
        assert gone not in toolbox_text, gone
    # the judges' geometry is shared, and every module says so the same way
    assert "must not share" not in toolbox_text
    assert "judges' own functions, re-exported" in toolbox_text
    import toolbox

    for module, name in sorted(set(re.findall(r"`toolbox\.([a-z_]+)(?:\.(\w+))?", toolbox_text))):
        if hasattr(toolbox, module) and not name:
            continue
        owner = importlib.import_module(f"toolbox.{module}") if name else toolbox
        assert hasattr(owner, name or module), f"toolbox.{module}.{name} does not exist"


def test_every_field_of_a_documented_class_is_described():
    """`MoveVerdict.ok/.reason/.blockers`, `GraspReport`, `Workspace` fields: a program reads
    them; the docs must say what they hold."""
    import dataclasses
    import inspect

    from toolbox.docs import MODULES

    for m in MODULES:
        module = importlib.import_module(f"toolbox.{m}")
        for name in module.__all__:
            cls = getattr(module, name)
            if not inspect.isclass(cls):
                continue
            if dataclasses.is_dataclass(cls):
                fields = [f.name for f in dataclasses.fields(cls)]
            else:
                fields = list(getattr(cls, "_fields", ()))
            doc = inspect.getdoc(cls) or ""
            for f in fields:
                assert re.search(rf"(^|\s|`){f}(`|:|\s|,)", doc), f"{m}.{name}.{f} undescribed"


def test_the_hand_docs_say_what_the_checks_pass_and_return(toolbox_text):
    robot = toolbox_text[toolbox_text.index("## toolbox.robot") :].split("\n## toolbox.")[0]
    robot = flat(robot)
    for said in (
        "The plan checks and the executor pass each mesh's full symmetry group",
        "a `MoveVerdict` (`.ok`, else `.reason` and `.blockers`, the ids in the way)",
        "`place_records` are the other objects as they stand at the place",
        "is how the checks judge each step",
        "a `GraspReport`",
        "ok: True when some grasp makes the move",
        "blockers: when not `ok`, the ids (str) of the neighbours in the way",
        "reach: largest horizontal distance",
    ):
        assert said in robot, said
    # the checks' hand (`checks.robot.RobotView` takes `Domain.grasps`): each mesh's full
    # symmetry group, the one the domain section counts
    domain = domains.load("assembly")
    for key in domain.mesh_specs:
        assert np.array_equal(domain.grasps.symmetries[key], domain.symmetries(key))
        assert len(domain.symmetries(key)) > 0


def test_the_knob_footprint_example_takes_the_knob():
    """The `footprint` example's height band starts above the piece it names (whose thickness
    it states, not the knob's width) and holds the knob alone."""
    import inspect

    from toolbox.packing import footprint

    doc = " ".join((inspect.getdoc(footprint) or "").split())
    low, high = map(float, re.search(r"z_range=\(([\d.]+), ([\d.]+)\)", doc).groups())
    thick = re.search(r"(\d+) mm thick", doc)
    assert thick, "the example states the height its band starts above"
    mesh = domains.load("tangram").mesh("square")
    z = np.asarray(mesh.vertices)[:, 2]
    slab = np.unique(np.round(z, 6))  # bottom, the piece's top face, the knob's top
    assert float(thick.group(1)) / 1000 == pytest.approx(slab[1])
    assert slab[1] < low < slab[2] <= high
    piece = footprint(mesh, np.eye(4))
    knob = np.ptp(footprint(mesh, np.eye(4), z_range=(low, high)), axis=0)
    assert np.ptp(piece, axis=0).min() > 2 * knob.max()  # the knob, not the piece
