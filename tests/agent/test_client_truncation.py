"""Answers cut off at max_tokens, failed calls in the ledger: the loop and the journal."""

from __future__ import annotations

import json

import pytest

from agent.clients import (
    AnthropicClient,
    ModelResponse,
    RecordingClient,
    ReplayClient,
    ScriptedClient,
    Usage,
    _http,
)
from agent.errors import ModelRefused
from agent.journal import Journal
from agent.loop import DEFAULT_MAX_TOKENS, MAX_TOKENS_CAP, AuthoringRun, next_max_tokens
from contracts.functions import authoring_order

from .conftest import CONTEXT, good
from .fake_model_server import FakeModelServer, anthropic_sse

ORDER = authoring_order()
CUT = "Here is the module.\n\n```python\ndef render():\n    points = [1, 2,"


def cut(text: str = CUT) -> ModelResponse:
    return ModelResponse(text=text, model="scripted", stop_reason="max_tokens")


def run(tmp_path, client, checker, name="run", **kw):
    return AuthoringRun(
        ctx=CONTEXT,
        client=client,
        checker=checker,
        journal=Journal(tmp_path / name),
        progress=lambda _: None,
        **kw,
    )


def test_the_limit_doubles_up_to_the_cap():
    assert DEFAULT_MAX_TOKENS == 16000 and MAX_TOKENS_CAP == 64000
    assert [next_max_tokens(n) for n in (16000, 32000, 64000)] == [32000, 64000, 64000]
    assert next_max_tokens(50000) == 64000


def test_a_cut_off_answer_is_told_so_and_the_next_attempt_may_write_more(tmp_path, checker):
    client = ScriptedClient([cut(), good("render")] + [good(f) for f in ORDER[1:]])
    r = run(tmp_path, client, checker)
    r.run()
    first, repair = client.requests[0], client.requests[1]
    assert (first.max_tokens, repair.max_tokens) == (16000, 32000)
    text = repair.text()
    assert "your answer was cut off" in text and "output limit of 16000 tokens" in text
    assert "up to 32000 tokens" in text
    assert "holds no ```python code block" not in text
    assert r.history[0].report["first_failure"] == "response_complete"
    assert [q.max_tokens for q in client.requests[2:]] == [16000] * 3  # per function
    from contracts import validate

    validate("check_report", r.history[0].report)


def test_repeated_cut_offs_stop_at_the_cap(tmp_path, checker):
    client = ScriptedClient([cut()] * 4 + [good("render")] + [good(f) for f in ORDER[1:]])
    run(tmp_path, client, checker, max_attempts=5).run()
    assert [q.max_tokens for q in client.requests[:5]] == [16000, 32000, 64000, 64000, 64000]
    assert "is already the most an answer may use" in client.requests[4].text()


def test_a_cut_off_answer_with_a_complete_block_is_still_checked(tmp_path, checker):
    text = good("render") + "\n\nA note on the design: the points are"
    client = ScriptedClient([cut(text)] + [good(f) for f in ORDER[1:]])
    r = run(tmp_path, client, checker)
    r.run()
    assert r.history[0].passed


def test_resume_rebuilds_the_larger_limit_from_the_journal(tmp_path, checker):
    first = ScriptedClient([cut(), BrokenPipeError("killed")])
    with pytest.raises(BrokenPipeError):
        run(tmp_path, first, checker).run()
    events = Journal(tmp_path / "run").events()
    response = next(e for e in events if e["event"] == "response")
    assert response["stop_reason"] == "max_tokens" and response["max_tokens"] == 16000
    second = ScriptedClient([good("render")] + [good(f) for f in ORDER[1:]])
    run(tmp_path, second, checker).run()
    assert (second.requests[0].attempt, second.requests[0].max_tokens) == (2, 32000)
    assert second.requests[0].hash == first.requests[1].hash  # the same request as before


def test_a_failed_call_with_known_usage_joins_the_ledger(tmp_path, checker):
    refused = ModelRefused(
        "the model refused", usage=Usage(input_tokens=900, output_tokens=3, usd=0.25)
    )
    client = ScriptedClient([good("render"), refused])
    with pytest.raises(ModelRefused):
        run(tmp_path, client, checker).run()
    journal = Journal(tmp_path / "run")
    failed = [e for e in journal.events() if e["event"] == "call_failed"]
    assert len(failed) == 1 and failed[0]["usage"]["usd"] == 0.25
    assert "ModelRefused: the model refused" in failed[0]["error"]
    st = journal.state()
    assert st.spent_usd == pytest.approx(0.25) and st.calls == 2


def test_through_the_wire_the_next_request_asks_for_more(tmp_path, checker, monkeypatch):
    """A real SDK call whose answer stops at max_tokens; the repair asks with 32000; the
    transcript (stop_reason kept) replays strictly."""
    monkeypatch.setenv("ANTHROPIC_API_KEY", "sk-ant-test-not-a-key")
    with FakeModelServer() as server:
        server.script["messages"] += [anthropic_sse(CUT, stop_reason="max_tokens")] + [
            anthropic_sse(good(f)) for f in ORDER
        ]
        inner = AnthropicClient(
            base_url=server.url,
            progress=lambda _: None,
            retry=_http.RetryPolicy(initial_backoff_s=0.01),
        )
        rec = RecordingClient(inner, tmp_path / "transcript", domain="toy")
        frozen = run(tmp_path, rec, checker).run()
        rec.close()
        sent = [c.body["max_tokens"] for c in server.calls("messages")]
        assert sent == [16000, 32000, 16000, 16000, 16000]
    meta = json.loads((tmp_path / "transcript" / "meta.json").read_text())
    assert meta["responses"][0]["stop_reason"] == "max_tokens"
    again = run(
        tmp_path, ReplayClient(tmp_path / "transcript", strict=True), checker, name="replay"
    ).run()
    assert again == frozen


def test_bad_drafts_still_say_no_code_block_when_not_cut_off(tmp_path, checker):
    client = ScriptedClient(["no code here", good("render")] + [good(f) for f in ORDER[1:]])
    run(tmp_path, client, checker).run()
    assert "holds no ```python code block" in client.requests[1].text()
    assert client.requests[1].max_tokens == 16000
