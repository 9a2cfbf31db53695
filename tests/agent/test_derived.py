"""The people-written sets are a derived build (docs/design.md, "Artifacts"): the programs in
`domains/<d>/programs/` are the only hand-edited source; the reference transcript and the
frozen set are what `make refreeze` makes of them, and `rivet refreeze --check` says where
the committed ones are not."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

import domains
from agent.handwritten import derivation_problems
from rivet.cli import main

REPO = Path(__file__).resolve().parents[2]
DOMAINS = [name for name in domains.names() if (domains.load(name).root / "programs").is_dir()]


@pytest.mark.parametrize("name", DOMAINS)
def test_committed_transcripts_and_sets_are_what_the_programs_make(name):
    assert derivation_problems(domains.load(name)) == []


@pytest.fixture
def copy(tmp_path):
    """A copy of the cubes domain's programs, transcript and frozen set."""
    root = tmp_path / "cubes"
    shutil.copytree(REPO / "domains" / "cubes" / "programs", root / "programs")
    shutil.copytree(
        REPO / "domains" / "cubes" / "transcripts" / "reference",
        root / "transcripts" / "reference",
    )
    shutil.copytree(REPO / "artifacts" / "cubes", tmp_path / "artifacts" / "cubes")
    domain = SimpleNamespace(
        name="cubes", root=root, reference_transcript=root / "transcripts" / "reference"
    )
    return domain, tmp_path / "artifacts"


def test_a_program_changed_without_a_refreeze_is_found(copy):
    domain, artifacts = copy
    assert derivation_problems(domain, artifacts, prompts=False) == []
    plan = domain.root / "programs" / "plan.py"
    plan.write_text(plan.read_text().replace("\ndef plan(", "\nCHANGED = 1\n\n\ndef plan(", 1))
    problems = derivation_problems(domain, artifacts, prompts=False)
    assert any("transcript's plan answers" in p for p in problems), problems
    assert any("frozen plan.py is not programs/plan.py" in p for p in problems), problems


def test_a_frozen_file_edited_by_hand_is_found(copy):
    domain, artifacts = copy
    relate = artifacts / "cubes" / "relate.py"
    relate.write_text(relate.read_text() + "\n# edited\n")
    problems = derivation_problems(domain, artifacts, prompts=False)
    assert len(problems) == 1 and "does not match the manifest" in problems[0], problems


def test_a_draft_that_the_transcript_lacks_is_found(copy):
    domain, artifacts = copy
    drafts = domain.root / "programs" / "drafts"
    drafts.mkdir(exist_ok=True)
    (drafts / "render_v1.py").write_text("def render(records, meshes, camera):\n    return {}\n")
    problems = derivation_problems(domain, artifacts, prompts=False)
    assert problems == [
        "cubes: the transcript's render answers are not drafts/render_v1.py, render.py "
        "(1 answers for 2 files, or a file changed)"
    ]


def test_refreeze_check_exits_0_on_the_committed_files(capsys):
    assert main(["refreeze", "--check", *DOMAINS]) == 0
    assert "derived files match the programs" in capsys.readouterr().out


def test_a_prompt_changed_since_packing_is_found(monkeypatch):
    """A transcript packed from other prompts would drift on replay: the function whose first
    request changed is named."""
    import agent.prompt

    real = agent.prompt.template

    def edited(name: str) -> str:
        text = real(name)
        return text + "\nOne more sentence.\n" if name == "plan.md" else text

    cubes = domains.load("cubes")
    before = set(derivation_problems(cubes))
    monkeypatch.setattr(agent.prompt, "template", edited)
    assert set(derivation_problems(cubes)) - before == {
        "cubes: the prompt of plan changed since the transcript was packed"
    }
