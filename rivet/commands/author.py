"""`rivet author DOMAIN`: have a model (or a replayed transcript) write the domain's four
programs, check every draft in the sandbox, and freeze the passing set in `artifacts/<domain>/`.

Offline by default: with neither `--model` nor `--replay`, it replays
`domains/<domain>/transcripts/reference`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from contracts.errors import UsageError

RUNS = Path("runs")


def _client(args: argparse.Namespace, domain, run_dir: Path):
    from agent.clients import AnthropicClient, Budget, RecordingClient, ReplayClient

    budget = Budget(max_usd=args.max_usd, max_calls=args.max_calls)
    if args.model:
        inner = AnthropicClient(args.model, budget=budget)
        return RecordingClient(inner, run_dir / "transcript", domain=domain.name)
    replay = args.replay or domain.reference_transcript
    if not (Path(replay) / "meta.json").is_file():
        raise UsageError(
            f"no transcript at {replay}: pass --replay DIR, or --model M with ANTHROPIC_API_KEY set"
        )
    return ReplayClient(Path(replay), strict=args.strict, budget=budget)


def run(args: argparse.Namespace) -> int:
    import domains
    from agent.checking import SuiteChecker
    from agent.context import build_context, reference_observations
    from toolbox.docs import toolbox_docs

    domain = domains.load(args.domain)
    runs_root = Path(args.runs_dir)
    if args.ray:
        return _author_on_ray(args, domain.name, runs_root)
    ctx = build_context(domain, reference_observations(domain), toolbox_docs())
    checker = SuiteChecker(sandbox=args.sandbox, thorough=args.thorough)
    results: list[bool] = []
    try:
        _author_runs(args, domain, ctx, checker, runs_root, results)
    finally:
        checker.close()
    if args.runs > 1:
        print(f"{sum(results)}/{args.runs} runs produced a complete checked set")
    return 0 if all(results) else 1


def _run_cli(argv: list[str]) -> int:
    import subprocess

    return subprocess.run(argv).returncode


def _author_on_ray(args: argparse.Namespace, domain: str, runs_root: Path) -> int:
    """`--runs N --ray ADDRESS`: each run is one Ray task running `rivet author --runs 1` on a
    node (which needs the project, Docker and the sandbox image; the key, if any, comes from
    the node's own ANTHROPIC_API_KEY)."""
    from rivet.scaleout import map_tasks

    source = (
        ["--model", args.model]
        if args.model
        else ["--replay", str(Path(args.replay).resolve())]
        if args.replay
        else []
    )
    argvs = []
    for k in range(args.runs):
        out = (runs_root / f"ray-{k + 1:03d}").resolve()
        argvs.append(
            [
                sys.executable,
                "-m",
                "rivet.cli",
                "author",
                domain,
                *source,
                "--runs-dir",
                str(out),
                "--artifacts",
                str(out / "artifacts"),
                "--attempts",
                str(args.attempts),
                "--sandbox",
                args.sandbox,
            ]
            + (["--max-usd", str(args.max_usd)] if args.max_usd is not None else [])
            + (["--max-calls", str(args.max_calls)] if args.max_calls is not None else [])
        )
    codes = map_tasks(args.ray, _run_cli, argvs)
    ok = sum(c == 0 for c in codes)
    print(
        f"{ok}/{args.runs} runs produced a complete checked set (Ray: {args.ray}); runs under {runs_root}/ray-*"
    )
    return 0 if ok == args.runs else 1


def _author_runs(args, domain, ctx, checker, runs_root: Path, results: list[bool]) -> None:
    from agent.errors import AgentError
    from agent.journal import Journal, latest_run_dir, new_run_dir
    from agent.loop import AuthoringRun
    from agent.prompt import templates_hash
    from agent.report import summary, write_report
    from artifacts import build_manifest, freeze

    for i in range(args.runs):
        run_dir = None
        if args.resume:
            run_dir = latest_run_dir(runs_root, domain.name)
            if run_dir is None:
                raise UsageError(f"--resume: no earlier run of {domain.name} under {runs_root}/")
        run_dir = run_dir or new_run_dir(runs_root, domain.name)
        print(f"run {i + 1}/{args.runs}: {run_dir}", file=sys.stderr)
        journal = Journal(run_dir)
        client = _client(args, domain, run_dir)
        try:
            frozen = AuthoringRun(
                ctx=ctx, client=client, checker=checker, journal=journal, max_attempts=args.attempts
            ).run()
        except AgentError as e:
            report = write_report(journal, f"RIVET authoring run — {domain.name}")
            print(f"authoring failed: {e}\nreport: {report}", file=sys.stderr)
            results.append(False)
            if args.runs == 1:
                raise
            continue
        report = write_report(journal, f"RIVET authoring run — {domain.name}")
        results.append(True)
        if args.runs > 1:
            continue  # reliability studies: keep each run's programs under runs/, freeze none
        per_fn = summary(journal)
        manifest = build_manifest(
            domain.name,
            frozen,
            author=client.author.to_dict(),
            prompt_hash=templates_hash(),
            attempts={f: s["attempts"] for f, s in per_fn.items()},
            checks={f: s["checks"] for f, s in per_fn.items()},
        )
        changed = freeze(
            domain.name, frozen, manifest, Path(args.artifacts) if args.artifacts else None
        )
        state = "written" if changed else "unchanged"
        print(f"artifacts/{domain.name}: {state}, set hash {manifest['set_hash']}")
        print(f"report: {report}")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "author", help="author a domain's programs (offline replay by default)", description=__doc__
    )
    p.add_argument("domain", metavar="DOMAIN")
    src = p.add_mutually_exclusive_group()
    src.add_argument(
        "--model",
        help="author with this Claude model (key from ANTHROPIC_API_KEY), e.g. claude-opus-5",
    )
    src.add_argument("--replay", type=Path, metavar="DIR", help="replay a transcript folder")
    p.add_argument(
        "--strict",
        action="store_true",
        help="replay: fail on any request not recorded byte-for-byte",
    )
    p.add_argument(
        "--resume", action="store_true", help="continue the latest run of DOMAIN under --runs-dir"
    )
    p.add_argument(
        "--attempts", type=int, default=4, metavar="K", help="attempts per function (default 4)"
    )
    p.add_argument(
        "--max-usd",
        type=float,
        default=None,
        metavar="X",
        help="dollar budget, checked before each call",
    )
    p.add_argument("--max-calls", type=int, default=None, metavar="N", help="model-call budget")
    p.add_argument(
        "--runs",
        type=int,
        default=1,
        metavar="N",
        help="author N independent systems (no freezing)",
    )
    p.add_argument(
        "--sandbox",
        choices=("docker", "local"),
        default="docker",
        help="where drafts run (local isolates nothing)",
    )
    p.add_argument("--thorough", action="store_true", help="more property-test examples per check")
    p.add_argument(
        "--ray",
        default=None,
        metavar="ADDRESS",
        help="with --runs N: one Ray task per run ('local' starts Ray here)",
    )
    p.add_argument("--runs-dir", default=str(RUNS), help="where run journals go (default runs/)")
    p.add_argument(
        "--artifacts", default=None, help="artifact root (default: the repository's artifacts/)"
    )
    p.set_defaults(handler=run)
