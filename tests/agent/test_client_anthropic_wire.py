"""The Anthropic client with the real `anthropic` SDK against a fake API on 127.0.0.1: streaming,
stop reasons, retries, timeouts, token counting, credentials, thinking, the budget."""

from __future__ import annotations

import re
import time

import pytest

from agent.clients import AnthropicClient, Budget, ImageBlock, ModelRequest, TextBlock, _http
from agent.errors import (
    AgentError,
    ApiUnreachable,
    BudgetExceeded,
    ContextWindowExceeded,
    ModelRefused,
)

from .fake_model_server import (
    Blackhole,
    Close,
    FakeModelServer,
    Json,
    anthropic_error,
    anthropic_message,
    anthropic_sse,
    closed_port_url,
)

KEY = "sk-ant-test-not-a-key-7f3a"
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
FAST = _http.RetryPolicy(initial_backoff_s=0.01, max_backoff_s=0.05)


@pytest.fixture(autouse=True)
def _env(monkeypatch):
    monkeypatch.setenv("ANTHROPIC_API_KEY", KEY)
    monkeypatch.delenv("ANTHROPIC_AUTH_TOKEN", raising=False)
    monkeypatch.delenv("ANTHROPIC_BASE_URL", raising=False)


_MADE: list[AnthropicClient] = []


@pytest.fixture(autouse=True)
def _close_clients():
    yield
    while _MADE:
        _MADE.pop().close()


@pytest.fixture
def server():
    with FakeModelServer() as s:
        yield s


def client(server_or_url, lines=None, **kw) -> AnthropicClient:
    url = server_or_url if isinstance(server_or_url, str) else server_or_url.url
    kw.setdefault("retry", FAST)
    made = AnthropicClient(
        base_url=url, progress=(lines.append if lines is not None else lambda _: None), **kw
    )
    _MADE.append(made)
    return made


def messages(server) -> list:
    return server.calls("messages")


# ------------------------------------------------------------------------------ streaming


def test_streams_the_answer_with_images_cache_marks_and_priced_usage(server):
    lines: list[str] = []
    c = client(server, lines, budget=Budget(max_usd=5.0))
    response = c.complete(REQUEST)
    [call] = messages(server)
    body = call.body
    assert body["stream"] is True and body["max_tokens"] == 1000
    assert body["system"][0]["cache_control"] == {"type": "ephemeral"}
    image = body["messages"][0]["content"][1]
    assert image["type"] == "image" and image["source"]["media_type"] == "image/png"
    assert KEY in (call.headers.get("x-api-key", "") + call.headers.get("authorization", ""))
    assert "def render" in response.text and response.stop_reason == "end_turn"
    assert not response.truncated
    u = response.usage
    expected = (100 * 5 + 50 * 25 + 1000 * 5 * 1.25 + 2000 * 5 * 0.1) / 1e6
    assert u.usd == pytest.approx(expected) and c.budget.spent_usd == pytest.approx(expected)
    assert c.budget.calls == 1


def test_progress_while_a_long_answer_streams(server):
    slow = anthropic_sse("```python\ndef render():\n    return 1\n```", pieces=6)
    slow.delay_s = 0.06
    server.script["messages"].append(slow)
    lines: list[str] = []
    client(server, lines, progress_every_s=0.1).complete(REQUEST)
    ticks = [line for line in lines if "render attempt 1:" in line]
    assert ticks, lines
    assert all(
        re.search(r"(~\d+ tokens so far|waiting for the first token), \d+ s$", line)
        for line in ticks
    )


def test_non_streaming_mode_reads_one_json_message(server):
    response = client(server, stream=False).complete(REQUEST)
    assert "def render" in response.text
    assert "stream" not in messages(server)[0].body


def test_thinking_text_is_not_part_of_the_answer(server):
    server.script["messages"].append(
        anthropic_sse("```python\ndef render():\n    pass\n```", thinking="let me think")
    )
    response = client(server).complete(REQUEST)
    assert "let me think" not in response.text and "def render" in response.text


# ------------------------------------------------------------------------------ stop reasons


def test_max_tokens_marks_the_response_truncated(server):
    server.script["messages"].append(
        anthropic_sse("```python\ndef render():\n    x = [", stop_reason="max_tokens")
    )
    response = client(server).complete(REQUEST)
    assert response.truncated and response.stop_reason == "max_tokens"


