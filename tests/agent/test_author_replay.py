"""`rivet author DOMAIN` offline (default matching by function and attempt, so a renderer that
draws a pixel differently on another machine only warns): replays the committed reference transcript through the real
checks in the Docker sandbox, repairs at least once, and reproduces the committed artifacts."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import domains

REPO = Path(__file__).resolve().parents[2]
RIVET = str(Path(sys.executable).parent / "rivet")


def _transcript_domains() -> list[str]:
    return [
        d
        for d in domains.names()
        if (domains.load(d).root / "transcripts" / "reference" / "meta.json").is_file()
    ]


@pytest.mark.docker
@pytest.mark.slow
@pytest.mark.parametrize("domain", _transcript_domains())
def test_replayed_authoring_reproduces_the_committed_artifacts(tmp_path, domain):
    committed = json.loads((REPO / "artifacts" / domain / "manifest.json").read_text())
    proc = subprocess.run(
        [
            RIVET,
            "author",
            domain,
            "--strict",
            "--runs-dir",
            str(tmp_path / "runs"),
            "--artifacts",
            str(tmp_path / "art"),
        ],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=REPO,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    fresh = json.loads((tmp_path / "art" / domain / "manifest.json").read_text())
    assert fresh["set_hash"] == committed["set_hash"]
    assert fresh["author"]["kind"] == "people"  # hand-written, and labelled so
    assert any(f.get("attempts", 1) > 1 for f in fresh["functions"].values()), "no repair exercised"
    assert "failed:" in proc.stderr  # a draft was rejected by the checks, then repaired
    (run_dir,) = list((tmp_path / "runs" / domain).iterdir())
    assert (run_dir / "report.html").is_file()
