"""What trials `rivet eval`'s options name: the policy, the instances, the cameras and the
protocol. Shared by the evaluation (`rivet.commands.eval`) and the reliability study
(`rivet.commands._study`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from contracts.errors import UsageError, user_input

VIEWS = ("front", "view1", "view2")  # the named views `--view all` runs


def _policy(values: list[str]) -> tuple[str, str | None]:
    if values == ["oracle"] or values == ["artifacts"]:
        return values[0], None
    if len(values) == 2 and values[0] in ("programs", "artifacts", "runs"):
        return values[0], values[1]
    raise UsageError(
        "--policy must be 'oracle', 'programs DIR', 'artifacts' or 'runs RUNS_DIR'; "
        f"got {' '.join(values)!r}"
    )


def _instances(domain, args: argparse.Namespace) -> list[dict]:
    chosen = [o for o, v in (("--seed", args.seed), ("--composed", args.composed)) if v is not None]
    if len(chosen) + bool(args.instances) > 1:
        raise UsageError(f"{', '.join(chosen + ['--instances'] * bool(args.instances))}: pick one")
    if args.instances:
        from sim.scene import load_instance

        files = (
            sorted(Path(args.instances).glob("*.json"))
            if Path(args.instances).is_dir()
            else [Path(args.instances)]
        )
        if not files:
            raise UsageError(f"--instances {args.instances}: no .json instance files")
        out = []
        for f in files:
            with user_input():  # the user's instance file: a malformed one exits 2
                _, inst = load_instance(f)
            d = inst.to_dict()
            d["name"] = d.get("name") or f.stem
            out.append(d)
        return out[: args.trials] if args.trials else out
    if args.composed is not None:
        return _composed(domain, args.composed, args.trials or 60)
    if args.seed is not None:
        n = args.trials or 60
        from sim.settle import physical_problems

        return [
            domain.generate(args.seed + k, physics=physical_problems, split=args.split).to_dict()
            for k in range(n)
        ]
    bench = domain.benchmark(split=args.split)
    # start-major order, so that a short run still covers many goals
    ordered = sorted(bench, key=lambda i: (i.name.split("_start")[-1], i.name))
    return [i.to_dict() for i in ordered[: args.trials or len(ordered)]]


def _composed(domain, seed: int, n: int) -> list[dict]:
    """`n` instances of goals composed from the task text's parts outside every catalogue
    (`Domain.composed_instance`: never the test split's families), from seeds `seed`, `seed` + 1,
    … (a seed without a scene or an executable order is skipped)."""
    out: list[dict] = []
    for s in range(seed, seed + 50 * n):
        inst = domain.composed_instance(s)
        if inst is not None:
            out.append(inst.to_dict())
            if len(out) == n:
                return out
        elif not out and s - seed >= 49:
            raise UsageError(f"--composed: {domain.name} composes no goals (seeds {seed}–{s})")
    raise UsageError(f"--composed {seed}: only {len(out)} of {n} seeds gave an instance")


def protocol_of(args: argparse.Namespace):
    """The trial protocol the options name (`--protocol oracle-sensing` is clean images, the true
    camera, an exact in-hand pose and a ground-truth object tracker)."""
    from sim.trials import HONEST, ORACLE_SENSING, TrialProtocol

    if args.protocol == "previous":  # the old name, kept for scripts that use it
        print("warning: --protocol previous is now --protocol oracle-sensing", file=sys.stderr)
    base = ORACLE_SENSING if args.protocol in ("oracle-sensing", "previous") else HONEST
    return TrialProtocol(
        realism=args.realism or base.realism,
        in_hand=args.in_hand or base.in_hand,
        track_objects=args.track_objects or base.track_objects,
        weld_assist=args.weld_assist,
        camera_offset=not args.no_camera_offset,
    )


def cameras_of(args: argparse.Namespace) -> list[tuple[str, object]]:
    """(label, camera) per camera to evaluate: named views, then camera files."""
    out: list[tuple[str, object]] = []
    if args.camera:
        from sim.observation import load_camera

        out += [(Path(f).stem, load_camera(f)) for f in args.camera]
    if not args.camera or args.view != "front" or args.all:
        views = VIEWS if args.all or args.view == "all" else [args.view]
        out = [(v, None) for v in views] + out
    return out