def test_a_refusal_is_a_clear_error_and_its_usage_is_counted(server):
    server.script["messages"].append(
        anthropic_sse("I can't help with that.", stop_reason="refusal")
    )
    c = client(server, budget=Budget(max_usd=5.0))
    with pytest.raises(
        ModelRefused, match=r"refused to answer render attempt 1 \(stop_reason: refusal\)"
    ) as info:
        c.complete(REQUEST)
    assert info.value.usage is not None and info.value.usage.usd > 0
    assert c.budget.spent_usd == pytest.approx(info.value.usage.usd) and c.budget.calls == 1
    assert len(messages(server)) == 1  # not retried


def test_a_prompt_over_the_context_window_is_a_clear_error_not_retried(server):
    server.script["messages"].append(
        anthropic_error(
            400, "invalid_request_error", "prompt is too long: 250000 tokens > 200000 maximum"
        )
    )
    with pytest.raises(
        ContextWindowExceeded,
        match=r"does not fit claude-opus-5's context window: .*prompt is too long",
    ):
        client(server).complete(REQUEST)
    assert len(messages(server)) == 1


def test_the_context_window_filling_during_the_answer_is_a_clear_error(server):
    server.script["messages"].append(
        anthropic_sse("partial", stop_reason="model_context_window_exceeded")
    )
    with pytest.raises(
        ContextWindowExceeded, match="filled claude-opus-5's context window"
    ) as info:
        client(server).complete(REQUEST)
    assert info.value.usage is not None


# ------------------------------------------------------------------------------ retries


def test_529_twice_then_200_succeeds(server):
    busy = anthropic_error(529, "overloaded_error", "Overloaded")
    server.script["messages"] += [busy, busy]
    lines: list[str] = []
    response = client(server, lines).complete(REQUEST)
    assert "def render" in response.text
    assert len(messages(server)) == 3
    assert sum("HTTP 529 overloaded_error" in line for line in lines) == 2


def test_429_retry_after_is_honoured(server):
    server.script["messages"].append(
        anthropic_error(429, "rate_limit_error", "slow down", {"retry-after": "1"})
    )
    t0 = time.monotonic()
    client(server).complete(REQUEST)
    assert time.monotonic() - t0 >= 0.95
    assert len(messages(server)) == 2


def test_a_huge_retry_after_is_capped(server):
    server.script["messages"].append(
        anthropic_error(429, "rate_limit_error", "come back tomorrow", {"retry-after": "86400"})
    )
    lines: list[str] = []
    t0 = time.monotonic()
    client(server, lines, retry=_http.RetryPolicy(retry_after_cap_s=0.3)).complete(REQUEST)
    assert time.monotonic() - t0 < 5
    assert any("the server asked for 86400 s; waiting at most 0.3 s" in line for line in lines), (
        lines
    )
    assert _http.RETRY_AFTER_CAP_S == 60.0  # the default cap


def test_a_stream_cut_off_mid_way_is_retried_and_its_usage_counted(server):
    server.script["messages"].append(anthropic_sse(cut_after=4))
    c = client(server, budget=Budget(max_usd=5.0))
    response = c.complete(REQUEST)
    assert len(messages(server)) == 2
    # the broken attempt reported its input (message_start) and 1 output token
    assert response.usage.input_tokens == 200 and response.usage.output_tokens == 51
    assert c.budget.spent_usd == pytest.approx(response.usage.usd) and c.budget.calls == 1


def test_a_dropped_connection_is_retried(server):
    server.script["messages"].append(Close())
    assert "def render" in client(server).complete(REQUEST).text
    assert len(messages(server)) == 2


def test_persistent_overload_fails_clearly(server):
    server.script["messages"] += [anthropic_error(529, "overloaded_error", "Overloaded")] * 4
    with pytest.raises(
        AgentError,
        match=r"render attempt 1: .* answered HTTP 529 overloaded_error: Overloaded \(after 3 tries",
    ):
        client(server, retry=_http.RetryPolicy(max_retries=2, initial_backoff_s=0.01)).complete(
            REQUEST
        )


