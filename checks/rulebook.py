"""Every rule a draft is checked for, gathered from where each check states it: the interface
rules and each suite's `RULES` (`checks.suites`), and the domain properties' rules
(`checks.properties`). Above both, so that neither the suites nor the rule language
(`checks.rules`) import what they are gathered into."""

from __future__ import annotations

from typing import Any

from checks import properties, suites
from checks.rules import Rule, RuleError, Stated, state


def rules_for(domain: Any, function: str) -> list[Stated]:
    """Every rule a draft of `function` is checked for in `domain`, in report order: the
    interface checks, the function's suite (schema, properties, images) and the domain
    properties the domain declares for it.

    Raises:
        RuleError: a check the suite runs has no rule (a bug of the checks).
    """
    out = [state(r, domain=domain) for r in suites.interface_rules(function)]
    out += [state(r, domain=domain) for r in suites.RULES[function]]
    for prop in properties.properties_for(domain, function):
        rule = getattr(prop.fn, "rule", None)
        if not rule:
            raise RuleError(
                f"domain property {prop.name!r} has no rule: give it @_register(rule=...) in "
                "checks/properties/library.py"
            )
        out.append(
            state(Rule(check=prop.name, text=rule), domain=domain, params=prop.params,
                  name=prop.check_name)
        )  # fmt: skip
    order = ("interface", "schema", "property", "domain", "image")
    return sorted(out, key=lambda s: order.index(s.check.split(".")[0]))


def rule_map(domain: Any, function: str) -> dict[str, Stated]:
    """`rules_for` by check name."""
    return {s.check: s for s in rules_for(domain, function)}
