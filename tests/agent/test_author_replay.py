"""The committed reference transcripts, replayed.

`rivet author DOMAIN` offline (default matching by function and attempt, so a renderer that
draws a pixel differently on another machine only warns) replays the committed reference
transcript through the real checks in the Docker sandbox, repairs at least once, and reproduces
the committed artifacts. A faster test, below, says in seconds when a prompt input has changed
so that strict replay would refuse the transcript."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import domains
from agent.context import build_context, reference_observations
from agent.extract import extract_draft
from agent.prompt import build_request
from agent.transcript import Transcript
from artifacts.hashing import CHECKED_AGAINST
from contracts.functions import FUNCTIONS
from toolbox.docs import toolbox_docs

REPO = Path(__file__).resolve().parents[2]
RIVET = str(Path(sys.executable).parent / "rivet")


def _transcript_domains() -> list[str]:
    return [
        d for d in domains.names() if (domains.load(d).reference_transcript / "meta.json").is_file()
    ]


def _events(run_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (run_dir / "journal.jsonl").read_text().splitlines()]


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
            "--gate-trials",
            # the gate in the real command path, one trial (the reference sets fail some of
            # their gate draws' trials: docs/checks.md, "Measured on the reference programs")
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=1800,
        cwd=REPO,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    fresh = json.loads((tmp_path / "art" / domain / "manifest.json").read_text())
    assert fresh["set_hash"] == committed["set_hash"]
    # … and the committed manifest names what these checks just passed against
    assert [fresh[k] for k in CHECKED_AGAINST] == [committed[k] for k in CHECKED_AGAINST]
    assert fresh["author"]["kind"] == "people"  # hand-written, and labelled so
    assert any(f.get("attempts", 1) > 1 for f in fresh["functions"].values()), "no repair exercised"
    assert "failed:" in proc.stderr  # a draft was rejected by the checks, then repaired
    (run_dir,) = list((tmp_path / "runs" / domain).iterdir())
    assert (run_dir / "report.html").is_file()
    gates = [e for e in _events(run_dir) if e["event"] == "gate"]
    assert [g["passed"] for g in gates] == [True] and len(gates[0]["trials"]) == 1


# The committed reference transcripts still answer today's prompts.
#
# A first attempt's request depends only on the prompt templates, the toolbox documentation, the
# domain context (task, cameras, meshes, reference images) and the frozen sources of the
# function's dependencies, all of which are known without running a check. So a change to any of
# them that would make `rivet author DOMAIN --strict` refuse the transcript fails here in seconds,
# without Docker, and says what to do — instead of after minutes of replayed checks.
@pytest.mark.parametrize("name", _transcript_domains())
def test_first_attempts_match_the_current_prompts(name):
    domain = domains.load(name)
    transcript = Transcript.load(domain.reference_transcript)
    ctx = build_context(domain, reference_observations(domain), toolbox_docs())
    frozen = {}
    for function in FUNCTIONS:
        entries = [e for e in transcript.entries if e.function == function]
        assert entries, f"{name}: the transcript has no response for {function}"
        first = min(entries, key=lambda e: e.attempt)
        assert first.attempt == 1
        request = build_request(ctx, function, 1, frozen=frozen)
        assert request.hash == first.request_hash, (
            f"{name}: the prompt for {function} attempt 1 changed since the reference transcript "
            f"was packed; re-pack it (rivet transcript pack {name} domains/{name}/programs) and "
            f"re-freeze (make author DOMAIN={name})"
        )
        last = max(entries, key=lambda e: e.attempt)
        frozen[function] = extract_draft(transcript.texts[last.file], function)
