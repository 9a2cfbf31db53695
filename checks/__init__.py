"""The checks that decide whether a draft is frozen: the judge, and the only one.

Design rule: every check runs here, in the caller's process; the draft runs in a sandbox
session (`sandbox`) and reaches the checks only through what its calls return. Layout:
- `run`: `run_checks`, the one entry point (the authoring loop, `rivet check`, the pytest
  plugin and the benchmarks call it);
- `inputs` and `budget`: the cases, built from the domain's seeded generator and the
  simulator, and how much checking a draft gets;
- `context` and `calls`: what a suite works with (the domain as the checks see it, the draft's
  calls with their budgets) and the interface checks;
- `suites/`: the generic checks of each function; `properties/`: the library of domain
  properties a domain asks for (`Domain.properties`);
- `images` (silhouette and depth comparison, overlays), `hypo` (seeded hypothesis runs),
  `report` (the report format and the Markdown the model reads).
"""

from __future__ import annotations

from checks.budget import DEFAULT, ONLINE_BUDGET, THOROUGH, Budget
from checks.report import (
    CATEGORIES,
    CheckResult,
    build_report,
    comparable,
    images_of,
    report_markdown,
)
from checks.run import run_checks

__all__ = [
    "CATEGORIES",
    "DEFAULT",
    "ONLINE_BUDGET",
    "THOROUGH",
    "Budget",
    "CheckResult",
    "build_report",
    "comparable",
    "images_of",
    "report_markdown",
    "run_checks",
]
