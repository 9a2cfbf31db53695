"""Calling a draft from a check: through its sandbox session, never in this process.

Design rule: the checks hold the draft only as a `sandbox.Session` — a process of its own in
the sandbox — and see nothing of it but the values its calls return (decoded with bounds on
this side). Each call runs under the function's per-call budget, enforced by the sandbox from
outside the draft's process; the time it took is measured there too. After a call that timed
out or killed the draft's process, every later call fails at once ("closed"), so a draft that
never returns cannot hold a check for calls × budget seconds.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from sandbox import CallReport, ExceptionInfo, Session

# What a call's verdict means, in the words the report uses.
_VERDICT_TEXT = {
    "timeout": "did not return within its {budget:g} s budget",
    "oom": "ran out of memory",
    "crashed": "killed its own process ({detail})",
    "bad_output": "returned a value that cannot be read ({detail})",
    "closed": "was not run: the draft's process had already ended ({detail})",
}


@dataclass(frozen=True, kw_only=True)
class CallResult:
    """What one call of the draft did."""

    value: Any = None
    verdict: str = "ok"
    exception: ExceptionInfo | None = None
    detail: str = ""
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    budget: float = 0.0

    @property
    def ok(self) -> bool:
        return self.verdict == "ok"

    @property
    def timed_out(self) -> bool:
        return self.verdict == "timeout"

    @property
    def traceback(self) -> str:
        return self.exception.traceback if self.exception is not None else ""

    def describe(self) -> str:
        """One line: the exception type and message, or what else became of the call."""
        if self.verdict == "exception" and self.exception is not None:
            return f"raised {self.exception.type}: {self.exception.message[:500]}"
        if self.verdict in _VERDICT_TEXT:
            return _VERDICT_TEXT[self.verdict].format(budget=self.budget, detail=self.detail[:300])
        return "returned"

    @staticmethod
    def of(report: CallReport, budget: float) -> CallResult:
        return CallResult(
            value=report.value,
            verdict=report.verdict,
            exception=report.exception,
            detail=report.detail,
            seconds=report.seconds,
            cpu_seconds=report.cpu_seconds,
            budget=budget,
        )


@dataclass(kw_only=True)
class DraftCalls:
    """The functions of one session, called with a per-call budget; keeps every call's time.

    Attributes:
        session: the sandbox session holding the program.
        module: the module whose function is judged (e.g. "plan").
        budget: per-call budget of that function [s].
        calls: how many calls were made.
        seconds: (label, CPU seconds) of every call of the judged function that returned: the
            time it needs on one core, whatever else the machine is doing.
        failures: (label, CallResult) of calls that timed out or ended the process.
    """

    session: Session
    module: str
    budget: float
    calls: int = 0
    seconds: list[tuple[str, float]] = field(default_factory=list)
    failures: list[tuple[str, CallResult]] = field(default_factory=list)

    def __call__(self, *args: Any, label: str = "", function: str | None = None) -> CallResult:
        """Call ``module.function(*args)`` (the judged function by default)."""
        name = function or self.module
        self.calls += 1
        result = CallResult.of(
            self.session.call(self.module, name, *args, timeout_s=self.budget), self.budget
        )
        if name == self.module and result.verdict in ("ok", "exception"):
            self.seconds.append((label, result.cpu_seconds))
        if result.verdict in ("timeout", "oom", "crashed"):
            self.failures.append((label, result))
        return result

    def attribute(self, name: str) -> CallResult:
        return CallResult.of(self.session.attribute(self.module, name), self.budget)

    def signature(self) -> CallResult:
        return CallResult.of(self.session.signature(self.module, self.module), self.budget)


def session_modules(function: str, source: str, deps: Mapping[str, str]) -> dict[str, str]:
    """The modules of a draft's session: the frozen functions it imports, then the draft."""
    return {**{k: v for k, v in deps.items() if k != function}, function: source}
