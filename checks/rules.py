"""The rules the checks enforce, stated for the model: one sentence per check.

Design rule: a rule never spells a number. Every tolerance, budget or threshold it states is a
placeholder naming the one place the number is defined, read when the rule is rendered:

    {geometry.tolerances:TOLERANCES.penetration|mm}   module:attribute path, shown in mm
    {checks.budget:ONLINE_BUDGET[perceive]|s}         a mapping entry, in seconds
    {domain.tolerance.translation|mm}                 the domain's own value
    {params.gap|mm}                                   a domain property's declared parameter
    [? and {domain.tolerance.rotation|deg}?]          dropped when a value inside is None
    [?!domain.tolerance.rotation: (not scored)?]      kept only when that value is None

so the prompt (`agent.prompt`), the report (each check's ``rule`` and ``limits``) and the
check's verdict read the same constant. Rules live beside their checks: the suites'
``RULES`` (`checks.suites`), the interface checks' in `checks.suites.interface_rules`, a
domain property's in its ``@_register(rule=...)`` (`checks.properties.library`).
`tests/agent/test_prompt_rules.py` holds every check to a stated rule and every stated number
to its source.
"""

from __future__ import annotations

import importlib
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

PLACEHOLDER = re.compile(
    r"\{((?:[a-z_][\w.]*:|domain\.|params\.)[^{}|\s]+)(?:\|([a-z_]+))?\}"
)  # {path} or {path|unit}; other braces are text
OPTIONAL = re.compile(r"\[\?(!([^:\]]+):)?(.*?)\?\]", re.S)
_STEP = re.compile(r"\.([A-Za-z_][A-Za-z0-9_]*)|\[([^\]]+)\]")


@dataclass(frozen=True, kw_only=True)
class Rule:
    """What one check enforces, as a template (see the module docstring)."""

    check: str  # the check's name ("property.accuracy"; a domain property: its library name)
    text: str


@dataclass(frozen=True, kw_only=True)
class Number:
    """One value a rendered rule states: where it comes from and how it reads."""

    source: str  # the placeholder's path
    unit: str  # "" (as is), "mm", "deg", "s", "pct", "px", "m", "region", "names", "vocab"
    value: Any  # the source's value (SI units)
    shown: str  # its text in the rule


@dataclass(frozen=True, kw_only=True)
class Stated:
    """A rendered rule: the check it belongs to, its sentence, the values it states."""

    check: str
    text: str
    numbers: tuple[Number, ...] = ()

    def limits(self) -> dict[str, float]:
        """The numeric values stated, by source path (what a report's ``limits`` holds)."""
        out: dict[str, float] = {}
        for n in self.numbers:
            for key, v in _flat_numbers(n.source, n.value):
                out[key] = v
        return out


class RuleError(LookupError):
    """A placeholder names nothing (a bug of the rule, not of a draft)."""


# -- resolving and showing values --------------------------------------------------------------


def resolve(path: str, *, domain: Any = None, params: Mapping[str, Any] | None = None) -> Any:
    """The value a placeholder path names (see the module docstring)."""
    if ":" in path:
        module, _, rest = path.partition(":")
        value: Any = importlib.import_module(module)
        rest = "." + rest
    else:
        root, _, tail = path.partition(".")
        if root == "domain":
            value = domain
        elif root == "params":
            value = dict(params or {})
        else:
            raise RuleError(f"placeholder {path!r}: roots are 'module:attr', 'domain.', 'params.'")
        if value is None:
            raise RuleError(f"placeholder {path!r} needs a {root}")
        rest = "." + tail if tail else ""
    pos = 0
    while pos < len(rest):
        m = _STEP.match(rest, pos)
        if m is None:
            raise RuleError(f"placeholder {path!r}: cannot read {rest[pos:]!r}")
        attr, key = m.groups()
        try:
            if attr is not None:
                value = value[attr] if isinstance(value, dict) else getattr(value, attr)
            else:
                value = value[int(key) if key.lstrip("-").isdigit() else key]
        except (AttributeError, KeyError, IndexError, TypeError) as e:
            raise RuleError(f"placeholder {path!r}: {e}") from None
        pos = m.end()
    return value


def number_text(x: float) -> str:
    """A number as rules show it: at most two decimals, no trailing zeros."""
    x = float(x)
    if x == int(x):
        return str(int(x))
    return f"{round(x, 2):g}" if abs(x) >= 0.1 else f"{x:.3g}"


