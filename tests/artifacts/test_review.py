"""`rivet diff`'s Markdown on a throwaway git repository."""

from __future__ import annotations

import json
import subprocess

import pytest

from artifacts import build_manifest, freeze
from artifacts.review import diff_markdown
from contracts.errors import UsageError

from .test_store import AUTHOR, SOURCES


def git(repo, *args):
    subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True)


@pytest.fixture
def repo(tmp_path):
    git(tmp_path, "init", "-q")
    git(tmp_path, "config", "user.email", "t@example.com")
    git(tmp_path, "config", "user.name", "t")
    manifest = build_manifest("toy", SOURCES, author=AUTHOR)
    freeze("toy", SOURCES, manifest, tmp_path / "artifacts")
    (tmp_path / "artifacts" / "toy" / "eval.json").write_text(
        json.dumps(
            {"set_hash": manifest["set_hash"], "state_ac": 0.9, "plan_sr": 1.0, "final_sr": 0.85}
        )
    )
    git(tmp_path, "add", "-A")
    git(tmp_path, "commit", "-qm", "base")
    return tmp_path


def test_unchanged_set(repo):
    md = diff_markdown("toy", "HEAD", repo)
    assert "Set hash unchanged" in md
    assert "```diff" not in md


def test_changed_function_shows_its_diff_and_metrics(repo):
    changed = {**SOURCES, "plan": SOURCES["plan"].replace("'ok'", "'ok'  # explicit")}
    manifest = build_manifest("toy", changed, author=AUTHOR)
    freeze("toy", changed, manifest, repo / "artifacts")
    (repo / "artifacts" / "toy" / "eval.json").write_text(  # metrics stamped with the new set
        json.dumps(
            {"set_hash": manifest["set_hash"], "state_ac": 0.95, "plan_sr": 1.0, "final_sr": 0.9}
        )
    )
    md = diff_markdown("toy", "HEAD", repo)
    assert "**Set hash changed**" in md
    assert "| `plan` | **yes** |" in md and "| `render` | no |" in md
    assert "+    return {'status': 'ok'  # explicit" in md
    assert "| final_sr | 85.0% | 90.0% |" in md


def test_unknown_revision_is_a_usage_error(repo):
    with pytest.raises(UsageError, match="unknown git revision 'nope'"):
        diff_markdown("toy", "nope", repo)
