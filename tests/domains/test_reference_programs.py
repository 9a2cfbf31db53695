"""The people-written reference programs play by the model's rules: every fact about the robot
they rely on comes from the toolbox (which the prompts document), none is copied from the
executor's hand model or the generator's placement region."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

import domains
from domains.base import Domain
from geometry.robot import ROBOT, WORKSPACE, FingerModel

PROGRAMS = sorted(Path(domains.__file__).parent.glob("*/programs/*.py"))
# the earlier failing versions the replay transcripts show: people-written too
DRAFTS = sorted(Path(domains.__file__).parent.glob("*/programs/drafts/*.py"))


def _floats(value) -> set[float]:
    if isinstance(value, tuple | list):
        return set().union(*(_floats(v) for v in value)) if value else set()
    return {round(abs(value), 6)} if isinstance(value, float) else set()


def _hand_facts(values: set[float]) -> set[float]:
    """The hand's dimensions a program could only have copied: 30 mm and more and not a round
    number of millimetres (0.0315, 0.064, 0.082 …); rounder or smaller ones (0.012, 0.04) also
    mean other things."""
    return {v for v in values if 0.03 <= v < 0.2 and round(v * 1000, 3) % 5 != 0}


HAND = _hand_facts(
    set().union(
        *(_floats(getattr(ROBOT.gripper.fingers, f)) for f in FingerModel.__dataclass_fields__)
    )
)
REGIONS = (
    _floats(WORKSPACE.x) | _floats(WORKSPACE.y) | {WORKSPACE.reach}
    | _floats(Domain.placement.x) | _floats(Domain.placement.y) | {Domain.placement.reach}
) - {0.0}  # fmt: skip


def _literals(path: Path) -> list[tuple[int, float]]:
    tree = ast.parse(path.read_text())
    return [
        (n.lineno, round(abs(n.value), 6))
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, float)
    ]


def test_the_fact_lists_are_not_empty():
    assert {0.0315, 0.064, 0.082} <= HAND  # the couplers' depth and reach, the wrist's offset
    assert {0.75, 0.78, 0.68, 0.72} <= REGIONS


@pytest.mark.parametrize(
    "path", PROGRAMS + DRAFTS, ids=lambda p: "/".join(p.parts[p.parts.index("programs") - 1 :])
)
def test_no_hand_dimension_is_copied_into_a_program(path):
    copied = [(line, v) for line, v in _literals(path) if v in HAND]
    assert not copied, f"{path}: hand dimensions copied from the executor: {copied}"


@pytest.mark.parametrize(
    "path", [p for p in PROGRAMS if p.name == "plan.py"], ids=lambda p: p.parts[-3]
)
def test_plans_take_the_hand_and_the_workspace_from_the_toolbox(path):
    copied = [(line, v) for line, v in _literals(path) if v in REGIONS]
    assert not copied, f"{path}: workspace or placement region copied: {copied}"
    imported = {
        alias.name
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.ImportFrom) and node.module == "toolbox.robot"
        for alias in node.names
    }
    assert "WORKSPACE" in imported, f"{path} does not take the workspace from toolbox.robot"


@pytest.mark.parametrize(
    "path", [p for p in DRAFTS if p.stem.startswith("plan")], ids=lambda p: p.parts[-4]
)
def test_plan_drafts_take_the_regions_from_the_toolbox(path):
    """A draft fails on its own merits, not on a region number only the generator knows."""
    copied = [(line, v) for line, v in _literals(path) if v in REGIONS]
    assert not copied, f"{path}: workspace or placement region copied: {copied}"


def _plan_module(path: Path):
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"_reference_plan_{path.parts[-3]}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    "path", [p for p in PROGRAMS if p.name == "plan.py"], ids=lambda p: p.parts[-3]
)
def test_plans_derive_no_region_that_reproduces_the_generators(path):
    """A region built from the workspace by a margin that happens to land on the generator's
    placement region (WORKSPACE.y ± 8 cm is PLACEMENT.y) is the generator's constant in
    disguise, which a literal search cannot see: a plan's module-level regions and bound pairs
    either are `toolbox.robot.PLACEMENT` (or its x / y) or share no edge with it."""
    placement = Domain.placement
    edges = {round(v, 6) for v in (*placement.x, *placement.y)}
    module = _plan_module(path)
    derived = []
    for name, value in vars(module).items():
        if value is placement or value is placement.x or value is placement.y:
            continue
        if isinstance(value, type(placement)):
            bounds = (*value.x, *value.y)
        elif (
            isinstance(value, tuple)
            and len(value) == 2
            and all(isinstance(v, float) for v in value)
        ):
            bounds = value
        else:
            continue
        shared = {round(v, 6) for v in bounds} & edges
        if shared:
            derived.append((name, sorted(shared)))
    assert not derived, f"{path}: regions that reproduce the placement region's edges: {derived}"


# the executor's own lengths [m] (its other fields are times, speeds and counts)
EXECUTOR_LENGTHS = (
    "final_approach",
    "clearance",
    "min_transfer_height",
    "release_height",
    "hold_tolerance",
)


def _lengths_and_angles() -> dict[float, str]:
    """The executor's, the checks', the scoring's and the generators' own lengths [m] and
    angles (in degrees as a program writes them in `np.radians(...)`), by value → name: what a
    program can know only when its prompt or the task text states it. Of the generators: the
    construction planner's fields and the domain modules' float constants (not their tuples,
    class attributes or numbers written inline)."""
    from geometry.tolerances import TOLERANCES
    from sim.executor import ExecutorConfig

    named: dict[float, str] = {}

    def add(name: str, value, *, angle: bool = False) -> None:
        for v in _floats(value):
            if v >= 1e-4:
                named.setdefault(round(float(np.degrees(v)), 3) if angle else v, name)

    for f in FingerModel.__dataclass_fields__:
        add(f"FingerModel.{f}", getattr(ROBOT.gripper.fingers, f))
    for f in ("penetration", "contact", "com_margin", "perceived_penetration",
              "perceived_contact", "sweep_touch", "sweep_clearance", "grasp_margins", "vertical"):  # fmt: skip
        add(f"TOLERANCES.{f}", getattr(TOLERANCES, f))
    for f in ("face_vertical", "face_antiparallel", "yaw_only"):
        add(f"TOLERANCES.{f}", getattr(TOLERANCES, f), angle=True)
    config = ExecutorConfig()
    for f in EXECUTOR_LENGTHS:
        add(f"ExecutorConfig.{f}", getattr(config, f))
    add("ExecutorConfig.in_hand.position", config.in_hand.position)
    add("ExecutorConfig.in_hand.rotation", config.in_hand.rotation, angle=True)
    # the generators': the construction planner's clearances and grid, the scenes' spacings
    from domains.reference_order import ReferencePlanner

    for f, field in ReferencePlanner.__dataclass_fields__.items():
        if isinstance(field.default, float):
            add(f"ReferencePlanner.{f}", field.default)
    add("Domain.temp_clearance", Domain.temp_clearance)
    for name in domains.names():
        module = type(domains.load(name)).__module__
        for attr, value in vars(__import__(module, fromlist=["_"])).items():
            if attr.isupper() and isinstance(value, float):
                add(f"{module}.{attr}", value)
    return named


HIDDEN = _lengths_and_angles()
_NUMBER = re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)\s*(mm|cm|m\b|°|deg|rad)?")


def _stated(text: str) -> set[float]:
    """Every number the text states, in the units a program would write it in (metres for
    lengths, degrees or the bare number otherwise). The toolbox documentation's headings
    (a constant's `TOUCHING = 0.001`, a signature's defaults) do not count: a value the prompt gives
    only by a toolbox name is one a program takes by that name, so a reader can see where it
    comes from."""
    out: set[float] = set()
    for line in text.splitlines():
        if line.startswith("###"):
            continue
        for number, unit in _NUMBER.findall(line):
            out |= _as_written(
                float(number), "mm" if line.startswith("|") and "×" in line else unit
            )
    return out


def _as_written(v: float, unit: str) -> set[float]:
    """A stated number as a program may write it (a size table "160 × 35 × 20" is in mm)."""
    out = {round(v, 6)}
    if unit == "mm":
        out.add(round(v / 1000, 6))
    elif unit == "cm":
        out.add(round(v / 100, 6))
    elif unit == "rad":
        out.add(round(float(np.degrees(v)), 3))
    return out


@pytest.fixture(scope="module")
def prompts():
    """Domain → function → the text a model writing that function reads (its first request and
    the task text)."""
    from agent.context import build_context
    from agent.prompt import build_request
    from toolbox.docs import toolbox_docs

    docs = toolbox_docs()
    out = {}
    for name in domains.names():
        d = domains.load(name)
        ctx = build_context(d, (), docs)
        programs = {p.stem: p.read_text() for p in (d.root / "programs").glob("*.py")}
        order = ("render", "perceive", "relate", "plan")
        out[name] = {}
        for k, function in enumerate(order):
            request = build_request(ctx, function, 1, frozen={f: programs[f] for f in order[:k]})
            blocks = (*request.system, *request.content)
            text = "".join(getattr(b, "text", "") for b in blocks)
            out[name][function] = text + (d.root / "task.md").read_text()
    return out


def test_the_hidden_constants_are_found_and_stated_numbers_read():
    assert HIDDEN[0.12] in {"ExecutorConfig.min_transfer_height", "FingerModel.palm_from"}
    assert HIDDEN[0.003] in {"TOLERANCES.perceived_penetration", "FingerModel.tip_margin"}
    assert {0.025, 0.0003, 0.3} <= set(HIDDEN)  # inner half width, in-hand noise (m and °)
    assert HIDDEN[0.03] == "ReferencePlanner.clearance"  # the generator's temporary places
    assert HIDDEN[0.055] == "domains.assembly.PILLARS_FOR_BEAM"  # its scenes' spacings
    assert {0.003, 3.0, 0.04, 0.5, 0.16} <= _stated("3 mm, 3°, 4 cm and 0.5\n| 160 × 35 |")


@pytest.mark.parametrize(
    "path",
    [p for p in PROGRAMS if p.stem in ("relate", "plan")],
    ids=lambda p: f"{p.parts[-3]}/{p.name}",
)
def test_no_unstated_constant_of_the_executor_or_the_checks_is_in_a_program(path, prompts):
    """A literal in `relate` or `plan` equal to a length or angle of the executor, the checks,
    the scoring or the generators must be one the program's prompt or task text states: otherwise it was
    copied (or lands on the hidden value by chance, which a reader cannot tell apart). Derive
    it from the toolbox's facts or the stated sizes instead. (`perceive`'s numbers are about
    pixels, colours and search grids: a value threshold of 0.12 is not the palm's height.)"""
    stated = _stated(prompts[path.parts[-3]][path.stem])
    copied = [
        (line, v, HIDDEN[v]) for line, v in _literals(path) if v in HIDDEN and v not in stated
    ]
    assert not copied, f"{path}: constants no prompt states: {copied}"


