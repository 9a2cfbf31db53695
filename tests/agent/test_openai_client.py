"""The OpenAI-compatible client with the real `openai` SDK against a fake server on 127.0.0.1."""

from __future__ import annotations

import base64
import re
import time

import pytest

from agent.clients import Budget, ImageBlock, ModelRequest, OpenAIClient, TextBlock, _http
from agent.errors import (
    AgentError,
    ApiUnreachable,
    BudgetExceeded,
    ContextWindowExceeded,
    ModelRefused,
)
from contracts.errors import UsageError

from .fake_model_server import FakeModelServer, Json, closed_port_url, openai_completion, openai_sse

PNG = bytes.fromhex(
    "89504e470d0a1a0a0000000d4948445200000001000000010806000000"
    "1f15c4890000000d49444154789c6360000002000154a24f5d0000000049454e44ae426082"
)
REQUEST = ModelRequest(
    function="render",
    attempt=1,
    system=(TextBlock(text="rules", cache=True), TextBlock(text="more rules")),
    content=(TextBlock(text="task"), ImageBlock(png=PNG, caption="start"), TextBlock(text="go")),
    max_tokens=1000,
)
FAST = _http.RetryPolicy(initial_backoff_s=0.01, max_backoff_s=0.05)


def oai_error(
    status: int, message: str, kind: str = "invalid_request_error", code=None, headers=None
) -> Json:
    return Json(status, {"error": {"message": message, "type": kind, "code": code}}, headers or {})


