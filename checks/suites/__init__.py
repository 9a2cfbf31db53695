"""One check suite per generated function; each returns its interface/schema/property checks.

A suite is `checks(ctx: SuiteContext) -> list[CheckResult]`; domain properties are added by
`checks.properties`, the image checks and perception accuracy on the host by `checks.run`.
Each suite module also states what its checks enforce (`RULES`, see `checks.rules`); the
interface checks every function gets (`checks.context`) are stated here.
"""

from __future__ import annotations

from collections.abc import Callable

from checks.rules import Rule
from checks.suites import perceive, plan, relate, render

SUITES: dict[str, Callable] = {
    "render": render.checks,
    "perceive": perceive.checks,
    "relate": relate.checks,
    "plan": plan.checks,
}

RULES: dict[str, tuple[Rule, ...]] = {
    "render": render.RULES,
    "perceive": perceive.RULES,
    "relate": relate.RULES,
    "plan": plan.RULES,
}


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
