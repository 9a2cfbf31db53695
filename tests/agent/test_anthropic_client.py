"""The Anthropic client against the real SDK, with faults injected at the HTTP layer."""

from __future__ import annotations

import json

import httpx2 as httpx
import pytest

from agent.clients import AnthropicClient, Budget, ImageBlock, ModelRequest, TextBlock
from agent.errors import AgentError, BudgetExceeded, ModelCallFailed

PNG = bytes.fromhex(
    "89504e470d0a1a0a0000000d4948445200000001000000010806000000"
    "1f15c4890000000d49444154789c6360000002000154a24f5d0000000049454e44ae426082"
)

REQUEST = ModelRequest(
    function="render",
    attempt=1,
    system=(TextBlock(text="rules", cache=True),),
    content=(TextBlock(text="task"), ImageBlock(png=PNG, caption="start"), TextBlock(text="go")),
    max_tokens=1000,
)


def _message(text="```python\ndef render():\n    pass\n```") -> dict:
    return {
        "id": "msg_1",
        "type": "message",
        "role": "assistant",
        "model": "claude-opus-5",
        "content": [{"type": "text", "text": text}],
        "stop_reason": "end_turn",
        "stop_sequence": None,
        "usage": {
            "input_tokens": 100,
            "output_tokens": 50,
            "cache_creation_input_tokens": 1000,
            "cache_read_input_tokens": 2000,
        },
    }


class Server:
    """A scripted HTTP server behind httpx.MockTransport: faults first, then answers."""

    def __init__(self, faults=()):
        self.faults = list(faults)
        self.requests: list[tuple[str, dict]] = []

    def __call__(self, request: httpx.Request) -> httpx.Response:
        body = json.loads(request.content)
        self.requests.append((request.url.path, body))
        if request.url.path.endswith("/count_tokens"):
            return httpx.Response(200, json={"input_tokens": 3100})
        if self.faults:
            fault = self.faults.pop(0)
            if fault == "timeout":
                raise httpx.ReadTimeout("simulated timeout", request=request)
            return httpx.Response(
                fault,
                headers={"retry-after-ms": "1"},
                json={"type": "error", "error": {"type": "overloaded_error", "message": "busy"}},
            )
        return httpx.Response(200, json=_message())

    def client(self, **kw) -> AnthropicClient:
        return AnthropicClient(http_client=httpx.Client(transport=httpx.MockTransport(self)), **kw)


@pytest.fixture(autouse=True)
def _fake_key(monkeypatch):
    monkeypatch.setenv("ANTHROPIC_API_KEY", "sk-ant-test-not-a-key")


@pytest.mark.parametrize("faults", [[429], [500], [529], ["timeout"], [429, 529, 500]], ids=str)
def test_transient_errors_are_retried(faults):
    server = Server(faults)
    response = server.client().complete(REQUEST)
    assert "def render" in response.text
    assert sum(p.endswith("/v1/messages") for p, _ in server.requests) == len(faults) + 1


def test_persistent_errors_fail_the_call_clearly():
    server = Server([529] * 10)
    with pytest.raises(ModelCallFailed, match=r"InternalServerError|overloaded|529"):
        server.client(max_retries=2).complete(REQUEST)


def test_request_carries_images_and_cache_marks_and_usage_is_priced():
    server = Server()
    client = server.client(budget=Budget(max_usd=5.0))
    response = client.complete(REQUEST)
    _, body = next(r for r in server.requests if r[0].endswith("/v1/messages"))
    assert body["model"] == "claude-opus-5"
    assert body["system"][0]["cache_control"] == {"type": "ephemeral"}
    image = body["messages"][0]["content"][1]
    assert image["type"] == "image" and image["source"]["media_type"] == "image/png"
    u = response.usage
    assert (u.input_tokens, u.output_tokens, u.cache_write_tokens, u.cache_read_tokens) == (
        100,
        50,
        1000,
        2000,
    )
    # $5/M input, $25/M output, writes 1.25x, reads 0.1x
    expected = (100 * 5 + 50 * 25 + 1000 * 5 * 1.25 + 2000 * 5 * 0.1) / 1e6
    assert u.usd == pytest.approx(expected)
    assert client.budget.spent_usd == pytest.approx(expected)


def test_budget_is_checked_before_the_call_from_a_token_count():
    server = Server()
    # worst case: 3100 input tokens written to cache + 1000 output tokens ≈ $0.044
    client = server.client(budget=Budget(max_usd=0.03))
    with pytest.raises(BudgetExceeded, match="could cost up to"):
        client.complete(REQUEST)
    assert not any(p.endswith("/v1/messages") for p, _ in server.requests)


def test_key_only_from_environment(monkeypatch):
    monkeypatch.delenv("ANTHROPIC_API_KEY")
    with pytest.raises(AgentError, match="ANTHROPIC_API_KEY is not set"):
        Server().client()


def test_tests_cannot_reach_a_real_api():
    with pytest.raises(AgentError, match="forbidden"):
        AnthropicClient()


def test_unpriced_model_is_refused_before_any_call():
    with pytest.raises(BudgetExceeded, match="no price known for model 'gpt-x'"):
        Server().client(model="gpt-x")
