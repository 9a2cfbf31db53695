"""A scripted fake model for tests: answers from a queue, and records what it was asked."""

from __future__ import annotations

from collections.abc import Callable, Iterable

from agent.clients.base import Author, ModelRequest, ModelResponse, Usage
from agent.clients.pricing import Budget
from agent.errors import AgentError

Reply = str | ModelResponse | Callable[[ModelRequest], str | ModelResponse] | BaseException


class ScriptedClient:
    """Replies in order; a reply may be text, a `ModelResponse` (e.g. a truncated one), a function
    of the request returning either, or an exception."""

    def __init__(
        self,
        replies: Iterable[Reply],
        *,
        budget: Budget | None = None,
        usd_per_call: float = 0.0,
        model: str = "scripted",
    ):
        self.replies = list(replies)
        self.requests: list[ModelRequest] = []
        self.budget = budget or Budget()
        self.usd_per_call = usd_per_call
        self.model = model

    @property
    def author(self) -> Author:
        return Author(kind="people", names=("test script",), note="scripted fake model for tests")

    def complete(self, request: ModelRequest) -> ModelResponse:
        self.budget.reserve(self.usd_per_call)
        if not self.replies:
            raise AgentError(
                f"scripted model has no reply left for {request.function} #{request.attempt}"
            )
        self.requests.append(request)
        reply = self.replies.pop(0)
        if isinstance(reply, BaseException):
            raise reply
        answer = reply(request) if callable(reply) else reply
        self.budget.spend(self.usd_per_call)
        if isinstance(answer, ModelResponse):
            return answer
        return ModelResponse(text=answer, model=self.model, usage=Usage(usd=self.usd_per_call))
