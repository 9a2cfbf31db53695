"""Record → replay round trip; strict mode; drift warnings; transcript provenance."""

from __future__ import annotations

import json

import pytest

from agent.clients import Author, RecordingClient, ReplayClient, ScriptedClient
from agent.errors import ReplayMismatch, TranscriptError
from agent.journal import Journal
from agent.loop import AuthoringRun
from agent.prompt import DomainContext
from contracts.functions import authoring_order

from .conftest import CONTEXT, bad, good

ORDER = authoring_order()


def author(tmp_path, client, checker, name="run", ctx=CONTEXT):
    return AuthoringRun(
        ctx=ctx,
        client=client,
        checker=checker,
        journal=Journal(tmp_path / name),
        progress=lambda _: None,
    ).run()


def record(tmp_path, checker):
    people = Author(kind="people", names=("RIVET team",), note="hand-written reference programs")
    inner = ScriptedClient(
        [good("render"), bad("perceive"), good("perceive"), good("relate"), good("plan")]
    )
    rec = RecordingClient(inner, tmp_path / "transcript", domain="toy", author=people)
    return author(tmp_path, rec, checker, "recorded")


def test_recorded_transcript_is_readable_and_says_who_wrote_it(tmp_path, checker):
    record(tmp_path, checker)
    meta = json.loads((tmp_path / "transcript" / "meta.json").read_text())
    assert meta["written_by"] == {
        "kind": "people",
        "names": ["RIVET team"],
        "note": "hand-written reference programs",
    }
    files = sorted(p.name for p in (tmp_path / "transcript").glob("*.md"))
    assert files == [
        "01-render-attempt1.md",
        "02-perceive-attempt1.md",
        "03-perceive-attempt2.md",
        "04-relate-attempt1.md",
        "05-plan-attempt1.md",
    ]
    assert (
        "return {'ok': False}" in (tmp_path / "transcript" / "02-perceive-attempt1.md").read_text()
    )


@pytest.mark.parametrize("strict", [False, True])
def test_replay_reproduces_the_recorded_run(tmp_path, checker, strict):
    frozen = record(tmp_path, checker)
    replay = ReplayClient(tmp_path / "transcript", strict=strict)
    assert author(tmp_path, replay, checker, "replayed") == frozen
    assert replay.author.kind == "people"
    assert replay.drifted == []


def test_strict_replay_fails_on_prompt_drift_and_default_warns(tmp_path, checker, capsys):
    record(tmp_path, checker)
    drifted = DomainContext(**{**CONTEXT.__dict__, "task": "Stack the blocks, carefully."})
    with pytest.raises(
        ReplayMismatch, match="strict replay: no recorded response for render attempt 1"
    ):
        author(
            tmp_path, ReplayClient(tmp_path / "transcript", strict=True), checker, "strict", drifted
        )
    lenient = ReplayClient(tmp_path / "transcript")
    author(tmp_path, lenient, checker, "lenient", drifted)
    assert ("render", 1) in lenient.drifted
    assert "prompt for render attempt 1 drifted" in capsys.readouterr().err


def test_replay_without_a_response_fails_clearly(tmp_path, checker):
    record(tmp_path, checker)
    meta_path = tmp_path / "transcript" / "meta.json"
    meta = json.loads(meta_path.read_text())
    meta["responses"] = [r for r in meta["responses"] if r["function"] != "plan"]
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(ReplayMismatch, match="holds no response for plan attempt 1"):
        author(tmp_path, ReplayClient(tmp_path / "transcript"), checker, "short")


def test_malformed_transcripts_are_usage_errors(tmp_path):
    with pytest.raises(TranscriptError, match=r"no meta\.json"):
        ReplayClient(tmp_path)
    (tmp_path / "meta.json").write_text(
        json.dumps({"format": "rivet-transcript/1", "domain": "toy"})
    )
    with pytest.raises(TranscriptError, match="malformed"):
        ReplayClient(tmp_path)
