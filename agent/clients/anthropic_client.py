"""Claude through the `anthropic` SDK: image blocks, prompt caching, streaming, retries, dollars.

Credentials come from the environment only: `ANTHROPIC_API_KEY` or, when it is unset,
`ANTHROPIC_AUTH_TOKEN` (a bearer token, for gateways), handed to the SDK as such; never an
argument, never logged, never passed to a sandbox. `ANTHROPIC_BASE_URL` (or `base_url`) points
the client at another endpoint.

Each call:
1. refuses before any network call when `max_tokens` at the output price, or that plus the
   locally estimated input (all written to the cache), cannot be covered by `--max-usd`;
2. counts the input tokens (`count_tokens`, only when a dollar budget is set) and checks the
   budget again with the exact count; an endpoint without that route (404/405/501, or no
   connection) is budgeted from the estimate, and says so once;
3. streams the answer, with a progress line every 30 s (tokens so far, seconds);
4. retries 408/409/429/5xx/529 and broken streams (`_http.call_with_retries`: retry-after
   capped at 60 s, connect failures bounded to 30 s in all), re-checking the budget first;
5. prices the usage, failed attempts' known usage included.

`stop_reason: max_tokens` comes back as a truncated response (the loop tells the model and
raises the limit); `refusal` raises `ModelRefused`; a prompt that does not fit raises
`ContextWindowExceeded`. `thinking_budget` (manual extended thinking) or `effort`
(adaptive thinking at that effort) add thinking; thinking tokens count against `max_tokens`,
so the client sends the answer's `max_tokens` plus the thinking budget (or the effort's
headroom, `EFFORT_HEADROOM`).

Setting `RIVET_FORBID_MODEL_API=1` (the test suite does) makes constructing a client fail
unless an `http_client` is injected or the base URL is a loopback address.
"""

from __future__ import annotations

import os
import time
from typing import Any

import anthropic
import httpx2 as httpx

from agent.clients import _http
from agent.clients.base import (
    STOP_MAX_TOKENS,
    Author,
    ImageBlock,
    ModelRequest,
    ModelResponse,
    TextBlock,
    Usage,
)
from agent.clients.pricing import (
    Budget,
    Price,
    cost_usd,
    estimate_input_tokens,
    price_of,
    worst_case_usd,
)
from agent.errors import (
    AgentError,
    BudgetExceeded,
    ContextWindowExceeded,
    ModelCallFailed,
    ModelRefused,
)
from contracts.errors import UsageError

DEFAULT_MODEL = "claude-opus-5"
DEFAULT_BASE_URL = "https://api.anthropic.com"
EFFORTS = ("low", "medium", "high")
# Extra output tokens allowed for adaptive thinking at each effort (max_tokens covers thinking).
EFFORT_HEADROOM = {"low": 4000, "medium": 16000, "high": 32000}
MIN_THINKING_BUDGET = 1024


MISSING_KEY = (
    "ANTHROPIC_API_KEY is not set (nor ANTHROPIC_AUTH_TOKEN): export one to author with a "
    "model, or replay a transcript (rivet author DOMAIN --replay DIR)"
)


