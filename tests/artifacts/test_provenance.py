"""`artifacts.provenance.dirty`: a checkout differs from its commit when a tracked file does,
results aside (the files runs write and no run reads) — tested on a scratch repository."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from artifacts import provenance


@pytest.fixture
def repo(tmp_path, monkeypatch) -> Path:
    def git(*args: str) -> None:
        subprocess.run(["git", *args], cwd=tmp_path, check=True, capture_output=True)

    for name in ("sim/loop.py", "artifacts/cubes/eval.json", "docs/results/cubes-test-front.json",
                 "docs/results.md"):  # fmt: skip
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("before\n")
    git("init", "-q")
    git("add", "-A")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "scratch")
    monkeypatch.setattr(provenance, "REPO", tmp_path)
    return tmp_path


def test_results_written_by_runs_leave_the_checkout_clean(repo):
    assert provenance.dirty() is False
    for name in ("artifacts/cubes/eval.json", "docs/results/cubes-test-front.json",
                 "docs/results.md"):  # fmt: skip
        (repo / name).write_text("after\n")
    (repo / "docs/results/new-run.json").write_text("{}\n")  # untracked: never counted
    assert provenance.dirty() is False
    (repo / "sim/loop.py").write_text("after\n")
    assert provenance.dirty() is True