_SCALES: dict[str, tuple[float | Callable[[float], float], str]] = {
    "": (1.0, ""),
    "mm": (1000.0, " mm"),
    "deg": (math.degrees, "°"),
    "s": (1.0, " s"),
    "pct": (100.0, "%"),
    "px": (1.0, " px"),
    "m": (1.0, " m"),
}


def scaled(unit: str, x: float) -> float:
    """A source value (SI) in the unit a rule shows it in."""
    scale = _SCALES[unit][0]
    return float(scale(x)) if callable(scale) else float(x) * scale


def show(value: Any, unit: str) -> str:
    """A resolved value as text in `unit`."""
    if unit == "region":
        x, y, reach = value.x, value.y, value.reach
        return (
            f"x ∈ [{number_text(x[0])}, {number_text(x[1])}] m, y ∈ [{number_text(y[0])}, "
            f"{number_text(y[1])}] m, every point within {number_text(reach)} m of the robot's "
            "base axis"
        )
    if unit == "names":
        return ", ".join(f"`{k}`" for k in value)
    if unit == "vocab":
        return "; ".join(f"`{k}`: {v}" for k, v in dict(value).items())
    if unit in _SCALES:
        if isinstance(value, str):
            return value
        if isinstance(value, Sequence):
            return ", ".join(show(v, unit) for v in value)
        return number_text(scaled(unit, value)) + _SCALES[unit][1]
    raise RuleError(f"unknown unit {unit!r}; known: {', '.join([*_SCALES, 'region', 'names'])}")


def _flat_numbers(key: str, value: Any) -> list[tuple[str, float]]:
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return []
    if isinstance(value, int | float | np.floating | np.integer):
        return [(key, float(value))]
    if hasattr(value, "x") and hasattr(value, "reach"):  # a Workspace
        return [
            (f"{key}.x_min", float(value.x[0])),
            (f"{key}.x_max", float(value.x[1])),
            (f"{key}.y_min", float(value.y[0])),
            (f"{key}.y_max", float(value.y[1])),
            (f"{key}.reach", float(value.reach)),
        ]
    if isinstance(value, Sequence):
        return [kv for i, v in enumerate(value) for kv in _flat_numbers(f"{key}[{i}]", v)]
    return []


# -- rendering ---------------------------------------------------------------------------------


def render(
    template: str, *, domain: Any = None, params: Mapping[str, Any] | None = None
) -> tuple[str, tuple[Number, ...]]:
    """The text of a template and the values it states."""
    numbers: list[Number] = []

    def fill(text: str, drop_none: bool) -> str | None:
        out, pos = [], 0
        for m in PLACEHOLDER.finditer(text):
            path, unit = m.group(1), m.group(2) or ""
            value = resolve(path, domain=domain, params=params)
            if value is None:
                if drop_none:
                    return None
                raise RuleError(f"placeholder {path!r} is None outside an optional segment")
            shown = show(value, unit)
            numbers.append(Number(source=path, unit=unit, value=value, shown=shown))
            out += [text[pos : m.start()], shown]
            pos = m.end()
        out.append(text[pos:])
        return "".join(out)

    parts, pos = [], 0
    for m in OPTIONAL.finditer(template):
        parts.append(fill(template[pos : m.start()], False) or "")
        if m.group(1):  # [?!path: text?]: the text when the value is None
            if resolve(m.group(2).strip(), domain=domain, params=params) is None:
                parts.append(fill(m.group(3), False) or "")
            pos = m.end()
            continue
        kept = len(numbers)
        seg = fill(m.group(3), True)
        if seg is None:
            del numbers[kept:]
        else:
            parts.append(seg)
        pos = m.end()
    parts.append(fill(template[pos:], False) or "")
    return "".join(parts), tuple(numbers)


def state(rule: Rule, *, domain: Any = None, params: Mapping[str, Any] | None = None,
          name: str | None = None) -> Stated:  # fmt: skip
    """A rule rendered for a domain (and a property's parameters)."""
    text, numbers = render(rule.text, domain=domain, params=params)
    return Stated(check=name or rule.check, text=" ".join(text.split()), numbers=numbers)


__all__ = [
    "Number",
    "Rule",
    "RuleError",
    "Stated",
    "number_text",
    "render",
    "resolve",
    "scaled",
    "show",
    "state",
]
