"""The checks that decide whether a draft is frozen: suites, physics, images, reports.

Split, by what each part needs:
- `contracts.checks.suite` (+ `suites/`, `domain_properties/`, `physics`, `_hypo`, `_calls`)
  runs INSIDE the sandbox, in the draft's process: interface, schema, hypothesis properties
  and domain properties. Pure Python on numpy/scipy/trimesh/networkx/hypothesis; no simulator,
  no Docker, no files.
- `sim.checking` runs on the host: builds the inputs from the domain's instance generator and
  the simulator, runs the suite through a sandbox executor, and adds the checks that need
  ground truth or the simulator (perception accuracy, image comparisons, overlay PNGs).
- `contracts.checks.report` and `contracts.checks.images`: the report format, its Markdown
  for the prompt, and image metrics (pure, used on the host).

`run_checks` is the one function the authoring loop calls; it imports the host side lazily, so
importing this package pulls in neither the simulator nor Docker.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from contracts.checks.report import (
    CATEGORIES,
    FUNCTIONS,
    CheckResult,
    build_report,
    comparable,
    images_of,
    report_markdown,
)

__all__ = [
    "CATEGORIES",
    "FUNCTIONS",
    "CheckResult",
    "build_report",
    "comparable",
    "images_of",
    "report_markdown",
    "run_checks",
]


def run_checks(
    domain: str,
    function: str,
    source: str,
    *,
    deps: dict[str, str],
    thorough: bool = False,
    executor: Any = None,
    out_dir: Path | None = None,
) -> dict:
    """Run one draft's full checks and return its check report.

    Args:
        domain: a registered domain name (e.g. "cubes").
        function: "render", "perceive", "relate" or "plan".
        source: the draft module's source; it must define `function`.
        deps: frozen sources of the functions it depends on, by function name (e.g.
            {"relate": src} for `plan`); the module names the draft imports them by. Where a
            dependency is absent the domain's ground truth stands in (reference relations for
            `plan`, the toolbox renderer for re-rendering perceived records).
        thorough: more instances, observations and hypothesis examples (`sim.checking.THOROUGH`).
        executor: a `sandbox.Executor` to run the suite in; None opens (and closes) the Docker
            backend, and fails loudly when Docker is unavailable.
        out_dir: where the overlay PNGs go (referenced by path in the report); None: no images.

    Returns:
        A dict valid against `check_report.schema.json`.
    """
    from sim.checking import run_checks as _run  # the host side: simulator, sandbox

    return _run(
        domain,
        function,
        source,
        deps=deps,
        thorough=thorough,
        executor=executor,
        out_dir=out_dir,
    )
