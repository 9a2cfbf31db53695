"""One check suite per generated function, each a list of registered checks (`checks.registry`).

Each suite module registers its checks, one function each with its rule, in the order they
run; a suite runs as `run_suite(function, ctx)` (`SUITES[function](ctx)`). Domain properties are
added by `checks.properties`, and the host checks (`on="host"`: perception accuracy, the image
checks) are run by `checks.run`. The interface checks every function gets (`checks.context`)
state their rules here.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

from checks.registry import SUITE, rules, run_suite
from checks.rules import Rule
from checks.suites import perceive, plan, relate, render
from contracts.functions import FUNCTIONS

_MODULES = (render, perceive, relate, plan)  # importing them registers their checks
SUITES: dict[str, Callable] = {f: partial(run_suite, f) for f in FUNCTIONS if f in SUITE}
RULES: dict[str, tuple[Rule, ...]] = {f: rules(f) for f in SUITES}


def interface_rules(function: str) -> tuple[Rule, ...]:
    """The rules of the interface checks (`checks.context`) for `function`."""
    f = function
    return (
        Rule(
            check="interface.import",
            text="The module imports without an error within "
            "{checks.budget:DEFAULT.load_timeout|s} (work done at import time counts), importing "
            "only the libraries the rules allow.",
        ),
        Rule(
            check="interface.signature",
            text=f"The module defines a function `{f}` whose positional parameters are exactly "
            f"{{contracts.functions:SIGNATURES[{f}].params|names}} (any further parameter needs "
            "a default).",
        ),
        Rule(
            check="interface.runs",
            text="No call may end the process the module runs in (a crash, `exit`, running out "
            "of memory).",
        ),
        Rule(
            check="interface.returns_in_time",
            text=f"Every call returns within {{checks.budget:DEFAULT.call_timeout[{f}]|s}}: a hard "
            "limit enforced from outside the process, after which the call is killed and every "
            "later call fails.",
        ),
        Rule(
            check="interface.fast_enough",
            text="Over the calls the checks make on inputs new to your process (a repeated "
            "input counts once, at its first call), the median CPU time per call is at most "
            f"{{checks.budget:ONLINE_BUDGET[{f}]|s}} on one core (the online budget of `{f}`) "
            "and the median wall time, less the time spent waiting for a CPU on a busy "
            "machine, at most {checks.budget:WALL_FACTOR} times that: time spent sleeping or "
            "blocked counts.",
        ),
    )


__all__ = ["RULES", "SUITES", "interface_rules"]
