"""A domain's fixed benchmark sets (20 goals × 3 starts each): splits, names, the file
format, regeneration.

Two splits (`SPLITS`): `dev`, the set programs are written and improved against, and `test`,
drawn from goal families the dev split never uses (its figures are reported, never tuned
on; docs/domains.md, "Splits"). Generation is deterministic: goal g of a split is drawn from
the seed (K, g), its starts from (K, g, s), K = `SPLIT_SEEDS[split]` (10000 dev, 20000 test);
dev goal 1 is the domain's hand-authored reference. Dev files are
`benchmark/goalGG_startS.json`, test files `benchmark/test/goalGG_startS.json` (instance
names `goalGG_startS` and `test/goalGG_startS`). They are written and verified with
`rivet scene benchmark DOMAIN [--split dev|test] [--check]` (which settles every scene in
MuJoCo).
"""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    pass

BENCHMARK_GOALS = 20
BENCHMARK_STARTS = 3
SPLITS = ("dev", "test")
SPLIT_SEEDS = {"dev": 10_000, "test": 20_000}  # the first seed key of a split's instances

_NUMBERS = re.compile(r"\[\s*(-?[\d.e+-]+(?:,\s*-?[\d.e+-]+)*)\s*\]")


def dumps(value: dict) -> str:
    """JSON with every list of numbers (a pose row) on one line: reviewable diffs."""
    text = json.dumps(value, indent=1)
    text = _NUMBERS.sub(
        lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text
    )
    return text + "\n"


def check_split(split: str) -> str:
    """`split` if it is one of `SPLITS` (ValueError otherwise)."""
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; known: {', '.join(SPLITS)}")
    return split


def benchmark_name(goal: int, start: int, split: str = "dev") -> str:
    """``goal01_start2`` (dev) or ``test/goal01_start2`` (test): also the file's path below
    the domain's benchmark folder, without ``.json``."""
    name = f"goal{goal:02d}_start{start}"
    return name if check_split(split) == "dev" else f"{split}/{name}"


def benchmark_keys() -> list[tuple[int, int]]:
    """(goal, start) of every benchmark instance, goal-major."""
    return [(g, s) for g in range(1, BENCHMARK_GOALS + 1) for s in range(1, BENCHMARK_STARTS + 1)]


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