class AnthropicClient:
    def __init__(
        self,
        model: str = DEFAULT_MODEL,
        *,
        budget: Budget | None = None,
        max_retries: int = 6,
        timeout_s: float = _http.READ_TIMEOUT_S,
        connect_timeout_s: float = _http.CONNECT_TIMEOUT_S,
        http_client: httpx.Client | None = None,
        base_url: str | None = None,
        stream: bool = True,
        thinking_budget: int | None = None,
        effort: str | None = None,
        price: Price | None = None,
        retry: _http.RetryPolicy | None = None,
        progress: _http.Say | None = None,
        progress_every_s: float = _http.PROGRESS_EVERY_S,
    ) -> None:
        self.base_url = (
            base_url or os.environ.get("ANTHROPIC_BASE_URL") or DEFAULT_BASE_URL
        ).rstrip("/")
        _http.forbid_real_api(self.base_url, injected=http_client is not None)
        key = os.environ.get("ANTHROPIC_API_KEY") or None
        token = None if key else (os.environ.get("ANTHROPIC_AUTH_TOKEN") or None)
        if not key and not token:
            raise AgentError(MISSING_KEY)
        if thinking_budget is not None and effort is not None:
            raise UsageError("--thinking and --effort are exclusive: give one")
        if thinking_budget is not None and thinking_budget < MIN_THINKING_BUDGET:
            raise UsageError(
                f"--thinking {thinking_budget}: the budget must be at least {MIN_THINKING_BUDGET} tokens"
            )
        if effort is not None and effort not in EFFORTS:
            raise UsageError(f"--effort {effort!r}: one of {', '.join(EFFORTS)}")
        self.price = price_of(model, price)  # fail before any call for a model we cannot budget
        self.model = model
        self.budget = budget or Budget()
        self.stream = stream
        self.thinking_budget = thinking_budget
        self.effort = effort
        self.connect_timeout_s = connect_timeout_s
        self.read_timeout_s = timeout_s
        self.retry = retry or _http.RetryPolicy(max_retries=max_retries)
        self.say = progress or _http.stderr_say
        self.progress_every_s = progress_every_s
        self._count_route = True  # False once the endpoint showed it has no count_tokens
        self._said_estimate = False
        self._count_unreachable = False
        self._sdk = anthropic.Anthropic(
            api_key=key,
            auth_token=token,
            max_retries=0,  # ours: _http.call_with_retries
            timeout=_http.timeout(timeout_s, connect_timeout_s),
            http_client=http_client,
            base_url=self.base_url,
        )
        del key, token

    @property
    def author(self) -> Author:
        return Author(kind="model", provider="anthropic", model=self.model)

    def close(self) -> None:
        """Close the HTTP connections (an injected `http_client` included)."""
        self._sdk.close()

    # ------------------------------------------------------------------------------ request

    @staticmethod
    def _block(b: TextBlock | ImageBlock) -> dict[str, Any]:
        if isinstance(b, TextBlock):
            d: dict[str, Any] = {"type": "text", "text": b.text}
            if b.cache:
                d["cache_control"] = {"type": "ephemeral"}
            return d
        return {
            "type": "image",
            "source": {"type": "base64", "media_type": "image/png", "data": b.b64()},
        }

    def _params(self, request: ModelRequest) -> dict[str, Any]:
        return {
            "model": self.model,
            "system": [self._block(b) for b in request.system],
            "messages": [{"role": "user", "content": [self._block(b) for b in request.content]}],
        }

    def _thinking(self) -> dict[str, Any]:
        if self.thinking_budget is not None:
            return {"thinking": {"type": "enabled", "budget_tokens": self.thinking_budget}}
        if self.effort is not None:
            return {"thinking": {"type": "adaptive"}, "output_config": {"effort": self.effort}}
        return {}

    def max_tokens_for(self, request: ModelRequest) -> int:
        """What is sent as `max_tokens`: the answer's limit plus the thinking allowance."""
        if self.thinking_budget is not None:
            return request.max_tokens + self.thinking_budget
        if self.effort is not None:
            return request.max_tokens + EFFORT_HEADROOM[self.effort]
        return request.max_tokens

    # ------------------------------------------------------------------------------ budget

    def _note(self, line: str) -> None:
        if not self._said_estimate:
            self._said_estimate = True
            self.say(line)

    def _input_tokens(self, request: ModelRequest, params: dict[str, Any], estimate: int) -> int:
        """The exact input token count when the endpoint can count, else the estimate."""
        if not self._count_route:
            return estimate
        try:
            counted = self._sdk.messages.count_tokens(
                **params, timeout=_http.timeout(60.0, self.connect_timeout_s)
            )
            return int(counted.input_tokens)
        except anthropic.APIStatusError as e:
            if e.status_code in (404, 405, 501):
                self._count_route = False
                self._note(
                    f"note: {self.base_url} has no token-count route (HTTP {e.status_code}); "
                    f"budgeting from an estimate of the input (~{estimate} tokens for this call: "
                    "characters / 3.5, up to 1600 per image)"
                )
            return estimate
        except anthropic.APIConnectionError:
            # said after the call succeeds: if the endpoint is down, the call's own error is
            # the one message
            self._count_unreachable = True
            return estimate

    # ------------------------------------------------------------------------------ calling

    def complete(self, request: ModelRequest) -> ModelResponse:
        started = time.monotonic()
        params = self._params(request)
        max_tokens = self.max_tokens_for(request)
        _, pout = self.price
        # 1. before any network call: the answer alone, then with the estimated input
        self.budget.check_output(max_tokens, pout)
        estimate = estimate_input_tokens(request)
        self.budget.reserve(worst_case_usd(estimate, max_tokens, self.price))
        # 2. the exact count tightens the check (only worth a round trip under a dollar budget)
        input_tokens = estimate
        if self.budget.max_usd is not None:
            input_tokens = max(estimate, self._input_tokens(request, params, estimate))
            self.budget.reserve(worst_case_usd(input_tokens, max_tokens, self.price))
        worst = worst_case_usd(input_tokens, max_tokens, self.price)

        spent = Usage()  # usage of failed attempts of this call
        state: dict[str, Any] = {}

        def attempt() -> Any:
            state.clear()
            try:
                if not self.stream:
                    return self._sdk.messages.create(
                        max_tokens=max_tokens, **params, **self._thinking()
                    )
                return self._streamed(request, params, max_tokens, state)
            except BaseException:
                partial = state.get("usage")
                if partial is not None:
                    nonlocal spent
                    spent = spent + partial
                    self.budget.spend(cost_usd(self.model, partial, self.price), call=False)
                raise

        def classify(e: BaseException) -> _http.Failure | None:
            return _http.classify(anthropic, e, self._url(), self.read_timeout_s)

        def give_up(
            f: _http.Failure, tries: int, elapsed: float, e: BaseException
        ) -> BaseException:
            return self._failure(request, f, tries, elapsed, spent)

        try:
            message = _http.call_with_retries(
                attempt,
                classify=classify,
                give_up=give_up,
                policy=self.retry,
                say=self.say,
                connect_timeout_s=self.connect_timeout_s,
                started=started,
                before_retry=lambda: self.budget.reserve(worst),
            )
        except ModelCallFailed as e:
            if e.usage is not None and (e.usage.input_tokens or e.usage.output_tokens):
                self.budget.calls += 1  # a billed call, although it failed
            raise
        except BudgetExceeded as e:  # before a retry, after a broken attempt that cost something
            if spent.input_tokens or spent.output_tokens:
                e.usage = Usage(
                    **{**spent.to_dict(), "usd": cost_usd(self.model, spent, self.price)}
                )  # type: ignore[attr-defined]
                self.budget.calls += 1
            raise
        u = message.usage
        usage = spent + Usage(
            input_tokens=u.input_tokens or 0,
            output_tokens=u.output_tokens or 0,
            cache_write_tokens=u.cache_creation_input_tokens or 0,
            cache_read_tokens=u.cache_read_input_tokens or 0,
        )
        if self._count_unreachable:
            self._count_unreachable = False
            self._note(
                f"note: the token-count route of {self.base_url} could not be reached; this call "
                f"was budgeted from an estimate of its input (~{estimate} tokens)"
            )
        usd_now = cost_usd(self.model, usage, self.price) - cost_usd(self.model, spent, self.price)
        self.budget.spend(usd_now)
        usage = Usage(**{**usage.to_dict(), "usd": cost_usd(self.model, usage, self.price)})
        text = "".join(b.text for b in message.content if getattr(b, "type", None) == "text")
        stop = message.stop_reason
        if stop == "refusal":
            raise ModelRefused(
                f"the model refused to answer {request.function} attempt {request.attempt} "
                f"(stop_reason: refusal); nothing was retried. The call cost ${usage.usd:.2f}.",
                usage=usage,
            )
        if stop == "model_context_window_exceeded":
            raise ContextWindowExceeded(
                f"{request.function} attempt {request.attempt}: the prompt ({usage.input_tokens + usage.cache_read_tokens + usage.cache_write_tokens} "
                f"input tokens) plus the answer ({usage.output_tokens} tokens so far) filled "
                f"{self.model}'s context window (stop_reason: model_context_window_exceeded); "
                "use a model with a larger window, or a smaller prompt",
                usage=usage,
            )
        return ModelResponse(text=text, model=message.model, usage=usage, stop_reason=stop)

    def _url(self) -> str:
        return f"{self.base_url}/v1/messages"

    def _streamed(
        self, request: ModelRequest, params: dict[str, Any], max_tokens: int, state: dict
    ) -> Any:
        chars = {"n": 0}

        def line(elapsed: float) -> str:
            n = chars["n"]
            got = f"~{int(n / 3.5)} tokens so far" if n else "waiting for the first token"
            return f"  … {request.function} attempt {request.attempt}: {got}, {elapsed:.0f} s"

        with (
            _http.Ticker(self.say, self.progress_every_s, line),
            self._sdk.messages.stream(
                max_tokens=max_tokens, **params, **self._thinking()
            ) as stream,
        ):
            if stream.response.headers.get("content-type", "").startswith("application/json"):
                # a gateway that does not stream
                stream.response.read()
                return anthropic.types.Message.model_validate(stream.response.json())
            try:
                for event in stream:
                    if event.type == "text":
                        chars["n"] += len(event.text)
                    elif event.type == "thinking":
                        chars["n"] += len(event.thinking)
                if _snapshot_usage(stream) is None:
                    raise httpx.RemoteProtocolError(
                        "the event stream ended before its first message event"
                    )
                return stream.get_final_message()
            except BaseException:
                state["usage"] = _snapshot_usage(stream)
                raise

    def _failure(
        self, request: ModelRequest, f: _http.Failure, tries: int, elapsed: float, spent: Usage
    ) -> Exception:
        usage = None
        if spent.input_tokens or spent.output_tokens:
            usage = Usage(**{**spent.to_dict(), "usd": cost_usd(self.model, spent, self.price)})
        return _http.failure_error(
            f,
            tries,
            elapsed,
            usage,
            api="Anthropic API",
            base_url=self.base_url,
            what=f"{request.function} attempt {request.attempt}",
            model=self.model,
            credentials="ANTHROPIC_API_KEY or ANTHROPIC_AUTH_TOKEN",
            base_url_env="ANTHROPIC_BASE_URL",
        )


def _snapshot_usage(stream: Any) -> Usage | None:
    """The usage a stream had reported when it broke (None before its first event)."""
    try:
        snap = stream.current_message_snapshot
    except (AssertionError, AttributeError):
        return None
    u = snap.usage
    return Usage(
        input_tokens=u.input_tokens or 0,
        output_tokens=u.output_tokens or 0,
        cache_write_tokens=u.cache_creation_input_tokens or 0,
        cache_read_tokens=u.cache_read_input_tokens or 0,
    )


__all__ = ["DEFAULT_MODEL", "EFFORTS", "EFFORT_HEADROOM", "STOP_MAX_TOKENS", "AnthropicClient"]