def test_budget_is_rechecked_before_a_retry(server):
    # the first attempt breaks after costing something; the retry no longer fits the budget
    server.script["messages"].append(
        anthropic_sse(
            usage={
                "input_tokens": 60000,
                "output_tokens": 50,
                "cache_creation_input_tokens": 0,
                "cache_read_input_tokens": 0,
            },
            cut_after=2,
        )
    )
    c = client(server, budget=Budget(max_usd=0.33))  # worst case ≈ $0.044 + $0.025 at first
    with pytest.raises(BudgetExceeded, match="could cost up to") as info:
        c.complete(REQUEST)
    assert len(messages(server)) == 1
    assert c.budget.spent_usd == pytest.approx(60000 * 5 / 1e6 + 1 * 25 / 1e6)
    assert info.value.usage.usd == pytest.approx(c.budget.spent_usd)  # for the journal
    assert c.budget.calls == 1


# ------------------------------------------------------------------------------ no connection


def test_a_refused_connection_fails_fast_with_one_message_naming_the_url():
    url = closed_port_url()
    lines: list[str] = []
    t0 = time.monotonic()
    with pytest.raises(ApiUnreachable) as info:
        AnthropicClient(base_url=url, progress=lines.append, budget=Budget(max_usd=5)).complete(
            REQUEST
        )
    assert time.monotonic() - t0 < 10
    message = str(info.value)
    assert f"cannot reach the Anthropic API at {url}" in message and "--base-url" in message
    assert "token count" not in message and "Connection error." not in message
    assert lines == []  # nothing else was said: the error is the one message


def test_an_endpoint_that_accepts_no_connection_fails_within_the_connect_deadline():
    with Blackhole() as hole:
        t0 = time.monotonic()
        policy = _http.RetryPolicy(connect_deadline_s=2.0)
        with pytest.raises(ApiUnreachable, match=re.escape(hole.url)) as info:
            AnthropicClient(
                base_url=hole.url,
                connect_timeout_s=0.4,
                retry=policy,
                progress=lambda _: None,
                budget=Budget(max_usd=5),
            ).complete(REQUEST)
        assert time.monotonic() - t0 < 2.0 + 0.5
        assert "timed out" in str(info.value)


def test_the_default_connect_bounds_keep_a_dead_endpoint_under_30_s(monkeypatch):
    """With the defaults (5 s connects, 30 s deadline) the worst case, every connect timing
    out, ends within 30 s: checked on a simulated clock."""
    now = [0.0]
    monkeypatch.setattr(_http.time, "monotonic", lambda: now[0])
    monkeypatch.setattr(_http.time, "sleep", lambda s: now.__setitem__(0, now[0] + s))
    tries = []

    def attempt():
        tries.append(now[0])
        now[0] += _http.CONNECT_TIMEOUT_S
        raise TimeoutError

    with pytest.raises(RuntimeError):
        _http.call_with_retries(
            attempt,
            classify=lambda e: _http.Failure(kind="connect", message="timed out", retryable=True),
            give_up=lambda f, n, t, e: RuntimeError(f"gave up after {n} tries, {t} s"),
            policy=_http.RetryPolicy(),
            say=lambda _: None,
            connect_timeout_s=_http.CONNECT_TIMEOUT_S,
            started=0.0,
        )
    assert now[0] <= 30.0 and len(tries) >= 2


# ------------------------------------------------------------------------------ token counting


@pytest.mark.parametrize("status", [404, 405, 501])
def test_an_endpoint_without_count_tokens_is_budgeted_from_an_estimate_said_once(status):
    with FakeModelServer() as server:
        server.script["count_tokens"].append(anthropic_error(status, "not_found_error", "no"))
        lines: list[str] = []
        c = client(server, lines, budget=Budget(max_usd=5.0))
        c.complete(REQUEST)
        c.complete(REQUEST)
        assert len(server.calls("count_tokens")) == 1  # not asked again
        notes = [line for line in lines if "token-count route" in line]
        assert len(notes) == 1 and f"HTTP {status}" in notes[0] and "estimate" in notes[0]


def test_count_tokens_only_under_a_dollar_budget(server):
    client(server).complete(REQUEST)
    assert server.calls("count_tokens") == []


# ------------------------------------------------------------------------------ budget


def test_the_answer_alone_over_budget_is_refused_before_any_network_call(server):
    c = client(server, budget=Budget(max_usd=0.02))  # 1000 output tokens cost $0.025
    with pytest.raises(BudgetExceeded, match=r"the answer alone could cost up to \$0.03"):
        c.complete(REQUEST)
    assert server.requests == []


