"""`rivet diff` cannot mislead: metrics are shown only for the set hash they measured.

On a throwaway git checkout (`rivet diff --repo`): set A is frozen with an eval.json stamped
with A's set hash (hand-written figures, as `rivet eval cubes --policy artifacts` would stamp
them) and committed; then a different set B is frozen. Freezing B moves A's eval.json aside
(eval.stale.json), and the review shows A's figures before and "not evaluated", with the
command to run, for B."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from artifacts import build_manifest, freeze
from artifacts.store import EVAL, STALE_EVAL
from rivet.cli import main

REPO = Path(__file__).resolve().parents[2]
RIVET = str(Path(sys.executable).parent / "rivet")
AUTHOR = {"kind": "people", "names": ["RIVET tests"]}

# Four tiny hand-written programs (the review reads hashes and text; nothing runs them).
SET_A = {
    "render": "def render(records, meshes, camera):\n    return {'n': len(records)}\n",
    "perceive": "def perceive(observation, meshes, camera):\n    return []\n",
    "relate": "def relate(records, meshes):\n    return {'nodes': [], 'edges': []}\n",
    "plan": "def plan(start, goal, meshes):\n    return {'status': 'ok', 'steps': []}\n",
}
SET_B = {**SET_A, "plan": SET_A["plan"].replace("'steps': []", "'steps': []  # B")}


def git(repo: Path, *args: str) -> None:
    subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True)


def freeze_set(repo: Path, sources: dict[str, str]) -> str:
    manifest = build_manifest("cubes", sources, author=AUTHOR)
    assert freeze("cubes", sources, manifest, repo / "artifacts")
    return manifest["set_hash"]


def write_eval(repo: Path, set_hash: str, state: float, plan: float, final: float) -> None:
    figures = {"set_hash": set_hash, "trials": 60, "state_ac": state, "plan_sr": plan}
    (repo / "artifacts" / "cubes" / EVAL).write_text(json.dumps({**figures, "final_sr": final}))


def diff(repo: Path, capsys) -> str:
    """`rivet diff cubes --repo REPO`, through the command line's entry point (in process)."""
    capsys.readouterr()
    assert main(["diff", "cubes", "--repo", str(repo)]) == 0
    return capsys.readouterr().out


def diff_process(repo: Path) -> str:
    """The same through the installed `rivet` executable."""
    proc = subprocess.run(
        [RIVET, "diff", "cubes", "--repo", str(repo)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


@pytest.fixture
def repo(tmp_path) -> Path:
    git(tmp_path, "init", "-q")
    git(tmp_path, "config", "user.email", "t@example.com")
    git(tmp_path, "config", "user.name", "t")
    return tmp_path


def test_a_new_set_reads_not_evaluated_and_the_old_keeps_its_figures(repo, capsys):
    a = freeze_set(repo, SET_A)
    write_eval(repo, a, 0.9, 0.85, 0.8)
    git(repo, "add", "-A")
    git(repo, "commit", "-qm", "set A, evaluated")
    assert "| final_sr | 80.0% | 80.0% |" in diff(repo, capsys)  # same set both sides

    b = freeze_set(repo, SET_B)
    assert b != a
    folder = repo / "artifacts" / "cubes"
    assert not (folder / EVAL).exists()  # freezing B marked A's metrics stale …
    assert json.loads((folder / STALE_EVAL).read_text())["set_hash"] == a  # … and kept them

    md = diff_process(repo)
    assert f"**Set hash changed**: `{a[:16]}` → `{b[:16]}`" in md
    for row in (
        "| state_ac | 90.0% | not evaluated |",
        "| plan_sr | 85.0% | not evaluated |",
        "| final_sr | 80.0% | not evaluated |",
        "| trials | 60 | not evaluated |",
    ):
        assert row in md, md
    assert f"After (set `{b[:16]}` in the working tree): **not evaluated** — no `eval.json`" in md
    assert "run `rivet eval cubes --policy artifacts`" in md
    assert "Before (" not in md  # A was measured: no note for it


def test_an_eval_json_of_another_set_is_never_shown_as_this_sets(repo, capsys):
    a = freeze_set(repo, SET_A)
    write_eval(repo, a, 1.0, 1.0, 1.0)
    git(repo, "add", "-A")
    git(repo, "commit", "-qm", "set A")
    b = freeze_set(repo, SET_B)
    write_eval(repo, a, 1.0, 1.0, 1.0)  # e.g. copied back by hand: it still names set A
    md = diff(repo, capsys)
    assert "| final_sr | 100.0% | not evaluated |" in md
    assert f"`eval.json` measured set `{a[:16]}`, not this one" in md
    # once B is measured, its own figures show
    write_eval(repo, b, 0.95, 0.9, 0.9)
    md = diff(repo, capsys)
    assert "| final_sr | 100.0% | 90.0% |" in md and "not evaluated" not in md


def test_the_before_side_is_checked_too(repo, capsys):
    a = freeze_set(repo, SET_A)
    (repo / "artifacts" / "cubes" / EVAL).write_text('{"final_sr": 1.0}')  # no set hash
    git(repo, "add", "-A")
    git(repo, "commit", "-qm", "set A, metrics of unknown provenance")
    b = freeze_set(repo, SET_B)
    write_eval(repo, b, 1.0, 1.0, 0.95)
    md = diff(repo, capsys)
    assert "| final_sr | not evaluated | 95.0% |" in md
    assert f"Before (set `{a[:16]}` at `HEAD`): **not evaluated** — `eval.json` names no" in md
    assert "on a checkout of `HEAD`, run `rivet eval cubes --policy artifacts`" in md


def test_freezing_back_a_measured_set_restores_its_metrics(repo):
    a = freeze_set(repo, SET_A)
    write_eval(repo, a, 1.0, 1.0, 1.0)
    freeze_set(repo, SET_B)  # A's metrics → eval.stale.json
    freeze_set(repo, SET_A)  # A again: they measure it, so they are eval.json again
    folder = repo / "artifacts" / "cubes"
    assert json.loads((folder / EVAL).read_text())["set_hash"] == a
    assert not (folder / STALE_EVAL).exists()
