"""`rivet eval DOMAIN --policy runs RUNS_DIR --pairs K`: a reliability study.

Each authoring run under RUNS_DIR (`rivet author DOMAIN --runs N --runs-dir RUNS_DIR`) has its
final programs evaluated — in a sandbox session of their own, policy `run RUN_DIR` — on the
first K start/goal pairs of `--split` (start-major order, as `--trials` takes them); runs that
did not finish authoring are reported as failed runs. Prints the per-run and the pooled table
(experiments/reliability.py) and writes both with `--json OUT`. Exit 0 only when every run finished
and solved every pair.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from contracts.errors import UsageError

PAPER_PAIRS = 6  # the paper's study: 10 runs × 6 pairs


def run_study_command(args: argparse.Namespace) -> int:
    import domains
    from artifacts.policy import find_runs
    from experiments.evaluation import EvalConfig, progress_bar, write_json
    from experiments.reliability import StudyRun, run_study, study_table
    from rivet.commands._trials import _instances, _policy, cameras_of, protocol_of

    kind, runs_dir = _policy(args.policy)
    if kind != "runs":
        raise UsageError("--pairs K is for a reliability study: --policy runs RUNS_DIR --pairs K")
    if args.all or args.domain is None:
        raise UsageError("--policy runs studies one DOMAIN (not --all)")
    if args.trials is not None:
        raise UsageError(
            "--policy runs takes --pairs K (the pairs each run is evaluated on), not --trials"
        )
    if args.record:
        raise UsageError("--record is not supported with --policy runs")
    pairs = PAPER_PAIRS if args.pairs is None else args.pairs
    if pairs < 1:
        raise UsageError(f"--pairs must be at least 1; got {pairs}")
    cams = cameras_of(args)
    if len(cams) != 1:
        raise UsageError("--policy runs evaluates on one camera: pick one --view or --camera")
    ((view, camera),) = cams
    domain = domains.load(args.domain)
    assert runs_dir is not None
    runs = [
        StudyRun(r.name, r.policy, r.reason, r.started)
        for r in find_runs(domain.name, Path(runs_dir))
    ]
    args.trials = pairs  # the first K pairs, exactly as `--trials K` picks trials
    instances = _instances(domain, args)
    config = EvalConfig(
        domain=domain.name,
        policy=("runs", runs_dir),
        view=view,
        camera=camera,
        protocol=protocol_of(args),
        split=args.split,
        sandbox=args.sandbox,
    )
    study = run_study(
        config,
        runs,
        instances,
        workers=args.workers,
        ray_address=args.ray,
        progress=None
        if args.quiet
        else lambda name, n: progress_bar(n, f"{domain.name}/{view} {name}"),
    )
    study["runs_dir"] = str(runs_dir)
    print(study_table(study))
    if args.json:
        write_json(study, Path(args.json))
    every = study["finished_runs"] == study["total_runs"]
    return 0 if every and study["pooled"]["final_ok"] == study["pooled"]["trials"] else 1
