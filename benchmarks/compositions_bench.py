"""A domain's plan on compositions the task text allows, not only the catalogue's.

The cubes task text promises "stacks, towers, pyramids and rows" of six 40 mm cubes, the
assembly one bridges, gates, houses and towers; the dev catalogues list some of them and the
test splits their own. This draws any such goal (`Domain.compose`: `domains.cubes.
task_structure`, `domains.assembly.task_structure`, the tangram's composed figures), started as
dev draws are, and asks of a `plan` what the robot asks: every step leaves the fingers room at
the pick and at the place (the executor's hand model; the arm's reach is not tested). A draw
counts as feasible when the generator's own robot planner finds an order.

Usage:
    python -m benchmarks.compositions_bench [--domain cubes] [--plan PATH] [--seed 50000]
        [--draws 200] [--out DIR]
Writes DIR/bench_compositions_DOMAIN.json (one row per draw) and prints the totals.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

import domains
from domains.errors import GenerationError


def draw(domain: Any, seed: int) -> tuple[list[dict], list[dict], bool] | None:
    """(start, goal, feasible) of a task-text composition (`Domain.compose`), or None when
    `seed` gives no scene."""
    drawn = domain.compose(seed)
    if drawn is None:
        return None
    start, goal = drawn
    try:
        domain.robot_reference_planner.order(start, goal)
    except GenerationError:
        return start, goal, False
    return start, goal, True


def hand_problem(domain: Any, start: Sequence[Mapping], steps: Sequence[Mapping]) -> str | None:
    """The first step the hand model finds no grasp with room for (None: every step has one)."""
    state = {r["id"]: (r["mesh"], np.asarray(r["pose"], float)) for r in start}
    for k, step in enumerate(steps):
        oid = step["object"]
        mesh, pose = state[oid]
        target = np.asarray(step["target_pose"], float)
        others = {j: v for j, v in state.items() if j != oid}
        verdict = domain.grasps.move(oid, mesh, pose, target, others, limit=1)
        if not verdict.ok:
            return f"step {k} ({oid}): {verdict.reason}"
        state[oid] = (mesh, target)
    return None


def load_plan(path: Path) -> Callable[..., dict]:
    spec = importlib.util.spec_from_file_location(f"_plan_{abs(hash(str(path)))}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.plan


def verdict(domain: Any, plan: Callable[..., dict], start: list, goal: list) -> str:
    """ "ok", "infeasible: …" or the first step without room."""
    out = plan(domain.scene(start), domain.scene(goal), domain.meshes())
    if out.get("status") != "ok":
        return f"infeasible: {out.get('reason')}"
    return hand_problem(domain, start, out["steps"]) or "ok"


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default="cubes", choices=domains.names())
    ap.add_argument("--plan", type=Path, help="default: domains/DOMAIN/programs/plan.py")
    ap.add_argument("--seed", type=int, default=50000)
    ap.add_argument("--draws", type=int, default=200)
    ap.add_argument("--out", type=Path, default=Path("runs/bench"))
    args = ap.parse_args(argv)
    domain = domains.load(args.domain)
    args.plan = args.plan or domain.root / "programs" / "plan.py"
    plan = load_plan(args.plan)
    rows, t0 = [], time.perf_counter()
    for seed in range(args.seed, args.seed + args.draws):
        drawn = draw(domain, seed)
        if drawn is None:
            continue
        start, goal, feasible = drawn
        rows.append(
            {"seed": seed, "feasible": feasible, "plan": verdict(domain, plan, start, goal)}
        )
        print(f"[{len(rows)}] seed {seed}: {rows[-1]['plan'][:90]}", file=sys.stderr)
    feasible = [r for r in rows if r["feasible"]]
    totals = {
        "plan": str(args.plan),
        "draws": len(rows),
        "feasible": len(feasible),
        "ok_on_feasible": sum(r["plan"] == "ok" for r in feasible),
        "ok_on_all": sum(r["plan"] == "ok" for r in rows),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"bench_compositions_{args.domain}.json").write_text(
        json.dumps({"totals": totals, "rows": rows}, indent=1)
    )
    print(json.dumps(totals))
    return 0 if totals["ok_on_feasible"] == totals["feasible"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