def _toolbox_named() -> dict[float, str]:
    """The lengths the toolbox documents by name (its tolerances and the hand's sizes)."""
    import toolbox.robot
    import toolbox.stability

    named: dict[float, str] = {}
    for module in (toolbox.stability, toolbox.robot):
        for name in module.__all__:
            for v in _floats(getattr(module, name)):
                named.setdefault(v, f"{module.__name__}.{name}")
    return named


TOOLBOX_NAMED = _toolbox_named()
# A module constant of a reference program whose number is a toolbox tolerance's by chance: what
# it means instead.
NOT_THE_TOOLBOX_FACT = {
    ("assembly", "relate", "ABOVE"): "a height band for `blocks` (outlines seen from above)",
    ("assembly", "relate", "OVERLAP"): "the least overlap of outlines that makes a `blocks` edge",
}


def _module_constants(path: Path) -> list[tuple[int, str, float]]:
    """(line, name, |value|) of each module-level `NAME = <number>`."""
    out = []
    for node in ast.parse(path.read_text()).body:
        if not (isinstance(node, ast.Assign) and len(node.targets) == 1):
            continue
        target, value = node.targets[0], node.value
        if isinstance(value, ast.UnaryOp) and isinstance(value.op, ast.USub):
            value = value.operand
        if (
            isinstance(target, ast.Name)
            and isinstance(value, ast.Constant)
            and isinstance(value.value, float)
        ):
            out.append((node.lineno, target.id, round(abs(value.value), 6)))
    return out


