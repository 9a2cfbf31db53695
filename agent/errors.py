"""Errors of the authoring agent."""

from __future__ import annotations

from contracts.errors import RivetError, UsageError


class AgentError(RivetError):
    """A failure of an authoring run (not of a draft: drafts fail into check reports)."""


class BudgetExceeded(AgentError):
    """The next model call would exceed `--max-usd` or `--max-calls`; it was not made."""


class ModelCallFailed(AgentError):
    """The model API failed after the SDK's retries."""


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
