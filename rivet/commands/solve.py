"""`rivet solve DOMAIN START_DIR GOAL_DIR`: run the frozen programs on two observation folders
and print the plan JSON. No model calls; the programs run in a sandbox session (Docker unless
`--sandbox local` is named), never in this process.

Exit codes: 0 a plan was found, 1 the programs failed or the goal is infeasible, 2 bad input
(a missing or corrupt observation folder, a camera without intrinsics, unknown domain).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from rivet.commands._options import add_sandbox_option


def run(args: argparse.Namespace) -> int:
    import domains
    import sandbox
    from artifacts import load, unchecked_note
    from artifacts.errors import ProgramFailed
    from artifacts.observations import read_observation
    from contracts import ContractError, to_jsonable, validate

    domain = domains.load(args.domain)
    start = read_observation(args.start)
    goal = read_observation(args.goal)
    system = load(domain.name, Path(args.artifacts) if args.artifacts else None)
    if note := unchecked_note(domain.name, system.manifest):
        print(note, file=sys.stderr)
    options = {"quiet": True} if args.sandbox == "local" else {}
    with sandbox.open_executor(args.sandbox, **options) as executor, system.runner(executor) as run:
        plan = run.solve(start, goal)
        wall, cpu = run.timings, run.cpu
    try:
        plan = validate("plan", to_jsonable(plan))
    except ContractError as e:  # a frozen program's bad output: the work failed, not the user
        raise ProgramFailed(f"the frozen `plan` returned an invalid plan: {e}") from None
    print(json.dumps(plan, indent=None if args.compact else 2))
    print(
        ", ".join(
            f"{name} {wall[name] * 1000:.0f} ms ({cpu[name] * 1000:.0f} ms CPU)"
            for name in ("perceive", "relate", "plan")
        )
        + f"; {wall['round_trip'] * 1000:.0f} ms with the sandbox's transfers",
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
    add_sandbox_option(p, what="the frozen programs")
    p.add_argument("--compact", action="store_true", help="one-line JSON")
    p.set_defaults(handler=run)
