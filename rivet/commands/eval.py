"""`rivet eval DOMAIN`: run trials — observe start and goal, plan with a policy, execute on the
simulated FR3 + 2F-85, score — and print the metrics, timings and every failure.

Policies: `oracle` (ground truth + the generator's construction order: the executor alone),
`programs DIR` (render/perceive/relate/plan .py files in DIR), `artifacts` (the frozen,
hash-checked programs of artifacts/DOMAIN), `runs RUNS_DIR` (a reliability study: each
authoring run's final programs under RUNS_DIR on the first `--pairs K` pairs, per run and
pooled; experiments/reliability.py). Trials come from the fixed benchmark set
(20 goals × 3 starts) unless `--seed`, `--composed` or `--instances` says otherwise.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from contracts.errors import UsageError
from rivet.commands._options import add_sandbox_option, int_at_least
from rivet.commands._trials import VIEWS, _instances, _policy, cameras_of, protocol_of


def _eval_one(domain_name: str, args: argparse.Namespace, view: str, camera: object) -> dict:
    from dataclasses import asdict

    import domains
    from artifacts.provenance import run_record
    from experiments.evaluation import EvalConfig, TrialLog, progress_bar, run_eval, table
    from sim.faults import parse_faults

    domain = domains.load(domain_name)
    policy = _policy(args.policy)
    set_hash = None
    if policy[0] == "artifacts":
        from artifacts import unchecked_note, verify

        # fail fast, exit 1 naming the file
        manifest, _ = verify(domain_name, Path(policy[1]) if policy[1] else None)
        set_hash = manifest["set_hash"]
        if note := unchecked_note(domain_name, manifest):
            print(note, file=sys.stderr)
    instances = _instances(domain, args)
    config = EvalConfig(
        domain=domain_name,
        policy=policy,
        view=view,
        camera=camera,
        protocol=protocol_of(args),
        split=args.split,
        sandbox=args.sandbox,
        record_root=str(Path(args.record) / domain_name / view) if args.record else None,
        loop=args.loop,
        faults=parse_faults(args.faults),
        fit=args.fit,
    )
    path = _log_path(args, domain_name, view)
    log = TrialLog(
        path,
        {
            **{k: v for k, v in asdict(config).items() if k not in ("sandbox", "record_root")},
            "set_hash": set_hash,
            "trials": [inst.get("name") for inst in instances],
        },
        resume=args.resume,
    )
    if not args.quiet:
        kept = f": {log.earlier()} of {len(instances)} trials kept" if args.resume else ""
        print(f"trial log {path}{kept}", file=sys.stderr)
    started = time.perf_counter()
    try:
        summary = run_eval(
            config,
            instances,
            workers=args.workers,
            ray_address=args.ray,
            progress=None if args.quiet else progress_bar(len(instances), f"{domain_name}/{view}"),
            log=log,
        )
    except KeyboardInterrupt:
        print(
            f"the finished trials are kept in {path}; the same command with --resume runs the rest",
            file=sys.stderr,
        )
        raise
    wall = time.perf_counter() - started
    print(table(summary))
    if set_hash is not None:
        summary["set_hash"] = set_hash  # which programs ran
    summary["run"] = {**run_record(getattr(args, "argv", None)), "wall_s": round(wall, 1)}
    return summary


def _log_path(args: argparse.Namespace, domain: str, view: str) -> Path:
    """Where an evaluation's trials are streamed: beside `--json OUT` (OUT's stem, the domain
    and the view), else under runs/eval/ (like `rivet author`'s runs/)."""
    if args.json:
        out = Path(args.json)
        return out.with_name(f"{out.stem}.{domain}.{view}.trials.jsonl")
    kind = _policy(args.policy)[0]
    extra = ("-closed" if args.loop == "closed" else "") + ("-faults" if args.faults else "")
    return Path("runs") / "eval" / domain / f"{view}-{args.split}-{kind}{extra}.trials.jsonl"


def _check_robot_models() -> None:
    """The robot's models load (MENAGERIE_ROOT, the menagerie package): else every trial would
    fail the same way and be scored as a failed trial. Building the robot without its visual
    meshes compiles the full robot once (`sim.robot.geom_inertials`), here, before any trial
    holds memory: the compile's transient peak does not add to a trial's."""
    from sim.errors import RobotModelError
    from sim.robot import build_robot_spec

    try:
        build_robot_spec(visuals=False)
    except RobotModelError as e:
        raise UsageError(f"the simulator cannot run: {e}") from None


def run(args: argparse.Namespace) -> int:
    import domains
    from artifacts.store import ROOT as ARTIFACTS_ROOT
    from experiments.evaluation import PAPER, write_json
    from sim.trials import HONEST

    if _policy(args.policy)[0] == "runs" or args.pairs is not None:
        from rivet.commands._study import run_study_command

        return run_study_command(args)
    if not args.all and args.domain is None:
        raise UsageError("name a DOMAIN or pass --all")
    names = domains.names() if args.all else [domains.load(args.domain).name]
    from sim.faults import parse_faults

    parse_faults(args.faults)  # a usage error before any work
    if args.loop == "closed" and _policy(args.policy)[0] == "oracle":
        raise UsageError(
            "--loop closed needs programs to look again with (--policy artifacts, programs "
            "DIR or run DIR); the oracle perceives nothing"
        )
    _check_robot_models()  # a configuration problem is found before the first trial
    kind, folder = _policy(args.policy)
    if kind == "artifacts" and folder is not None:  # a folder of frozen sets, like artifacts/
        for name in names:
            if not (Path(folder) / name / "manifest.json").is_file():
                raise UsageError(
                    f"--policy artifacts {folder}: no frozen {name} set there "
                    f"({Path(folder) / name / 'manifest.json'} is missing); DIR holds one "
                    f"folder per domain, as artifacts/ does (--policy programs DIR reads a "
                    "folder of four programs)"
                )
    cams = cameras_of(args)
    results: dict[str, dict[str, dict]] = {}
    for name in names:
        for view, camera in cams:
            results.setdefault(name, {})[view] = _eval_one(name, args, view, camera)
    if args.json:
        out = results[names[0]][cams[0][0]] if len(names) == 1 and len(cams) == 1 else results
        write_json(out, Path(args.json))
    if (
        _policy(args.policy)[0] == "artifacts"
        and args.seed is None
        and args.composed is None
        and not args.instances
        and not args.trials
        and args.split == "dev"
        and protocol_of(args) == HONEST
        and args.loop == "open"
        and not args.faults
    ):
        for name in names:
            if "front" in results[name]:
                front = results[name]["front"]
                front["views"] = {v: results[name][v]["final_sr"] for v in results[name]}
                folder = _policy(args.policy)[1]  # where the programs were read from
                root = (Path(folder) if folder else ARTIFACTS_ROOT) / name
                write_json(front, root / "eval.json")
                (root / "eval.stale.json").unlink(missing_ok=True)  # superseded
    if args.all and all("front" in results[n] and "view1" in results[n] for n in names):
        print("\nTable I (front camera) — ours vs paper")
        print(f"  {'domain':<10} {'state_ac':>16} {'plan_sr':>16} {'final_sr':>16}")
        for name in names:
            r, p = results[name]["front"], PAPER.get(name, {})
            cells = [
                f"{100 * r[k]:5.1f}% / {100 * p.get(k, float('nan')):5.1f}%"
                for k in ("state_ac", "plan_sr", "final_sr")
            ]
            print(f"  {name:<10} " + " ".join(f"{c:>16}" for c in cells))
        print("\nTable III (final success by viewpoint) — ours vs paper")
        print(f"  {'domain':<10} {'view1':>16} {'view2':>16}")
        for name in names:
            p = PAPER.get(name, {})
            cells = [
                f"{100 * results[name][v]['final_sr']:5.1f}% / {100 * p.get(v, float('nan')):5.1f}%"
                for v in ("view1", "view2")
            ]
            print(f"  {name:<10} " + " ".join(f"{c:>16}" for c in cells))
    all_ok = all(r["final_sr"] == 1.0 for per in results.values() for r in per.values())
    return 0 if all_ok else 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval", help="run start/goal trials in the simulator and score them", description=__doc__
    )
    p.add_argument("domain", nargs="?", metavar="DOMAIN")
    p.add_argument(
        "--all", action="store_true", help="every domain, every view; prints Tables I and III"
    )
    p.add_argument(
        "--policy",
        nargs="+",
        default=["artifacts"],
        metavar="POLICY",
        help="oracle | programs DIR | artifacts (default) | runs RUNS_DIR",
    )
    p.add_argument(
        "--trials", type=int_at_least(1), default=None, metavar="N", help="run the first N trials"
    )
    p.add_argument(
        "--pairs",
        type=int_at_least(1),
        default=None,
        metavar="K",
        help="--policy runs: each run on the first K start/goal pairs of --split (default 6)",
    )
    p.add_argument(
        "--view",
        choices=(*VIEWS, "all"),
        default="front",
        help="observation camera ('all': each in turn)",
    )
    p.add_argument(
        "--seed",
        type=int_at_least(0),
        default=None,
        help="a fresh generated set of --split's goal and start families from seeds S, S+1, … "
        "instead of the benchmark",
    )
    p.add_argument(
        "--composed",
        type=int_at_least(0),
        default=None,
        metavar="SEED",
        help="goals composed from the task text's parts outside every catalogue (dev-side, never "
        "the test families) from seeds S, S+1, …, starts drawn as dev starts",
    )
    p.add_argument(
        "--instances",
        default=None,
        metavar="DIR",
        help="instance files to run instead of the benchmark",
    )
    p.add_argument(
        "--workers", type=int_at_least(1), default=1, metavar="N", help="trials in N processes"
    )
    p.add_argument(
        "--ray",
        default=None,
        metavar="ADDRESS",
        help="fan trials out to a Ray cluster ('local' starts one)",
    )
    p.add_argument("--json", default=None, metavar="OUT", help="write the results JSON here")
    p.add_argument(
        "--record",
        default=None,
        metavar="DIR",
        help="write an MP4 + start/goal/final PNGs per trial",
    )
    p.add_argument(
        "--split",
        choices=("dev", "test"),
        default="dev",
        help="benchmark split: dev (tune on it) or test (report it, never tune on it)",
    )
    p.add_argument(
        "--camera",
        action="append",
        default=[],
        metavar="FILE.json",
        help="a camera file (DESIGN camera format); repeatable; replaces --view unless given",
    )
    p.add_argument(
        "--realism",
        choices=("clean", "default", "harsh"),
        default=None,
        help="observation realism (default: default; see docs/observations.md)",
    )
    p.add_argument(
        "--in-hand",
        choices=("wrist", "exact", "none"),
        default=None,
        help="in-hand pose estimate after the grasp: a wrist camera (default), exact, none",
    )
    p.add_argument(
        "--no-camera-offset",
        action="store_true",
        help="the executor takes perceived poses as they are, not corrected for the camera's "
        "calibration offset it reads with the wrist camera (see docs/executor.md)",
    )
    p.add_argument(
        "--track-objects",
        action="store_true",
        help="give the executor every object's true pose before each pick (no real robot can)",
    )
    p.add_argument(
        "--protocol",
        choices=("honest", "oracle-sensing", "previous"),
        default="honest",
        help="oracle-sensing: --realism clean --in-hand exact --track-objects (sensing no real "
        "robot has: measures what perception errors cost); previous: its old name",
    )
    add_sandbox_option(p, what="the policy's programs")
    p.add_argument(
        "--weld-assist",
        action="store_true",
        help="contact-gated weld assist (see docs/executor.md)",
    )
    p.add_argument(
        "--loop",
        choices=("open", "closed"),
        default="open",
        help="open (default, the paper's protocol): the plan runs to its end; closed: after each "
        "transfer the robot looks again and replans with the same programs (docs/executor.md)",
    )
    p.add_argument(
        "--faults",
        default=None,
        metavar="NAME[,NAME]|all",
        help="inject one fault per trial, drawn from these (slip, push, move, bias, skip: "
        "sim.faults.FAULTS, docs/executor.md)",
    )
    p.add_argument(
        "--fit",
        action="store_true",
        help="also judge how well each perceived state explains its image, as `rivet solve` "
        "does (artifacts.fit), into each trial's JSON (about 0.5 s a trial)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted evaluation: the trials its trial log holds are kept, the "
        "rest are run (the log is beside --json OUT, else under runs/eval/)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=run)
