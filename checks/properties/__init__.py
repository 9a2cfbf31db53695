"""Domain properties: checks a domain asks for on a function, run after the generic suite.

Design rule: the checks keep one library of domain properties (`library`), each a function
``(ctx, **params) -> CheckResult`` written against the geometry and the cases, never against
one domain; a domain declares which it wants, with their parameters, in
``Domain.properties = {function: [(property name, {params}), ...]}``. So a new domain touches
its own folder only, and the same property (support that matches the geometry, perceived states
that could stand) serves every domain that asks for it. Check names read
``domain.<domain>.<property>``.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from checks.properties.library import LIBRARY
from checks.report import CheckResult


@dataclass(frozen=True, kw_only=True)
class DomainProperty:
    """One property a domain asked for on one function."""

    domain: str
    function: str
    name: str
    fn: Callable[..., CheckResult]
    params: Mapping[str, Any] = field(default_factory=dict)

    @property
    def check_name(self) -> str:
        return f"domain.{self.domain}.{self.name}"


def properties_for(domain: Any, function: str) -> list[DomainProperty]:
    """The properties `domain` declares for `function`, in declaration order.

    Raises:
        KeyError: the domain names a property the library does not have (a bug of the domain).
    """
    out = []
    for name, params in getattr(domain, "properties", {}).get(function, []):
        if name not in LIBRARY:
            raise KeyError(
                f"{domain.name}: unknown domain property {name!r} for {function}; known: "
                f"{', '.join(sorted(LIBRARY))}"
            )
        out.append(
            DomainProperty(
                domain=domain.name, function=function, name=name, fn=LIBRARY[name], params=params
            )
        )
    return out


def run_property_check(prop: DomainProperty, ctx: Any) -> CheckResult:
    """Run one domain property; a crash of the property's own code is an error, not a pass."""
    t0 = time.perf_counter()
    try:
        result = prop.fn(ctx, **prop.params)
    except Exception as e:
        result = CheckResult(
            name=prop.check_name,
            category="domain",
            status="error",
            message=f"this check could not evaluate the function's output ({type(e).__name__}: "
            f"{e})",
            traceback=traceback.format_exc(),
        )
    result.name = prop.check_name
    result.duration_s = time.perf_counter() - t0
    return result


__all__ = ["LIBRARY", "DomainProperty", "properties_for", "run_property_check"]
