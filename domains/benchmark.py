"""A domain's fixed benchmark set (20 goals × 3 starts): names, the file format, regeneration.

Generation is deterministic: goal g is drawn from the seed (10000, g), its starts from
(10000, g, s); goal 1 is the domain's hand-authored reference. The files are written and
verified with `rivet scene benchmark DOMAIN [--check]` (which settles every scene in MuJoCo).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from domains.instance import Instance

if TYPE_CHECKING:
    from domains.base import Domain

BENCHMARK_GOALS = 20
BENCHMARK_STARTS = 3

_NUMBERS = re.compile(r"\[\s*(-?[\d.e+-]+(?:,\s*-?[\d.e+-]+)*)\s*\]")


def dumps(value: dict) -> str:
    """JSON with every list of numbers (a pose row) on one line: reviewable diffs."""
    text = json.dumps(value, indent=1)
    text = _NUMBERS.sub(
        lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text
    )
    return text + "\n"


def benchmark_name(goal: int, start: int) -> str:
    return f"goal{goal:02d}_start{start}"


_NAME = re.compile(r"^goal(\d\d)_start(\d)$")


def parse_benchmark_name(name: str) -> tuple[int, int] | None:
    """(goal, start) of a name like ``goal01_start2``, else None."""
    m = _NAME.match(name)
    return (int(m.group(1)), int(m.group(2))) if m else None


def regenerate(domain: Domain, physics: Callable[[Any, dict], list] | None) -> list[Instance]:
    """Every benchmark instance drawn again (`physics`: see `Domain.generate`)."""
    return [
        domain.benchmark_instance(g, s, physics=physics, grasps=True)
        for g in range(1, BENCHMARK_GOALS + 1)
        for s in range(1, BENCHMARK_STARTS + 1)
    ]


def same(a: dict, b: dict, atol: float = 1e-7) -> bool:
    """JSON instances equal up to `atol` in every number."""
    if type(a) is not type(b):
        return isinstance(a, int | float) and isinstance(b, int | float) and abs(a - b) <= atol
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k], atol) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y, atol) for x, y in zip(a, b, strict=True))
    if isinstance(a, float):
        return bool(np.isclose(a, b, rtol=0, atol=atol))
    return a == b
