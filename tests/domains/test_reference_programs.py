"""The people-written reference programs play by the model's rules: every fact about the robot
they rely on comes from the toolbox (which the prompts document), none is copied from the
executor's hand model or the generator's placement region."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import domains
from domains.base import Domain
from geometry.hand import WORKSPACE, FingerModel

PROGRAMS = sorted(Path(domains.__file__).parent.glob("*/programs/*.py"))


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
    set().union(*(_floats(getattr(FingerModel(), f)) for f in FingerModel.__dataclass_fields__))
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


@pytest.mark.parametrize("path", PROGRAMS, ids=lambda p: f"{p.parts[-3]}/{p.name}")
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
