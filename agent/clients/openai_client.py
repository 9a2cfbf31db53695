"""OpenAI-compatible chat completions through the `openai` SDK: vLLM, Ollama, LiteLLM, hosted.

`rivet author D --model openai:NAME --base-url URL`. The request is one system message (the
system blocks joined) and one user message of text parts and image parts (PNG as base64 data
URLs); cache marks have no counterpart and are dropped. The answer is streamed (with
`stream_options.include_usage`), with a progress line every 30 s. `finish_reason: length` is a
truncated answer (`stop_reason` `max_tokens`, as for Claude), `content_filter` or a refusal
raises `ModelRefused`, a prompt over the context length raises `ContextWindowExceeded`.
Retries and timeouts are `_http`'s (the same as the Anthropic client's).

The key is read from `OPENAI_API_KEY` only; it is optional for a local server (a placeholder
is sent instead). The base URL comes from `base_url`, else `OPENAI_BASE_URL`, else OpenAI's.
Prices are unknown: a dollar budget (`--max-usd`) needs `price=(IN, OUT)` (`--price IN,OUT`, USD
per million tokens); without one, calls cost $0 in the journal. Input tokens are estimated
locally (such servers have no token-count route); a server that reports no usage has its
output estimated too, and says so once.

`max_tokens` is sent as `max_tokens` (what every compatible server reads); a server that
answers 400 asking for `max_completion_tokens` (OpenAI's reasoning models) gets that instead.
`effort` is sent as `reasoning_effort`.
"""

from __future__ import annotations

import os
import time
from typing import Any

import httpx2 as httpx

from agent.clients import _http
from agent.clients.base import Author, ImageBlock, ModelRequest, ModelResponse, TextBlock, Usage
from agent.clients.pricing import (
    CHARS_PER_TOKEN,
    Budget,
    Price,
    cost_usd,
    estimate_input_tokens,
)
from agent.errors import AgentError, BudgetExceeded, ModelCallFailed, ModelRefused
from contracts.errors import UsageError

PREFIX = "openai:"
MISSING_KEY = (
    "OPENAI_API_KEY is not set: export it to use OpenAI's API, or point --base-url at an "
    "OpenAI-compatible server (vLLM, Ollama, LiteLLM)"
)
DEFAULT_BASE_URL = "https://api.openai.com/v1"
EFFORTS = ("low", "medium", "high")
_FINISH = {"stop": "end_turn", "length": "max_tokens", "tool_calls": "tool_use"}


