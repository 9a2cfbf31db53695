"""One check suite per generated function; each returns its interface/schema/property checks.

A suite is `checks(ctx: SuiteContext) -> list[CheckResult]`; domain properties are added by
`checks.properties`, image checks on the host by `sim.checking`.
"""

from __future__ import annotations

from collections.abc import Callable

from checks.suites import perceive, plan, relate, render

SUITES: dict[str, Callable] = {
    "render": render.checks,
    "perceive": perceive.checks,
    "relate": relate.checks,
    "plan": plan.checks,
}

__all__ = ["SUITES"]
