"""The arm along whole construction orders, without physics: every step of the oracle's plan
(ground-truth start, the reference construction order) planned by the executor's own transfer
planner — grasp choice among the believed neighbours, IK tick by tick, the long way round and
the joint-space alternatives — from where the previous step left the arm.

`benchmarks.reach_sweep` asks whether each pose alone has a reachable grasp from the ready
posture; a trial reaches each pick and place from the configuration the last transfer ended in,
among other objects. This walks those chains on many more dev-side instances than trials can
(seconds per instance instead of a minute). A refusal here (`unreachable`, `no_grasp`) is a
step where the executor's planner gives up from that arm configuration. A trial's chain
differs by the in-hand corrections (tenths of a millimetre at each place), which can tip a
marginal step either way, so a refusal marks a fragile step rather than a certain trial
failure: the three found on fresh assembly draws (seeds 60090, 60337, 61253; each fixed since,
tests/sim/test_executor.py) passed as trials where tried (60090, 60337).

Usage:
    python -m benchmarks.transfer_sweep [--domain assembly] [--dev]
        [--seed S | --composed S] [--count N] [--grasps K]
`--dev`: the dev benchmark's 60 instances; `--seed S`: N fresh dev draws from seed S (as
`rivet eval --seed`); `--composed S`: the composed goals of seeds S, S+1, … (as `rivet eval
--composed`, N seeds tried); `--grasps K`: at most K grasp candidates a step, a stress test of
the fallbacks (long way, joint-space approach, joint-space transfer) that the best grasps
rarely need. Prints each refusal and the totals, with how the planned steps go; exit 1 when
there is a refusal.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

import domains
from domains.errors import GenerationError
from sim import robot
from sim.execution import ExecutorConfig
from sim.ik import ArmIK
from sim.transfer import Chosen, TransferAbort, TransferPlanner, obstacles
from sim.trials import OraclePolicy


def planner(grasps: int | None = None) -> TransferPlanner:
    """The executor's transfer planner, as `sim.executor.Executor` builds it (its tick is the
    control period); with `grasps`, limited to that many grasp candidates a step."""
    ik = ArmIK()
    config = ExecutorConfig()
    if grasps is not None:
        config = replace(config, max_grasp_candidates=grasps)
    wrist = tuple(robot.RobotIndex.from_model(ik.model).arm_range[6])
    return TransferPlanner(ik, config, wrist, config.control_dt)


def walk(
    domain: Any,
    start: Sequence[Mapping],
    steps: Sequence[Mapping],
    transfers: TransferPlanner,
    ways: Counter[str] | None = None,
) -> tuple[int, str | None]:
    """(steps planned, the first refusal described or None) for `steps` from `start` (records),
    the arm starting at READY, each moved object then believed at its target. Counts into
    `ways` how each planned step goes (`way`)."""
    meshes = {r["id"]: domain.mesh(r["mesh"]) for r in start}
    symmetries = {r["id"]: list(domain.symmetries(r["mesh"])) for r in start}
    belief = {r["id"]: np.asarray(r["pose"], float) for r in start}
    q = robot.READY_QPOS.copy()
    for k, step in enumerate(steps):
        oid, target = step["object"], np.asarray(step["target_pose"], float)
        try:
            chosen = transfers.choose(
                q,
                robot.GRIPPER_OPEN,
                meshes[oid],
                symmetries[oid],
                belief[oid],
                target,
                obstacles(belief, meshes, oid),
            )
            place = transfers.place_segments(
                chosen.pick[-1].q[-1],
                chosen.grasp,
                target @ symmetries[oid][chosen.grasp.symmetry],
                chosen.transfer_z,
                long_way=chosen.long_way,
                transfer_q=chosen.transfer_q,
            )
        except TransferAbort as abort:
            return k, f"step {k} ({oid}): {abort.kind} at the {abort.phase}: {abort.reason}"
        q = place[-1].q[-1]
        belief[oid] = target
        if ways is not None:
            ways[way(chosen)] += 1
    return len(steps), None


def way(chosen: Chosen) -> str:
    """How a chosen transfer goes: `cartesian` all along, the transfer the `long way` round,
    the move above the object in joint space (`joint approach`), or the transfer in joint
    space (`joint transfer`, the last resort)."""
    if chosen.transfer_q is not None:
        return "joint transfer"
    if any(p.segment.q_goal is not None for p in chosen.pick):
        return "joint approach"
    return "long way" if chosen.long_way else "cartesian"


def instances(domain: Any, *, dev: bool, seed: int | None, composed: int | None, count: int):
    """The chosen dev-side instances, one at a time."""
    if dev:
        yield from domain.benchmark("dev")
    if seed is not None:
        from sim.settle import physical_problems

        for k in range(count):
            try:
                yield domain.generate(seed + k, physics=physical_problems, split="dev")
            except GenerationError as e:
                print(f"seed {seed + k}: no instance ({e})", file=sys.stderr)
    if composed is not None:
        for s in range(composed, composed + count):
            instance = domain.composed_instance(s)
            if instance is not None:
                yield instance


def sweep(
    domain: Any,
    chosen: Iterator,
    grasps: int | None = None,
    ways: Counter[str] | None = None,
) -> tuple[int, int, list[str]]:
    """(instances, steps planned, refusals described) over `chosen` instances, with at most
    `grasps` grasp candidates a step; how the steps go is counted into `ways`."""
    transfers = planner(grasps)
    n = planned = 0
    refused = []
    for instance in chosen:
        n += 1
        steps = OraclePolicy().solve_from_truth(instance, domain).plan["steps"]
        done, why = walk(domain, instance.start["objects"], steps, transfers, ways)
        planned += done
        if why is not None:
            refused.append(f"{instance.name}: {why}")
            print(refused[-1], file=sys.stderr, flush=True)
        if n % 25 == 0:
            print(f"… {n} instances, {planned} steps, {len(refused)} refused", file=sys.stderr)
    return n, planned, refused


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default="assembly", choices=domains.names())
    ap.add_argument("--dev", action="store_true", help="the dev benchmark's instances")
    source = ap.add_mutually_exclusive_group()
    source.add_argument("--seed", type=int, help="fresh dev draws from this seed")
    source.add_argument("--composed", type=int, help="composed goals from this seed")
    ap.add_argument("--count", type=int, default=100, help="draws or seeds tried [100]")
    ap.add_argument(
        "--grasps",
        type=int,
        metavar="K",
        help="at most K grasp candidates a step (the executor tries "
        f"{ExecutorConfig().max_grasp_candidates}); fewer makes the fallbacks carry more steps",
    )
    args = ap.parse_args(argv)
    if not (args.dev or args.seed is not None or args.composed is not None):
        ap.error("choose --dev, --seed S or --composed S")
    if args.grasps is not None and args.grasps < 1:
        ap.error(f"--grasps must be at least 1, not {args.grasps}")
    domain = domains.load(args.domain)
    t0 = time.perf_counter()
    chosen = instances(
        domain, dev=args.dev, seed=args.seed, composed=args.composed, count=args.count
    )
    ways: Counter[str] = Counter()
    n, planned, refused = sweep(domain, chosen, args.grasps, ways)
    how = ", ".join(f"{k} {v}" for k, v in ways.most_common())
    print(
        f"{args.domain}: {n} instances, {planned} steps planned ({how}), {len(refused)} refused "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    return 1 if refused else 0


if __name__ == "__main__":
    raise SystemExit(main())
