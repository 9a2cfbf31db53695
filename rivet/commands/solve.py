"""`rivet solve DOMAIN START_DIR GOAL_DIR`: run the frozen programs on two observation folders
and print the plan JSON. No model calls, no sandbox: the thin runtime.

Exit codes: 0 a plan was found, 1 the programs failed or the goal is infeasible, 2 bad input
(a missing or corrupt observation folder, a camera without intrinsics, unknown domain).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from contracts.errors import RivetError


def run(args: argparse.Namespace) -> int:
    import domains
    from artifacts import load
    from artifacts.observations import read_observation
    from contracts import to_jsonable, validate

    domain = domains.load(args.domain)
    start = read_observation(args.start)
    goal = read_observation(args.goal)
    system = load(domain.name, Path(args.artifacts) if args.artifacts else None)
    try:
        plan = system.solve(start, goal)
    except Exception as e:  # a frozen program failed on this input: the work failed, not the user
        raise RivetError(f"the frozen programs failed: {type(e).__name__}: {e}") from e
    plan = validate("plan", to_jsonable(plan))
    print(json.dumps(plan, indent=None if args.compact else 2))
    t = system.timings
    print(
        f"perceive {t['perceive'] * 1000:.0f} ms, relate {t['relate'] * 1000:.0f} ms, "
        f"plan {t['plan'] * 1000:.0f} ms",
        file=sys.stderr,
    )
    return 0 if plan["status"] == "ok" else 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "solve",
        help="plan from start/goal observation folders with frozen programs",
        description=__doc__,
    )
    p.add_argument("domain", metavar="DOMAIN")
    p.add_argument("start", type=Path, metavar="START_DIR")
    p.add_argument("goal", type=Path, metavar="GOAL_DIR")
    p.add_argument(
        "--artifacts", default=None, help="artifact root (default: the repository's artifacts/)"
    )
    p.add_argument("--compact", action="store_true", help="one-line JSON")
    p.set_defaults(handler=run)