@pytest.fixture(autouse=True)
def _env(monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    monkeypatch.delenv("OPENAI_BASE_URL", raising=False)


_MADE: list[OpenAIClient] = []


@pytest.fixture(autouse=True)
def _close_clients():
    yield
    while _MADE:
        _MADE.pop().close()


@pytest.fixture
def server():
    with FakeModelServer() as s:
        yield s


def client(server, lines=None, **kw) -> OpenAIClient:
    kw.setdefault("retry", FAST)
    made = OpenAIClient(
        "openai:local-vlm",
        base_url=f"{server.url}/v1",
        progress=(lines.append if lines is not None else lambda _: None),
        **kw,
    )
    _MADE.append(made)
    return made


def chat(server) -> list:
    return server.calls("chat")


def test_chat_completion_with_image_parts_streamed(server):
    response = client(server).complete(REQUEST)
    [call] = chat(server)
    body = call.body
    assert call.path == "/v1/chat/completions"
    assert body["model"] == "local-vlm" and body["max_tokens"] == 1000
    assert body["stream"] is True and body["stream_options"] == {"include_usage": True}
    system, user = body["messages"]
    assert system == {"role": "system", "content": "rules\n\nmore rules"}
    parts = user["content"]
    assert [p["type"] for p in parts] == ["text", "image_url", "text"]
    url = parts[1]["image_url"]["url"]
    assert (
        url.startswith("data:image/png;base64,") and base64.b64decode(url.split(",", 1)[1]) == PNG
    )
    assert call.headers["authorization"] == "Bearer EMPTY"  # no key: a local server
    assert "def render" in response.text and response.stop_reason == "end_turn"
    assert (response.usage.input_tokens, response.usage.output_tokens) == (1200, 80)
    assert response.usage.usd == 0.0  # unknown price


def test_the_key_comes_from_openai_api_key(server, monkeypatch):
    monkeypatch.setenv("OPENAI_API_KEY", "sk-test-local-123")
    client(server).complete(REQUEST)
    assert chat(server)[0].headers["authorization"] == "Bearer sk-test-local-123"


def test_non_streaming_mode(server):
    response = client(server, stream=False).complete(REQUEST)
    assert "def render" in response.text and "stream" not in chat(server)[0].body


def test_length_means_cut_off(server):
    server.script["chat"].append(openai_sse("```python\ndef render(", finish_reason="length"))
    response = client(server).complete(REQUEST)
    assert response.truncated and response.stop_reason == "max_tokens"


def test_content_filter_is_a_refusal(server):
    server.script["chat"].append(openai_sse("", finish_reason="content_filter"))
    with pytest.raises(ModelRefused, match="refused to answer render attempt 1"):
        client(server).complete(REQUEST)


def test_context_length_is_a_clear_error_not_retried(server):
    server.script["chat"].append(
        oai_error(
            400,
            "This model's maximum context length is 8192 tokens. However, you requested 9000 tokens.",
        )
    )
    with pytest.raises(ContextWindowExceeded, match="does not fit local-vlm's context window"):
        client(server).complete(REQUEST)
    assert len(chat(server)) == 1


def test_transient_errors_are_retried(server):
    server.script["chat"] += [
        oai_error(503, "busy", "server_error"),
        oai_error(500, "oops", "server_error"),
    ]
    lines: list[str] = []
    assert "def render" in client(server, lines).complete(REQUEST).text
    assert len(chat(server)) == 3 and sum("HTTP 50" in line for line in lines) == 2


def test_429_retry_after_is_honoured_and_capped(server):
    server.script["chat"].append(
        oai_error(429, "slow down", "rate_limit_error", headers={"retry-after": "1"})
    )
    t0 = time.monotonic()
    client(server).complete(REQUEST)
    assert time.monotonic() - t0 >= 0.95
    server.script["chat"].append(
        oai_error(429, "later", "rate_limit_error", headers={"retry-after": "9999"})
    )
    t0 = time.monotonic()
    client(server, retry=_http.RetryPolicy(retry_after_cap_s=0.2)).complete(REQUEST)
    assert time.monotonic() - t0 < 5


def test_a_stream_cut_off_is_retried(server):
    server.script["chat"].append(openai_sse(cut_after=2))
    assert "def render" in client(server).complete(REQUEST).text
    assert len(chat(server)) == 2


def test_max_completion_tokens_when_the_server_asks_for_it(server):
    server.script["chat"].append(
        oai_error(
            400,
            "Unsupported parameter: 'max_tokens' is not supported with this model. Use 'max_completion_tokens' instead.",
        )
    )
    c = client(server)
    c.complete(REQUEST)
    first, second = chat(server)
    assert "max_tokens" in first.body and second.body["max_completion_tokens"] == 1000
    assert "max_tokens" not in second.body
    c.complete(REQUEST)
    assert chat(server)[2].body["max_completion_tokens"] == 1000  # remembered


def test_effort_is_reasoning_effort(server):
    client(server, effort="low").complete(REQUEST)
    assert chat(server)[0].body["reasoning_effort"] == "low"


def test_unreachable_server_fails_with_one_message_naming_the_url():
    url = closed_port_url() + "/v1"
    lines: list[str] = []
    t0 = time.monotonic()
    with pytest.raises(
        ApiUnreachable, match=re.escape(f"cannot reach the OpenAI-compatible API at {url}")
    ):
        OpenAIClient("openai:m", base_url=url, progress=lines.append).complete(REQUEST)
    assert time.monotonic() - t0 < 10 and lines == []


# ------------------------------------------------------------------------------ prices


def test_max_usd_needs_a_price():
    with pytest.raises(
        UsageError, match=r"price of openai:local-vlm is unknown; pass --price IN,OUT"
    ):
        OpenAIClient("openai:local-vlm", base_url="http://127.0.0.1:9/v1", budget=Budget(max_usd=1))


def test_with_a_price_usage_is_priced_and_the_budget_checked_before_any_call(server):
    lines: list[str] = []
    c = client(server, lines, price=(2.0, 8.0), budget=Budget(max_usd=1.0))
    response = c.complete(REQUEST)
    assert response.usage.usd == pytest.approx((1200 * 2 + 80 * 8) / 1e6)
    assert c.budget.spent_usd == pytest.approx(response.usage.usd)
    assert sum("cannot count tokens" in line for line in lines) == 1
    tight = client(server, price=(2.0, 8.0), budget=Budget(max_usd=0.005))  # 1000 × $8/M = $0.008
    n = len(server.requests)
    with pytest.raises(BudgetExceeded, match="the answer alone could cost"):
        tight.complete(REQUEST)
    assert len(server.requests) == n


def test_missing_usage_is_estimated_and_said_once(server):
    server.script["chat"] += [openai_sse(include_usage=False), openai_sse(include_usage=False)]
    lines: list[str] = []
    c = client(server, lines, price=(1.0, 1.0))
    r = c.complete(REQUEST)
    c.complete(REQUEST)
    assert r.usage.input_tokens > 0 and r.usage.output_tokens > 0
    assert sum("reported no token usage" in line for line in lines) == 1


# ------------------------------------------------------------------------------ guards


def test_tests_cannot_reach_a_real_endpoint(monkeypatch):
    monkeypatch.setenv("OPENAI_API_KEY", "sk-x")
    with pytest.raises(AgentError, match="forbidden"):
        OpenAIClient("openai:gpt-x")
    with pytest.raises(AgentError, match="forbidden"):
        OpenAIClient("openai:m", base_url="https://llm.example.com/v1")


def test_openai_itself_needs_a_key():
    import httpx2 as httpx

    with httpx.Client() as hc, pytest.raises(AgentError, match="OPENAI_API_KEY is not set"):
        OpenAIClient("openai:gpt-x", http_client=hc)


def test_the_json_answer_of_a_non_streaming_server(server):
    server.script["chat"].append(
        Json(200, openai_completion("```python\ndef render():\n    pass\n```"))
    )
    assert "def render" in client(server, stream=False).complete(REQUEST).text
