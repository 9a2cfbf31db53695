"""Checks as a registry: each check of a function's suite is one function, registered with its
name and its rule, as the domain properties are (`checks.properties.library`).

    @register("relate", "property.deterministic",
              rule="Two calls on the same records return the same graph.")
    def deterministic(ctx: SuiteContext, r: CheckResult) -> None:
        ...  # fill `r` in; raise `checks.hypo.Failure` to fail the check

A suite is the list `SUITE[function]`, in the order of registration: the order the checks run
in, the report lists and the prompt states their rules. `run_suite(function, ctx)` runs the
checks made in the draft's session (`checks.run` calls it). A check registered with
`on="host"` is judged on the host once the session is closed, from what the session checks
left in ``ctx.outputs``: it is registered for its rule and its place in the list, and
`checks.run` calls it. The category is the name's first part (`schema`, `property`, `image`).

Every check can run alone: `rivet check D FUNCTION FILE --only NAME` (`checks.suites._common.
selecting`) runs it with the interface and schema checks it rests on, and reports the others
skipped.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from checks.report import CheckResult
from checks.rules import Rule
from checks.suites._common import run_check

Body = Callable[[Any, CheckResult], None]  # (SuiteContext, the result to fill in)
SCHEMA = "schema.output"
SKIPPED_WITHOUT_SCHEMA = "skipped: the output does not pass its schema"


@dataclass(frozen=True, kw_only=True)
class Check:
    """One registered check of a function's suite.

    Attributes:
        function: the generated function it judges ("relate").
        name: "schema.output", "property.deterministic", …
        rule: what it enforces, for the prompt and the report (`checks.rules` placeholders).
        body: fills a `CheckResult` in and raises `Failure` to fail; None for a host check.
        on: "session" (run by `run_suite` while the draft's session is open) or "host".
        expected: the report's `expected` line: text, or text made from the context.
        seeded: the result records the hypothesis seed the check drew with.
        needs_schema: reported skipped, not run, when `schema.output` failed.
    """

    function: str
    name: str
    rule: str
    body: Body | None = None
    on: Literal["session", "host"] = "session"
    expected: str | Callable[[Any], str] | None = None
    seeded: bool = False
    needs_schema: bool = False

    @property
    def category(self) -> str:
        return self.name.partition(".")[0]

    def run(self, ctx: Any) -> CheckResult:
        """Run the check on `ctx` (a session check; `--only` may leave it out)."""
        if self.body is None:
            raise TypeError(f"{self.function}: {self.name} is judged on the host (checks.run)")
        fields: dict[str, Any] = {}
        if self.expected is not None:
            fields["expected"] = self.expected(ctx) if callable(self.expected) else self.expected
        if self.seeded:
            fields["seed"] = ctx.seed
        body = self.body
        return run_check(self.name, self.category, lambda r: body(ctx, r), **fields)


SUITE: dict[str, list[Check]] = {}


def register(
    function: str,
    name: str,
    *,
    rule: str,
    on: Literal["session", "host"] = "session",
    expected: str | Callable[[Any], str] | None = None,
    seeded: bool = False,
    needs_schema: bool = False,
) -> Callable[[Callable], Callable]:
    """Register the decorated function as the check `name` of `function`'s suite."""

    def deco(fn: Callable) -> Callable:
        checks = SUITE.setdefault(function, [])
        if any(c.name == name for c in checks):
            raise ValueError(f"{function}: a check named {name!r} is registered already")
        checks.append(
            Check(
                function=function,
                name=name,
                rule=rule,
                body=fn if on == "session" else None,
                on=on,
                expected=expected,
                seeded=seeded,
                needs_schema=needs_schema,
            )
        )
        return fn

    return deco


def suite(function: str) -> list[Check]:
    """`function`'s checks, in order. KeyError names the functions that have a suite."""
    if function not in SUITE:
        raise KeyError(f"no check suite for {function!r}; suites: {', '.join(sorted(SUITE))}")
    return list(SUITE[function])


def rules(function: str) -> tuple[Rule, ...]:
    """The rules of `function`'s checks, in order (what the prompt states)."""
    return tuple(Rule(check=c.name, text=c.rule) for c in suite(function))


def run_suite(function: str, ctx: Any) -> list[CheckResult]:
    """Run `function`'s session checks in order. Once `schema.output` fails, a check that
    needs it is reported skipped."""
    out: list[CheckResult] = []
    schema_failed = False
    for check in suite(function):
        if check.on != "session":
            continue
        if check.needs_schema and schema_failed:
            out.append(
                CheckResult(
                    name=check.name,
                    category=check.category,  # type: ignore[arg-type]
                    status="skipped",
                    message=SKIPPED_WITHOUT_SCHEMA,
                )
            )
            continue
        result = check.run(ctx)
        out.append(result)
        if check.name == SCHEMA and result.failing:
            schema_failed = True
    return out


__all__ = ["SUITE", "Check", "register", "rules", "run_suite", "suite"]
