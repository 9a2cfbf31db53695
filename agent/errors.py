"""Errors of the authoring agent."""

from __future__ import annotations

from typing import TYPE_CHECKING

from contracts.errors import RivetError, UsageError

if TYPE_CHECKING:
    from agent.clients.base import Usage


class AgentError(RivetError):
    """A failure of an authoring run (not of a draft: drafts fail into check reports)."""


class BudgetExceeded(AgentError):
    """The next model call would exceed `--max-usd` or `--max-calls`; it was not made.

    `usage` is None, unless the refusal came before a retry of a call whose broken first
    attempt had already cost something: then it is that cost, for the journal.
    """

    usage: Usage | None = None


class ModelCallFailed(AgentError):
    """The model API failed after the retries.

    `usage` is what the failed call is known to have consumed (billed tokens of a refusal, a
    stream cut off mid-way, …), or None when nothing is known; the journal records it and the
    budget has counted it.
    """

    def __init__(self, message: str, *, usage: Usage | None = None) -> None:
        super().__init__(message)
        self.usage = usage


class ApiUnreachable(ModelCallFailed):
    """No connection to the model API could be made (refused, timed out, no route)."""


class ModelRefused(ModelCallFailed):
    """The model declined to answer (`stop_reason: refusal`, or a content filter)."""


class ContextWindowExceeded(ModelCallFailed):
    """The prompt (or the prompt plus the answer) does not fit the model's context window."""


class AgentCommandFailed(AgentError):
    """An `--agent COMMAND` did not answer: non-zero exit, timeout, or no response file."""


class ReplayMismatch(AgentError):
    """A replayed run asked for a response that the transcript does not hold."""


class AuthoringExhausted(AgentError):
    """A function used all its attempts without passing its checks; `--resume` continues."""

    def __init__(self, function: str, attempts: int, run_dir: str, summary: str) -> None:
        self.function = function
        self.attempts = attempts
        self.run_dir = run_dir
        super().__init__(
            f"'{function}' did not pass its checks in {attempts} attempts; best draft and its "
            f"report are in {run_dir}.\n{summary}\n"
            f"Continue with: rivet author ... --resume --attempts {attempts + 2}"
        )


class TranscriptError(UsageError):
    """A transcript folder is missing or malformed."""


class GateFailed(AgentError):
    """The candidate set kept failing the trial gate (`artifacts.gate`) for its rounds."""

    def __init__(self, rounds: int, blamed: str, run_dir: str) -> None:
        self.rounds = rounds
        self.blamed = blamed
        self.run_dir = run_dir
        super().__init__(
            f"the candidate set failed the trial gate in {rounds} rounds, the last held against "
            f"'{blamed}'; the trials' reports are in {run_dir}/gate/. Nothing was frozen."
        )
