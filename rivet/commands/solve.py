"""`rivet solve DOMAIN START_DIR GOAL_DIR`: run the frozen programs on two observation folders
and print the plan JSON. No model calls; the programs run in a sandbox session (Docker unless
`--sandbox local` is named), never in this process.

It also writes, under `--out` (default runs/solve/DOMAIN/<time>/), what it perceived in each
image — `start.json` and `goal.json` (records, relations and the fit) and `start.png`,
`goal.png` (the perceived objects over the observation, the unexplained foreground in magenta)
— and the plan, `plan.json`. The *fit* (`artifacts.fit`) renders the perceived objects from the
image's own camera and compares them with its depth: when they do not explain the image (objects
of another domain, parts missed, a shape where there is nothing) `solve` refuses, exit 1,
naming what does not fit, instead of planning for objects it made up.

Exit codes: 0 a plan was found, 1 the programs failed, the images do not fit the domain or the
goal is infeasible, 2 bad input (a missing or corrupt observation folder, a camera without
intrinsics, unknown domain).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from contracts.errors import RivetError
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
    out = (
        Path(args.out)
        if args.out
        else Path("runs") / "solve" / domain.name / time.strftime("%Y%m%d-%H%M%S")
    )
    with sandbox.open_executor(args.sandbox, **options) as executor, system.runner(executor) as run:
        plan = run.solve(start, goal)
        wall, cpu = run.timings, run.cpu
        states = run.last_states
        assert states is not None
        lost = _write_what_was_seen(domain, out, {"start": start, "goal": goal}, states, run)
    if lost:
        raise ImagesDoNotFit(
            f"the images do not fit {domain.name}, so no plan is given: "
            + "; ".join(lost)
            + f" (what was perceived, and where: {out}/start.png, {out}/goal.png)"
        )
    try:
        plan = validate("plan", to_jsonable(plan))
    except ContractError as e:  # a frozen program's bad output: the work failed, not the user
        raise ProgramFailed(f"the frozen `plan` returned an invalid plan: {e}") from None
    (out / "plan.json").write_text(json.dumps(plan, indent=1) + "\n")
    print(json.dumps(plan, indent=None if args.compact else 2))
    print(
        ", ".join(
            f"{name} {wall[name] * 1000:.0f} ms ({cpu[name] * 1000:.0f} ms CPU)"
            for name in ("perceive", "relate", "plan")
        )
        + f"; {wall['round_trip'] * 1000:.0f} ms with the sandbox's transfers",
        file=sys.stderr,
    )
    print(f"what was perceived, its fit and the plan: {out}/", file=sys.stderr)
    return 0 if plan["status"] == "ok" else 1


class ImagesDoNotFit(RivetError):
    """The perceived objects do not explain an observation (exit 1)."""


def _write_what_was_seen(domain, out: Path, observations: dict, states, run) -> list[str]:
    """Write each side's perceived state, its fit and its overlay under `out`; what does not
    fit ([] when both fit)."""
    import cv2

    from artifacts.fit import fit_overlay, scene_fit
    from contracts import to_jsonable

    out.mkdir(parents=True, exist_ok=True)
    lost = []
    for (side, obs), state in zip(observations.items(), states, strict=True):
        try:
            fit = scene_fit(domain, obs, state["objects"], run.render)
        except (RivetError, ValueError, KeyError, TypeError) as e:  # the frozen render's fault
            why = f"the fit cannot be judged: the frozen `render` gave no usable image ({e})"
            print(f"rivet solve: {side}: {why}", file=sys.stderr)
            (out / f"{side}.json").write_text(
                json.dumps(to_jsonable({**state, "fit": {"ok": None, "problems": [why]}}))
            )
            continue
        (out / f"{side}.json").write_text(
            json.dumps(to_jsonable({**state, "fit": fit.to_dict()}), indent=1) + "\n"
        )
        picture = cv2.cvtColor(fit_overlay(obs, fit), cv2.COLOR_RGB2BGR)
        cv2.imwrite(str(out / f"{side}.png"), picture)
        lost += [f"{side}: {p}" for p in fit.problems[:3]]
    return lost


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
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="where the perceived states, their fit, overlays and the plan go "
        "(default runs/solve/DOMAIN/<time>/)",
    )
    p.set_defaults(handler=run)
