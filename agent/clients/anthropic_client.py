"""Claude through the `anthropic` SDK: image blocks, prompt caching, retries, usage in dollars.

The key is read from `ANTHROPIC_API_KEY` only (never an argument, never logged, never passed
to a sandbox). Retries with exponential backoff on 429/5xx/529/timeouts are the SDK's
(`max_retries`). The budget is checked before each call from a token count of the request
and the worst-case output, never after.

Setting `RIVET_FORBID_MODEL_API=1` (the test suite does) makes constructing a client without an
injected `http_client` fail, so tests cannot reach a real API.
"""

from __future__ import annotations

import os
from typing import Any

import anthropic
import httpx2 as httpx

from agent.clients.base import Author, ImageBlock, ModelRequest, ModelResponse, TextBlock, Usage
from agent.clients.pricing import CACHE_WRITE_FACTOR, Budget, cost_usd, price_of
from agent.errors import AgentError, ModelCallFailed

DEFAULT_MODEL = "claude-opus-5"


class AnthropicClient:
    def __init__(
        self,
        model: str = DEFAULT_MODEL,
        *,
        budget: Budget | None = None,
        max_retries: int = 6,
        timeout_s: float = 600.0,
        http_client: httpx.Client | None = None,
        base_url: str | None = None,
    ) -> None:
        if http_client is None and os.environ.get("RIVET_FORBID_MODEL_API") == "1":
            raise AgentError("real model API calls are forbidden here (RIVET_FORBID_MODEL_API=1)")
        key = os.environ.get("ANTHROPIC_API_KEY")
        if not key:
            raise AgentError(
                "ANTHROPIC_API_KEY is not set: export it to author with a model, "
                "or replay a transcript (rivet author DOMAIN --replay DIR)"
            )
        price_of(model)  # fail before any call for a model we cannot budget
        self.model = model
        self.budget = budget or Budget()
        self._sdk = anthropic.Anthropic(
            api_key=key,
            max_retries=max_retries,
            timeout=timeout_s,
            http_client=http_client,
            base_url=base_url,
        )

    @property
    def author(self) -> Author:
        return Author(kind="model", provider="anthropic", model=self.model)

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

    def complete(self, request: ModelRequest) -> ModelResponse:
        params = self._params(request)
        try:
            counted = self._sdk.messages.count_tokens(**params).input_tokens
        except anthropic.APIError as e:
            raise ModelCallFailed(f"token count failed: {e}") from e
        pin, pout = price_of(self.model)
        worst = (counted * pin * CACHE_WRITE_FACTOR + request.max_tokens * pout) / 1e6
        self.budget.reserve(worst)
        try:
            message = self._sdk.messages.create(max_tokens=request.max_tokens, **params)
        except anthropic.APIError as e:
            raise ModelCallFailed(f"{type(e).__name__}: {e}") from e
        u = message.usage
        usage = Usage(
            input_tokens=u.input_tokens,
            output_tokens=u.output_tokens,
            cache_write_tokens=u.cache_creation_input_tokens or 0,
            cache_read_tokens=u.cache_read_input_tokens or 0,
        )
        usd = cost_usd(self.model, usage)
        self.budget.spend(usd)
        text = "".join(getattr(b, "text", "") for b in message.content)
        return ModelResponse(
            text=text,
            model=message.model,
            usage=Usage(**{**usage.to_dict(), "usd": usd}),
            stop_reason=message.stop_reason,
        )