def test_the_toolbox_names_are_read():
    assert TOOLBOX_NAMED[0.001] == "toolbox.stability.TOUCHING"
    assert TOOLBOX_NAMED[0.003] == "toolbox.stability.PERCEIVED_OVERLAP"
    assert "toolbox.robot.GRASP_MARGINS" in TOOLBOX_NAMED.values()


@pytest.mark.parametrize(
    "path",
    [p for p in PROGRAMS if p.stem in ("relate", "plan")],
    ids=lambda p: f"{p.parts[-3]}/{p.name}",
)
def test_a_tolerance_the_toolbox_names_is_taken_by_its_name(path):
    """A program's named constant that equals a tolerance or hand size the toolbox documents by
    name (`toolbox.stability.TOUCHING`, `toolbox.robot.GRASP_MARGINS` …) is that fact: it is
    written as the name, so a reader sees where it comes from (the prompt may also state the
    number in prose, which is how a copied constant used to pass). A constant that only shares
    the number is one of the domain's own (its task text, its relation gaps) or is listed in
    NOT_THE_TOOLBOX_FACT with what it means instead."""
    domain, function = path.parts[-3], path.stem
    d = domains.load(domain)
    # the domain's own numbers: its task text and the relation gaps the facts state
    own = _stated(d.task) | {round(d.on_gap, 6), round(d.adjacent_gap, 6)}
    copied = [
        (line, name, v, TOOLBOX_NAMED[v])
        for line, name, v in _module_constants(path)
        if v in TOOLBOX_NAMED
        and v not in own
        and (domain, function, name) not in NOT_THE_TOOLBOX_FACT
    ]
    assert not copied, f"{path}: toolbox facts written as numbers: {copied}"


