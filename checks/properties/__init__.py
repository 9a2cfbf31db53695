"""Domain properties: checks a domain registers for a function, run after the generic suite.

A domain adds its properties with ``@register("cubes", "relate")`` on a function
`(ctx: SuiteContext) -> CheckResult` (category "domain"); they run inside the sandbox like the
generic suites, so they live here (the sandbox image holds `contracts`, not `domains`) and use
only what the suite context carries: the domain's geometry and the generated cases, and the
draft's results cached by the generic checks.
"""

from __future__ import annotations

from collections.abc import Callable

_REGISTRY: dict[tuple[str, str], list[Callable]] = {}


def register(domain: str, function: str) -> Callable[[Callable], Callable]:
    """Decorator: run the decorated property on `function`'s drafts in `domain`."""

    def add(prop: Callable) -> Callable:
        _REGISTRY.setdefault((domain, function), []).append(prop)
        return prop

    return add


def properties_for(domain: str, function: str) -> list[Callable]:
    """The properties `domain` registered for `function`, in registration order."""
    return list(_REGISTRY.get((domain, function), []))


from contracts.checks.domain_properties import cubes  # noqa: E402,F401  (registers itself)

__all__ = ["properties_for", "register"]
