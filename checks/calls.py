"""Calling a draft from a check: through its sandbox session, never in this process.

Design rule: the checks hold the draft only as a `sandbox.Session` — a process of its own in
the sandbox — and see nothing of it but the values its calls return (decoded with bounds on
this side). Each call runs under the function's per-call budget, enforced by the sandbox from
outside the draft's process; the time it took is measured there too. After a call that timed
out or killed the draft's process, every later call fails at once ("closed"), so a draft that
never returns cannot hold a check for calls × budget seconds.

What a call returns is counted before any check reads it (`contracts.limits.count_problem`:
records within the catalogue, edges within what the objects allow, plan steps within the
contract's cap): a value over a limit comes back as a ``bad_output`` verdict naming the count
and the limit, so no suite's geometry or comparison ever grows with a draft's answer. Decoding
such an answer still costs the host seconds (up to the sandbox's wire limits), so after one,
later calls of the function are not made ("refused"), as after a timeout: a draft that floods
cannot hold a check for calls × decoding seconds either.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from checks.timing import TimingLog
from contracts.functions import authoring_order
from contracts.limits import clip, count_problem
from sandbox import CallReport, ExceptionInfo, Session

# What a call's verdict means, in the words the report uses.
_VERDICT_TEXT = {
    "timeout": "did not return within its {budget:g} s budget",
    "oom": "ran out of memory",
    "crashed": "killed its own process ({detail})",
    "bad_output": "returned a value that cannot be used ({detail})",
    "closed": "was not run: the draft's process had already ended ({detail})",
    "refused": "was not run: an earlier call returned more than the contract allows ({detail})",
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
    queued_seconds: float = 0.0  # of `seconds`, waiting for a CPU (`sandbox.CallReport`)
    budget: float = 0.0
    over_limit: bool = False  # bad_output because a count is over its limit (`bounded`)

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
            return f"raised {clip(self.exception.type, 100)}: {clip(self.exception.message)}"
        if self.verdict in _VERDICT_TEXT:
            return _VERDICT_TEXT[self.verdict].format(budget=self.budget, detail=clip(self.detail))
        return "returned"

    def bounded(self, function: str, objects: int | None) -> CallResult:
        """This result, or a ``bad_output`` one when its value is over a count limit of
        `function`'s output (`contracts.limits`; `objects`: the catalogue's size)."""
        if not self.ok:
            return self
        problem = count_problem(function, self.value, objects=objects)
        if problem is None:
            return self
        return replace(self, value=None, verdict="bad_output", detail=problem, over_limit=True)

    @staticmethod
    def of(report: CallReport, budget: float) -> CallResult:
        return CallResult(
            value=report.value,
            verdict=report.verdict,
            exception=report.exception,
            detail=report.detail,
            seconds=report.seconds,
            cpu_seconds=report.cpu_seconds,
            queued_seconds=report.queued_seconds,
            budget=budget,
        )


@dataclass(kw_only=True)
class DraftCalls:
    """The functions of one session, called with a per-call budget; keeps every call's time.

    Attributes:
        session: the sandbox session holding the program.
        module: the module whose function is judged (e.g. "plan").
        budget: per-call budget of that function [s].
        objects: the domain's catalogue size, which bounds what the function may return
            (None: only the plan's step cap applies).
        calls: how many calls were made.
        seconds: (label, CPU seconds) of every call of the judged function that returned: the
            time it needs on one core, whatever else the machine is doing.
        failures: (label, CallResult) of calls that timed out or ended the process.
        flooded: the first answer of the judged function over a count limit (later calls of
            it are refused without being made), or None.
        timings: CPU and wall time of every call of the judged function that returned, each
            marked first or not on its input (`checks.timing`: what the speed gate counts).
    """

    session: Session
    module: str
    budget: float
    objects: int | None = None
    calls: int = 0
    seconds: list[tuple[str, float]] = field(default_factory=list)
    failures: list[tuple[str, CallResult]] = field(default_factory=list)
    flooded: CallResult | None = None
    timings: TimingLog = field(default_factory=TimingLog)

    def __call__(self, *args: Any, label: str = "", function: str | None = None) -> CallResult:
        """Call ``module.function(*args)`` (the judged function by default)."""
        name = function or self.module
        if name == self.module and self.flooded is not None:
            return replace(self.flooded, verdict="refused", seconds=0.0, cpu_seconds=0.0)
        self.calls += 1
        result = CallResult.of(
            self.session.call(self.module, name, *args, timeout_s=self.budget), self.budget
        ).bounded(name, self.objects)
        if name == self.module and result.over_limit:
            self.flooded = result
        if name == self.module and result.verdict in ("ok", "exception"):
            self.seconds.append((label, result.cpu_seconds))
        if name == self.module:
            self.timings.record(label, args, result)
        if result.verdict in ("timeout", "oom", "crashed"):
            self.failures.append((label, result))
        return result

    def attribute(self, name: str) -> CallResult:
        return CallResult.of(self.session.attribute(self.module, name), self.budget)

    def signature(self) -> CallResult:
        return CallResult.of(self.session.signature(self.module, self.module), self.budget)


def session_modules(function: str, source: str, frozen: Mapping[str, str]) -> dict[str, str]:
    """The modules of a check's session, composed as the runtime composes its one session
    (`artifacts.runtime.System.program`): every frozen program of the set, with `source` in
    `function`'s place, in authoring order. A draft checked this way sees the modules it will
    run beside; once the set is whole (a re-check, the pytest plugin) it is exactly the
    runtime's session."""
    modules = {**{k: v for k, v in frozen.items() if k != function}, function: source}
    return {name: modules[name] for name in authoring_order() if name in modules}


def frozen_up_to(function: str, frozen: Mapping[str, str]) -> dict[str, str]:
    """The frozen programs a session that calls the frozen `function` alone holds: it and
    those before it in authoring order, which its module may import."""
    order = authoring_order()
    before = set(order[: order.index(function) + 1])
    return {k: v for k, v in frozen.items() if k in before}