def _inline_numbers(source: str) -> list[tuple[int, float]]:
    """(line, |value|) of each number a program writes inline: every float literal but a
    module-level `NAME = <number>` (named constants are judged by their name), and an angle
    written in degrees (`np.radians(3.0)`) as the radians it means."""
    tree = ast.parse(source)
    skip = {
        id(node.value.operand if isinstance(node.value, ast.UnaryOp) else node.value)
        for node in tree.body
        if isinstance(node, ast.Assign)
    }
    out = []
    for n in ast.walk(tree):
        if (
            isinstance(n, ast.Call)
            and getattr(n.func, "attr", getattr(n.func, "id", None)) in ("radians", "deg2rad")
            and n.args
            and isinstance(n.args[0], ast.Constant)
        ):
            skip.add(id(n.args[0]))
            out.append((n.lineno, round(abs(float(np.radians(n.args[0].value))), 6)))
    for n in ast.walk(tree):
        if isinstance(n, ast.Constant) and isinstance(n.value, float) and id(n) not in skip:
            out.append((n.lineno, round(abs(n.value), 6)))
    return sorted(out)


def test_inline_numbers_are_read():
    source = "A = 0.7\nB = -0.002\nC = np.radians(4.0)\ndef f(x):\n    return x > -0.001 and np.cos(math.radians(3))\n"
    assert _inline_numbers(source) == [
        (3, round(float(np.radians(4.0)), 6)),
        (5, 0.001),
        (5, round(float(np.radians(3.0)), 6)),
    ]


