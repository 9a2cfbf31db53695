"""Running one property with hypothesis: seeded, no database, shrinking with a call budget.

`run_property(prop, strategy, ...)` draws inputs from `strategy` (explicit examples first),
calls `prop(example)`, which returns None when the property holds or a `Failure`, and returns
the failure for the smallest failing input hypothesis found. Shrinking is bounded by a number
of further calls, not by time, so the same draft always gets the same counterexample; inputs
already tried keep their outcome, so hypothesis's final replay of the minimal example is
consistent.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field
from typing import Any

from hypothesis import HealthCheck, Phase, Verbosity, given, settings
from hypothesis import example as explicit
from hypothesis import seed as seeded
from hypothesis import strategies as st


@dataclass(kw_only=True)
class Failure(Exception):
    """Why a property does not hold for one input (what the check report shows)."""

    message: str
    expected: Any = None
    actual: Any = None
    counterexample: Any = None
    traceback: str = ""
    error: bool = False  # the draft raised (or timed out) rather than returned a wrong value
    extra: dict[str, Any] = field(default_factory=dict)

    def __str__(self) -> str:
        return self.message


@dataclass(frozen=True, kw_only=True)
class PropertyOutcome:
    failure: Failure | None
    examples: int  # distinct inputs the property was called on


def run_property(
    prop: Callable[[Any], Failure | None],
    strategy: st.SearchStrategy,
    *,
    max_examples: int,
    seed: int,
    shrink_calls: int = 25,
    examples: Sequence[Hashable] = (),
) -> PropertyOutcome:
    """Search for an input of `strategy` on which `prop` fails; see the module docstring.

    Inputs must be hashable (tuples of ints and strings): they key the memo.
    """
    memo: dict[Hashable, Failure | None] = {}
    state: dict[str, int | None] = {"first_failure_at": None}

    def test(x: Hashable) -> None:
        if x in memo:
            outcome = memo[x]
        else:
            first = state["first_failure_at"]
            if first is not None and len(memo) - first >= shrink_calls:
                return  # shrinking budget spent: untried inputs count as passing
            outcome = prop(x)
            memo[x] = outcome
            if outcome is not None and first is None:
                state["first_failure_at"] = len(memo)
        if outcome is not None:
            raise outcome

    wrapped = given(strategy)(test)
    for x in reversed(list(examples)):
        wrapped = explicit(x)(wrapped)
    wrapped = settings(
        max_examples=max(1, max_examples),
        database=None,
        deadline=None,
        derandomize=False,
        suppress_health_check=list(HealthCheck),
        phases=(Phase.explicit, Phase.generate, Phase.shrink),
        report_multiple_bugs=False,
        print_blob=False,
        verbosity=Verbosity.quiet,
    )(seeded(seed)(wrapped))
    try:
        wrapped()
    except Failure as f:
        return PropertyOutcome(failure=f, examples=len(memo))
    return PropertyOutcome(failure=None, examples=len(memo))
