"""`rivet eval --view all` on the frozen artifacts: one summary per camera, each naming the set
hash of the programs it ran (so a result can be traced to the artifacts that produced it)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
RIVET = str(Path(sys.executable).parent / "rivet")


def test_every_view_summary_names_the_evaluated_set(tmp_path):
    out = tmp_path / "eval.json"
    proc = subprocess.run(
        [
            RIVET,
            "eval",
            "cubes",
            "--policy",
            "artifacts",
            "--trials",
            "1",
            "--view",
            "all",
            "--quiet",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert proc.returncode in (0, 1), proc.stderr[-2000:]
    manifest = json.loads((REPO / "artifacts" / "cubes" / "manifest.json").read_text())
    summaries = json.loads(out.read_text())["cubes"]
    assert sorted(summaries) == ["front", "view1", "view2"]
    for view, summary in summaries.items():
        assert summary["view"] == view and summary["trials"] == 1
        assert summary["set_hash"] == manifest["set_hash"]


def test_a_fresh_seed_draws_from_the_split_asked_for(tmp_path):
    """`--seed S --split test` runs fresh test-split instances (named test/seedS), not dev ones,
    and a fresh set, even from seed 0, never writes the set's benchmark figures (eval.json)."""
    out = tmp_path / "eval.json"
    eval_json = REPO / "artifacts" / "cubes" / "eval.json"
    before = eval_json.read_bytes() if eval_json.is_file() else None
    proc = subprocess.run(
        [
            *(RIVET, "eval", "cubes", "--policy", "oracle", "--split", "test", "--seed", "0"),
            *("--trials", "1", "--quiet", "--json", str(out)),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert proc.returncode in (0, 1), proc.stderr[-2000:]
    summary = json.loads(out.read_text())
    assert [t["name"] for t in summary["per_trial"]] == ["test/seed0"]
    assert (eval_json.read_bytes() if eval_json.is_file() else None) == before
