"""The thin runtime refuses a program's answer over its counts (issue 35, item 4): the same
limits as the checks (`contracts.limits`), before the next program or the robot gets it.

The cubes reference programs run in a local sandbox session with one of them swapped for a
hostile draft of `tests/checks/drafts/`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sandbox
from artifacts.errors import ProgramFailed
from artifacts.runtime import from_folder

REPO = Path(__file__).resolve().parents[2]
PROGRAMS = REPO / "domains" / "cubes" / "programs"
DRAFTS = REPO / "tests" / "checks" / "drafts"


@pytest.fixture(scope="module")
def executor():
    with sandbox.open_executor("local", quiet=True) as ex:
        yield ex


def _system(tmp_path: Path, function: str, draft: str):
    for name in ("render", "perceive", "relate", "plan"):
        source = DRAFTS / draft if name == function else PROGRAMS / f"{name}.py"
        (tmp_path / f"{name}.py").write_text(source.read_text())
    return from_folder("cubes", tmp_path)


def _records() -> list[dict]:
    pose = np.eye(4)
    pose[2, 3] = 0.02
    return [{"id": "red", "mesh": "cube", "pose": pose}]


def test_a_system_knows_its_catalogue(tmp_path):
    assert _system(tmp_path, "plan", "plan_long.py").objects == 6


@pytest.mark.parametrize(
    ("function", "draft", "call", "message"),
    [
        (
            "perceive",
            "perceive_stacked.py",
            lambda run: run.perceive(
                {"rgb": np.zeros((4, 4, 3), np.uint8), "depth": np.zeros((4, 4)), "camera": {}}
            ),
            "4000 records, but the domain's catalogue holds 6 objects",
        ),
        (
            "relate",
            "relate_duplicates.py",
            lambda run: run.relate(_records()),
            "200000 edges, over the 480 that 16 edge types could give 6 objects",
        ),
        (
            "plan",
            "plan_long.py",
            lambda run: run.plan({"objects": _records()}, {"objects": _records()}),
            "40000 plan steps, over the plan contract's cap of 1000",
        ),
    ],
    ids=["perceive", "relate", "plan"],
)
def test_an_answer_over_its_counts_is_a_program_failure(
    tmp_path, executor, function, draft, call, message
):
    system = _system(tmp_path, function, draft)
    with system.runner(executor) as run, pytest.raises(ProgramFailed) as info:
        call(run)
    assert info.value.function == function
    assert str(info.value).startswith(
        f"the frozen `{function}` returned a value that cannot be used ({message}"
    )
    assert len(str(info.value)) < 300
