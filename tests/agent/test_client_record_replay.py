"""The new clients record like any other and replay offline, strictly: an OpenAI-compatible
server and Claude through the fake API (the agent command's round trip is in
test_agent_command.py)."""

from __future__ import annotations

import json

import pytest

from agent.clients import AnthropicClient, OpenAIClient, RecordingClient, ReplayClient, _http
from agent.journal import Journal
from agent.loop import AuthoringRun
from contracts.functions import authoring_order

from .conftest import CONTEXT, bad, good
from .fake_model_server import FakeModelServer, anthropic_sse, openai_sse

ORDER = authoring_order()
ANSWERS = [good("render"), bad("perceive"), good("perceive"), good("relate"), good("plan")]


def author(tmp_path, client, checker, name):
    return AuthoringRun(
        ctx=CONTEXT,
        client=client,
        checker=checker,
        journal=Journal(tmp_path / name),
        progress=lambda _: None,
    ).run()


@pytest.mark.parametrize("kind", ["openai", "anthropic"])
def test_record_with_the_fake_server_then_replay_strictly_offline(
    tmp_path, checker, monkeypatch, kind
):
    monkeypatch.setenv("ANTHROPIC_API_KEY", "sk-ant-test-not-a-key")
    fast = _http.RetryPolicy(initial_backoff_s=0.01)
    with FakeModelServer() as server:
        if kind == "openai":
            server.script["chat"] += [openai_sse(a, model="qwen-vl") for a in ANSWERS]
            inner = OpenAIClient(
                "openai:qwen-vl", base_url=f"{server.url}/v1", retry=fast, progress=lambda _: None
            )
        else:
            server.script["messages"] += [anthropic_sse(a) for a in ANSWERS]
            inner = AnthropicClient(base_url=server.url, retry=fast, progress=lambda _: None)
        rec = RecordingClient(inner, tmp_path / "transcript", domain="toy")
        frozen = author(tmp_path, rec, checker, "recorded")
        rec.close()
        asked = len(server.requests)
    assert set(frozen) == set(ORDER)
    meta = json.loads((tmp_path / "transcript" / "meta.json").read_text())
    expected = {"openai": ("openai", "qwen-vl"), "anthropic": ("anthropic", "claude-opus-5")}[kind]
    assert (meta["written_by"]["provider"], meta["written_by"]["model"]) == expected
    assert [(e["function"], e["attempt"]) for e in meta["responses"]] == [
        ("render", 1),
        ("perceive", 1),
        ("perceive", 2),
        ("relate", 1),
        ("plan", 1),
    ]
    assert all(e["request_hash"] for e in meta["responses"])
    assert asked >= 5

    # the server is gone: the replay is offline and strict (every request hash recorded)
    replay = ReplayClient(tmp_path / "transcript", strict=True)
    again = author(tmp_path, replay, checker, "replayed")
    assert again == frozen and replay.drifted == []
    assert replay.author.provider == expected[0]