@pytest.mark.parametrize(
    "path",
    [p for p in PROGRAMS if p.stem in ("relate", "plan")],
    ids=lambda p: f"{p.parts[-3]}/{p.name}",
)
def test_no_toolbox_fact_is_written_inline(path):
    """The same rule for numbers written inline (`axis[2] >= 0.7`, `np.cos(np.radians(3.0))`,
    `top - 0.002`): one that equals a tolerance or angle the toolbox names is written as the name
    (`VERTICAL`, `YAW_ONLY`, `RESTING_GAP`), or, when it means something else, as a named
    constant of the program that says what (and is listed in NOT_THE_TOOLBOX_FACT)."""
    d = domains.load(path.parts[-3])
    own = _stated(d.task) | {round(d.on_gap, 6), round(d.adjacent_gap, 6)}
    lines = path.read_text().splitlines()
    copied = [
        (line, v, TOOLBOX_NAMED[v], lines[line - 1].strip())
        for line, v in _inline_numbers(path.read_text())
        if v in TOOLBOX_NAMED and v not in own
    ]
    assert not copied, f"{path}: toolbox facts written inline: {copied}"


def _judged_numbers(domain: Domain) -> dict[float, str]:
    """The numbers a plan must never hold, stated in its prompt or not: the scoring's tolerance
    (in metres, degrees and radians), the relation gaps the reference relations use, and the
    executor's and the construction planner's own lengths. A plan decides with the perceived
    states' slack and the hand model (toolbox names); `relate` alone reproduces the stated
    relation gaps, which are its specification."""
    from dataclasses import fields

    from domains.reference_order import ReferencePlanner
    from sim.executor import ExecutorConfig

    out: dict[float, str] = {}
    tol = domain.tolerance
    out[round(tol.translation, 6)] = "the scoring tolerance"
    if tol.rotation is not None:
        out[round(float(np.degrees(tol.rotation)), 3)] = "the scoring tolerance [°]"
        out[round(tol.rotation, 6)] = "the scoring tolerance [rad]"
    for name in domains.names():
        d = domains.load(name)
        out.setdefault(round(d.on_gap, 6), f"{name}'s 'on' gap")
        out.setdefault(round(d.adjacent_gap, 6), f"{name}'s 'adjacent' gap")
    for f in fields(ReferencePlanner):
        if isinstance(f.default, float):
            out.setdefault(round(f.default, 6), f"ReferencePlanner.{f.name}")
    config = ExecutorConfig()
    for f in EXECUTOR_LENGTHS:
        for v in _floats(getattr(config, f)):
            out.setdefault(v, f"ExecutorConfig.{f}")
    return out


def test_the_judged_numbers_are_found():
    judged = _judged_numbers(domains.load("tangram"))
    assert {0.005, 5.0, 0.008, 0.0005, 0.03} <= set(judged)
    assert judged[0.005] == "the scoring tolerance"


@pytest.mark.parametrize(
    "path", [p for p in PROGRAMS if p.name == "plan.py"], ids=lambda p: p.parts[-3]
)
def test_a_plan_holds_no_scoring_tolerance_relation_gap_or_executor_length(path):
    """Stated or not, a plan does not write the scorer's tolerance, a relation gap or a length
    of the executor or the construction planner as a number: it takes the perceived states'
    slack and the hand's sizes by their toolbox names, so that a reader sees what it means and
    a plan never aims at what it is scored with."""
    judged = _judged_numbers(domains.load(path.parts[-3]))
    numbers = _literals(path) + _inline_numbers(path.read_text())
    copied = sorted({(line, v, judged[v]) for line, v in numbers if v in judged})
    assert not copied, f"{path}: numbers of the scoring, relations or executor: {copied}"