class OpenAIClient:
    def __init__(
        self,
        model: str,
        *,
        base_url: str | None = None,
        budget: Budget | None = None,
        price: Price | None = None,
        max_retries: int = 6,
        timeout_s: float = _http.READ_TIMEOUT_S,
        connect_timeout_s: float = _http.CONNECT_TIMEOUT_S,
        http_client: httpx.Client | None = None,
        stream: bool = True,
        effort: str | None = None,
        retry: _http.RetryPolicy | None = None,
        progress: _http.Say | None = None,
        progress_every_s: float = _http.PROGRESS_EVERY_S,
    ) -> None:
        self.model = model.removeprefix(PREFIX)
        if not self.model:
            raise UsageError("--model openai:NAME: the model name is missing")
        self.base_url = (base_url or os.environ.get("OPENAI_BASE_URL") or DEFAULT_BASE_URL).rstrip(
            "/"
        )
        _http.forbid_real_api(self.base_url, injected=http_client is not None)
        key = os.environ.get("OPENAI_API_KEY") or None
        if key is None and self.base_url == DEFAULT_BASE_URL:
            raise AgentError(MISSING_KEY)
        self.budget = budget or Budget()
        if self.budget.max_usd is not None and price is None:
            raise UsageError(
                f"--max-usd: the price of openai:{self.model} is unknown; pass --price IN,OUT "
                "(USD per million input, output tokens), or leave out --max-usd"
            )
        if effort is not None and effort not in EFFORTS:
            raise UsageError(f"--effort {effort!r}: one of {', '.join(EFFORTS)}")
        self.price = price
        self.stream = stream
        self.effort = effort
        self.read_timeout_s = timeout_s
        self.connect_timeout_s = connect_timeout_s
        self.retry = retry or _http.RetryPolicy(max_retries=max_retries)
        self.say = progress or _http.stderr_say
        self.progress_every_s = progress_every_s
        self._limit_param = "max_tokens"
        self._noted: set[str] = set()
        import openai  # here, not at import: `agent.clients` loads without it

        self._openai = openai
        self._sdk = openai.OpenAI(
            api_key=key or "EMPTY",  # local servers take any key; vLLM's docs use "EMPTY"
            base_url=self.base_url,
            max_retries=0,  # ours: _http.call_with_retries
            timeout=_http.timeout(timeout_s, connect_timeout_s),
            http_client=http_client,
        )
        del key

    @property
    def author(self) -> Author:
        return Author(kind="model", provider="openai", model=self.model)

    def close(self) -> None:
        """Close the HTTP connections (an injected `http_client` included)."""
        self._sdk.close()

    def _note(self, key: str, line: str) -> None:
        if key not in self._noted:
            self._noted.add(key)
            self.say(line)

    # ------------------------------------------------------------------------------ request

    @staticmethod
    def _messages(request: ModelRequest) -> list[dict[str, Any]]:
        parts: list[dict[str, Any]] = []
        for b in request.content:
            if isinstance(b, TextBlock):
                parts.append({"type": "text", "text": b.text})
            elif isinstance(b, ImageBlock):
                parts.append(
                    {"type": "image_url", "image_url": {"url": f"data:image/png;base64,{b.b64()}"}}
                )
        system = "\n\n".join(b.text for b in request.system)
        return [{"role": "system", "content": system}, {"role": "user", "content": parts}]

    def _params(self, request: ModelRequest) -> dict[str, Any]:
        params: dict[str, Any] = {
            "model": self.model,
            "messages": self._messages(request),
            self._limit_param: request.max_tokens,
        }
        if self.effort is not None:
            params["reasoning_effort"] = self.effort
        if self.stream:
            params["stream"] = True
            params["stream_options"] = {"include_usage": True}
        return params

    def _usd(self, usage: Usage) -> float:
        return 0.0 if self.price is None else cost_usd(self.model, usage, self.price)

    # ------------------------------------------------------------------------------ calling

    def complete(self, request: ModelRequest) -> ModelResponse:
        started = time.monotonic()
        estimate = estimate_input_tokens(request)
        worst = 0.0
        if self.price is not None:
            pin, pout = self.price
            self.budget.check_output(request.max_tokens, pout)
            worst = (estimate * pin + request.max_tokens * pout) / 1e6
            if self.budget.max_usd is not None:
                self._note(
                    "estimate",
                    f"note: {self.base_url} cannot count tokens; budgeting from an estimate of the "
                    f"input (~{estimate} tokens for this call: characters / 3.5, up to 1600 per image)",
                )
        self.budget.reserve(worst)
        url = f"{self.base_url}/chat/completions"
        spent = Usage()
        state: dict[str, Any] = {}

        def attempt() -> dict[str, Any]:
            state.clear()
            try:
                try:
                    return self._once(request, state)
                except self._openai.BadRequestError as e:
                    if self._limit_param == "max_tokens" and "max_completion_tokens" in str(e):
                        self._limit_param = "max_completion_tokens"
                        state.clear()
                        return self._once(request, state)
                    raise
            except BaseException:
                partial = state.get("usage")
                if partial is not None:
                    nonlocal spent
                    spent = spent + partial
                    self.budget.spend(self._usd(partial), call=False)
                raise

        def give_up(
            f: _http.Failure, tries: int, elapsed: float, e: BaseException
        ) -> BaseException:
            usage = None
            if spent.input_tokens or spent.output_tokens:
                usage = Usage(**{**spent.to_dict(), "usd": self._usd(spent)})
            return _http.failure_error(
                f,
                tries,
                elapsed,
                usage,
                api="OpenAI-compatible API",
                base_url=self.base_url,
                what=f"{request.function} attempt {request.attempt}",
                model=self.model,
                credentials="OPENAI_API_KEY",
                base_url_env="OPENAI_BASE_URL",
            )

        try:
            got = _http.call_with_retries(
                attempt,
                classify=lambda e: _http.classify(self._openai, e, url, self.read_timeout_s),
                give_up=give_up,
                policy=self.retry,
                say=self.say,
                connect_timeout_s=self.connect_timeout_s,
                started=started,
                before_retry=lambda: self.budget.reserve(worst),
            )
        except ModelCallFailed as e:
            if e.usage is not None:
                self.budget.calls += 1
            raise
        except BudgetExceeded as e:  # before a retry, after a broken attempt that cost something
            if spent.input_tokens or spent.output_tokens:
                e.usage = Usage(**{**spent.to_dict(), "usd": self._usd(spent)})  # type: ignore[attr-defined]
                self.budget.calls += 1
            raise
        text: str = got["text"]
        usage: Usage | None = got["usage"]
        if usage is None:
            self._note(
                "usage",
                f"note: {self.base_url} reported no token usage; it is estimated "
                "(characters / 3.5)",
            )
            usage = Usage(input_tokens=estimate, output_tokens=int(len(text) / CHARS_PER_TOKEN))
        total = spent + usage
        self.budget.spend(self._usd(usage))
        total = Usage(**{**total.to_dict(), "usd": self._usd(total)})
        finish = got["finish"]
        if finish == "content_filter" or got["refusal"]:
            why = got["refusal"] or "finish_reason: content_filter"
            raise ModelRefused(
                f"the model refused to answer {request.function} attempt {request.attempt} "
                f"({why}); nothing was retried.",
                usage=total,
            )
        return ModelResponse(
            text=text,
            model=got["model"] or self.model,
            usage=total,
            stop_reason=_FINISH.get(finish, finish) if finish else None,
        )

    def _once(self, request: ModelRequest, state: dict[str, Any]) -> dict[str, Any]:
        params = self._params(request)
        if not self.stream:
            c = self._sdk.chat.completions.create(**params)
            choice = c.choices[0] if c.choices else None
            return {
                "text": (choice.message.content or "") if choice else "",
                "refusal": getattr(choice.message, "refusal", None) if choice else None,
                "finish": choice.finish_reason if choice else None,
                "usage": _usage(c.usage),
                "model": c.model,
            }
        pieces: list[str] = []
        refusal: list[str] = []
        seen = {"chars": 0}
        out: dict[str, Any] = {"finish": None, "usage": None, "model": None}

        def line(elapsed: float) -> str:
            n = seen["chars"]
            got = (
                f"~{int(n / CHARS_PER_TOKEN)} tokens so far" if n else "waiting for the first token"
            )
            return f"  … {request.function} attempt {request.attempt}: {got}, {elapsed:.0f} s"

        with _http.Ticker(self.say, self.progress_every_s, line):
            stream = self._sdk.chat.completions.create(**params)
            try:
                for chunk in stream:
                    out["model"] = out["model"] or getattr(chunk, "model", None)
                    if getattr(chunk, "usage", None) is not None:
                        out["usage"] = _usage(chunk.usage)
                    for choice in chunk.choices or ():
                        delta = choice.delta
                        if delta is not None:
                            if delta.content:
                                pieces.append(delta.content)
                                seen["chars"] += len(delta.content)
                            if getattr(delta, "refusal", None):
                                refusal.append(delta.refusal)
                            extra = getattr(delta, "model_extra", None) or {}
                            for k in ("reasoning_content", "reasoning"):
                                if isinstance(extra.get(k), str):
                                    seen["chars"] += len(extra[k])
                        if choice.finish_reason:
                            out["finish"] = choice.finish_reason
            except BaseException:
                if out["usage"] is not None:
                    state["usage"] = out["usage"]
                raise
            finally:
                stream.close()
        return {**out, "text": "".join(pieces), "refusal": "".join(refusal) or None}


def _usage(u: Any) -> Usage | None:
    if u is None:
        return None
    return Usage(input_tokens=u.prompt_tokens or 0, output_tokens=u.completion_tokens or 0)


__all__ = ["PREFIX", "OpenAIClient"]