def test_the_estimated_input_over_budget_is_refused_before_any_network_call(server):
    big = ModelRequest(
        function="render",
        attempt=1,
        system=(TextBlock(text="x" * 35000),),
        content=(),
        max_tokens=1000,
    )
    c = client(server, budget=Budget(max_usd=0.06))  # ≈ 10000 input tokens ×1.25 = $0.0625 + $0.025
    with pytest.raises(BudgetExceeded, match="could cost up to"):
        c.complete(big)
    assert server.requests == []


def test_the_exact_count_tightens_the_check(server):
    server.count_tokens = 3100  # worst case: 3100 × $5/M × 1.25 + 1000 × $25/M ≈ $0.044
    c = client(server, budget=Budget(max_usd=0.03))
    with pytest.raises(BudgetExceeded, match="could cost up to"):
        c.complete(REQUEST)
    assert messages(server) == [] and len(server.calls("count_tokens")) == 1


# ------------------------------------------------------------------------------ credentials, options


def test_auth_token_is_sent_as_a_bearer(server, monkeypatch):
    monkeypatch.delenv("ANTHROPIC_API_KEY")
    monkeypatch.setenv("ANTHROPIC_AUTH_TOKEN", "gateway-token-1")
    client(server).complete(REQUEST)
    headers = messages(server)[0].headers
    assert headers["authorization"] == "Bearer gateway-token-1"
    assert KEY not in str(headers)


def test_base_url_from_the_environment(server, monkeypatch):
    monkeypatch.setenv("ANTHROPIC_BASE_URL", server.url)
    made = AnthropicClient(progress=lambda _: None)
    _MADE.append(made)
    made.complete(REQUEST)
    assert len(messages(server)) == 1


def test_no_credentials_is_a_clear_error(monkeypatch):
    monkeypatch.delenv("ANTHROPIC_API_KEY")
    with pytest.raises(AgentError, match="ANTHROPIC_API_KEY is not set"):
        AnthropicClient(base_url="http://127.0.0.1:9")


def test_tests_cannot_reach_a_real_endpoint():
    with pytest.raises(AgentError, match="forbidden"):
        AnthropicClient()
    with pytest.raises(AgentError, match="forbidden"):
        AnthropicClient(base_url="https://gateway.example.com")


def test_the_key_is_never_in_messages_or_progress(server):
    server.script["messages"] += [anthropic_error(529, "overloaded_error", "busy")] * 3
    server.script["messages"].append(
        anthropic_error(401, "authentication_error", "invalid x-api-key")
    )
    lines: list[str] = []
    with pytest.raises(AgentError) as info:
        client(server, lines).complete(REQUEST)
    assert "ANTHROPIC_API_KEY or ANTHROPIC_AUTH_TOKEN" in str(info.value)
    assert KEY not in str(info.value) and not any(KEY in line for line in lines)


def test_thinking_budget_is_sent_and_added_to_max_tokens(server):
    client(server, thinking_budget=2048).complete(REQUEST)
    body = messages(server)[0].body
    assert body["thinking"] == {"type": "enabled", "budget_tokens": 2048}
    assert body["max_tokens"] == 1000 + 2048


def test_effort_is_adaptive_thinking_with_headroom(server):
    client(server, effort="high").complete(REQUEST)
    body = messages(server)[0].body
    assert body["thinking"] == {"type": "adaptive"} and body["output_config"] == {"effort": "high"}
    assert body["max_tokens"] == 1000 + 32000


def test_thinking_tokens_count_in_the_worst_case(server):
    # 1000 + 4000 thinking tokens at $25/M = $0.125 > $0.1: refused, although 1000 alone fits
    with pytest.raises(BudgetExceeded, match="max_tokens 5000"):
        client(server, thinking_budget=4000, budget=Budget(max_usd=0.1)).complete(REQUEST)


def test_a_gateway_that_answers_json_to_a_stream_request_still_works(server):
    server.script["messages"].append(
        Json(200, anthropic_message("```python\ndef render():\n    pass\n```"))
    )
    assert "def render" in client(server).complete(REQUEST).text


def test_a_count_route_that_drops_the_connection_is_budgeted_from_an_estimate(server):
    server.script["count_tokens"] += [Close(), Close()]
    lines: list[str] = []
    c = client(server, lines, budget=Budget(max_usd=5.0))
    c.complete(REQUEST)
    c.complete(REQUEST)
    assert len(messages(server)) == 2
    notes = [line for line in lines if "token-count route" in line]
    assert len(notes) == 1 and "could not be reached" in notes[0]
