"""`rivet author DOMAIN`: have a model (or a replayed transcript) write the domain's four
programs, check every draft in the sandbox, and freeze the passing set in `artifacts/<domain>/`.

Offline by default: with none of `--model`, `--agent` or `--replay`, it replays
`domains/<domain>/transcripts/reference`. `docs/agent.md` describes the model options, the
budget rules and the `--agent` file protocol.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from contracts.errors import UsageError
from rivet.commands._options import add_sandbox_option, int_at_least

GATE_TRIALS = 8  # artifacts.gate.GATE_TRIALS (not imported here: the CLI starts light)

RUNS = Path("runs")


def _model_options(args: argparse.Namespace) -> list[str]:
    """The model-client options given (they need --model)."""
    given = []
    for flag, value in (
        ("--base-url", args.base_url),
        ("--thinking", args.thinking),
        ("--effort", args.effort),
        ("--price", args.price),
    ):
        if value is not None:
            given.append(flag)
    return given


def _client(args: argparse.Namespace, domain, run_dir: Path, budget):
    from agent.clients import (
        AgentCommandClient,
        AnthropicClient,
        OpenAIClient,
        RecordingClient,
        ReplayClient,
    )
    from agent.clients.pricing import parse_price

    price = parse_price(args.price) if args.price is not None else None
    if args.agent is not None:
        if args.max_usd is not None:
            raise UsageError(
                "--max-usd cannot be enforced with --agent: RIVET does not see an agent "
                "command's usage; limit it with --max-calls"
            )
        if _model_options(args):
            raise UsageError(f"{', '.join(_model_options(args))}: only with --model, not --agent")
        agent = AgentCommandClient(
            args.agent, work_dir=run_dir / "agent", timeout_s=args.agent_timeout, budget=budget
        )
        return RecordingClient(agent, run_dir / "transcript", domain=domain.name)
    if args.model:
        inner: OpenAIClient | AnthropicClient
        if args.model.startswith("openai:"):
            if args.thinking is not None:
                raise UsageError("--thinking is for Claude models; use --effort with openai:NAME")
            inner = OpenAIClient(
                args.model, base_url=args.base_url, budget=budget, price=price, effort=args.effort
            )
        else:
            inner = AnthropicClient(
                args.model.removeprefix("anthropic:"),
                budget=budget,
                base_url=args.base_url,
                thinking_budget=args.thinking,
                effort=args.effort,
                price=price,
            )
        return RecordingClient(inner, run_dir / "transcript", domain=domain.name)
    if _model_options(args):
        raise UsageError(f"{', '.join(_model_options(args))}: only with --model")
    replay = args.replay or domain.reference_transcript  # found by `_check_sources`
    return ReplayClient(Path(replay), strict=args.strict, budget=budget)


def _check_model_name(model: str | None) -> None:
    """A `--model` that names no Claude model and no provider: the Anthropic client would
    only say that its key is missing, so say which provider prefix was probably meant."""
    if model is None or model.startswith(("openai:", "anthropic:", "claude")):
        return
    raise UsageError(
        f"--model {model}: not a Claude model. An OpenAI-compatible model is "
        f"--model openai:{model} (with --base-url URL for a server other than OpenAI's); "
        f"write --model anthropic:{model} to send it to Anthropic's API as it is"
    )


def _check_sources(args: argparse.Namespace, domain) -> None:
    """What the client will need, checked before a run folder exists: a transcript to replay,
    or the credential of the model's provider (the clients say the same, later)."""
    import os

    from agent.clients import anthropic_client, openai_client

    if args.agent:
        return
    if not args.model:
        replay = Path(args.replay) if args.replay else domain.reference_transcript
        if not (replay / "meta.json").is_file():
            raise UsageError(
                f"no transcript at {replay}: pass --replay DIR, --model M (with "
                "ANTHROPIC_API_KEY set) or --agent COMMAND"
            )
        return
    if args.model.startswith("openai:"):
        if not os.environ.get("OPENAI_API_KEY") and not (
            args.base_url or os.environ.get("OPENAI_BASE_URL")
        ):
            raise UsageError(openai_client.MISSING_KEY)
    elif not (os.environ.get("ANTHROPIC_API_KEY") or os.environ.get("ANTHROPIC_AUTH_TOKEN")):
        raise UsageError(anthropic_client.MISSING_KEY)


def run(args: argparse.Namespace) -> int:
    import domains
    from agent.checking import SuiteChecker
    from agent.context import build_context, reference_observations
    from toolbox.docs import toolbox_docs

    _check_model_name(args.model)  # before anything is created
    domain = domains.load(args.domain)
    runs_root = Path(args.runs_dir)
    if args.ray:  # each Ray node runs `rivet author` itself, with its own environment
        return _author_on_ray(args, domain.name, runs_root)
    _check_sources(args, domain)
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
    the node's own environment). `--max-usd X` gives each run X / N."""
    from experiments.scaleout import map_tasks

    source = (
        ["--model", args.model]
        if args.model
        else ["--agent", args.agent, "--agent-timeout", str(args.agent_timeout)]
        if args.agent
        else ["--replay", str(Path(args.replay).resolve())]
        if args.replay
        else []
    )
    for flag, value in (
        ("--base-url", args.base_url),
        ("--thinking", args.thinking),
        ("--effort", args.effort),
        ("--price", args.price),
    ):
        if value is not None:
            source += [flag, str(value)]
    # each task enforces its share of the dollar budget, so that the runs together stay in it
    share = None if args.max_usd is None else args.max_usd / args.runs
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
            + (["--gate-trials", str(args.gate_trials)] if args.gate_trials is not None else [])
            + (["--max-usd", repr(share)] if share is not None else [])
            + (["--max-calls", str(args.max_calls)] if args.max_calls is not None else [])
        )
    codes = map_tasks(args.ray, _run_cli, argvs)
    ok = sum(c == 0 for c in codes)
    print(
        f"{ok}/{args.runs} runs produced a complete checked set (Ray: {args.ray}); runs under {runs_root}/ray-*"
    )
    return 0 if ok == args.runs else 1


def _author_runs(args, domain, ctx, checker, runs_root: Path, results: list[bool]) -> None:
    from agent.clients import Budget
    from agent.errors import AgentError, BudgetExceeded
    from agent.journal import Journal, latest_run_dir, new_run_dir
    from agent.loop import AuthoringRun
    from agent.prompt import templates_hash
    from agent.report import summary, write_report
    from artifacts import build_manifest, freeze
    from artifacts.store import domain_dir, stamped_set_hash

    # One ledger for the whole invocation: --runs N shares it, --resume starts from the
    # spending its journal holds.
    ledger = Budget(max_usd=args.max_usd, max_calls=args.max_calls)
    carried: set[Path] = set()
    try:
        for i in range(args.runs):
            run_dir = None
            if args.resume:
                run_dir = latest_run_dir(runs_root, domain.name)
                if run_dir is None:
                    raise UsageError(
                        f"--resume: no earlier run of {domain.name} under {runs_root}/"
                    )
            run_dir = run_dir or new_run_dir(runs_root, domain.name)
            print(f"run {i + 1}/{args.runs}: {run_dir}", file=sys.stderr)
            journal = Journal(run_dir)
            if args.resume and run_dir not in carried:
                carried.add(run_dir)
                earlier = journal.state()
                ledger.carry(earlier.spent_usd, earlier.calls)
                if earlier.calls:
                    print(
                        f"resuming: this run has spent ${earlier.spent_usd:.2f} in "
                        f"{earlier.calls} calls so far",
                        file=sys.stderr,
                    )
            client = _client(args, domain, run_dir, ledger)
            try:
                try:
                    frozen = AuthoringRun(
                        ctx=ctx,
                        client=client,
                        checker=checker,
                        journal=journal,
                        max_attempts=args.attempts,
                        cases_seed=getattr(client, "cases_seed", None),
                        gate=_gate(args, domain.name),
                    ).run()
                finally:
                    _close(client)
            except AgentError as e:
                report = write_report(journal, f"RIVET authoring run — {domain.name}")
                results.append(False)
                if args.runs == 1:
                    # the error itself is printed once, by the command line
                    print(f"report: {report}", file=sys.stderr)
                    raise
                print(f"run {i + 1} failed: {e}\nreport: {report}", file=sys.stderr)
                if isinstance(e, BudgetExceeded):
                    print("the budget is spent: no further runs", file=sys.stderr)
                    results.extend([False] * (args.runs - i - 1))
                    break
                continue
            results.append(True)
            if (
                args.runs > 1
            ):  # reliability studies: keep each run's programs under runs/, freeze none
                write_report(journal, f"RIVET authoring run — {domain.name}")
                continue
            per_fn = summary(journal)
            manifest = build_manifest(
                domain.name,
                frozen,
                author=client.author.to_dict(),
                prompt_hash=templates_hash(),
                attempts={f: s["attempts"] for f, s in per_fn.items()},
                checks={f: s["checks"] for f, s in per_fn.items()},
                cases_seeds={f: s["cases_seed"] for f, s in per_fn.items()},
            )
            root = Path(args.artifacts) if args.artifacts else None
            # the set hash a manifest is stamped with, read as eval.json's is
            before = stamped_set_hash(domain_dir(domain.name, root) / "manifest.json")
            state = "unchanged"
            report = write_report(
                journal, f"RIVET authoring run — {domain.name}", set_hash=manifest["set_hash"]
            )
            if freeze(domain.name, frozen, manifest, root):
                state = "written"
                if before == manifest["set_hash"]:
                    state = "re-stamped (the same programs, checked against the current toolbox)"
            print(f"artifacts/{domain.name}: {state}, set hash {manifest['set_hash']}")
            print(f"report: {report}")
    finally:
        if ledger.calls and (args.model or args.agent):
            limit = f" of --max-usd {ledger.max_usd:.2f}" if ledger.max_usd is not None else ""
            print(f"spent ${ledger.spent_usd:.2f}{limit} in {ledger.calls} calls", file=sys.stderr)


def _gate(args, domain: str):
    """The trial gate the run's candidate set must pass before it is frozen (None: off).

    Default: `GATE_TRIALS` trials for a model or an agent; none for a replay, which
    reproduces the recorded run, and the reference transcripts were packed without a gate
    (their sets' gate figures: docs/checks.md, "Measured on the reference programs")."""
    trials = args.gate_trials
    if trials is None:
        trials = 0 if not (args.model or args.agent) else GATE_TRIALS
    if not trials:
        return None
    from artifacts.gate import run_gate

    def gate(sources: dict[str, str], seed: int, out: Path):
        return run_gate(
            domain,
            sources,
            seed=seed,
            trials=trials,
            sandbox=args.sandbox,
            out_dir=out,
            progress=lambda line: print(line, file=sys.stderr, flush=True),
        )

    return gate


def _close(client) -> None:
    close = getattr(client, "close", None)
    if close is not None:
        close()


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "author", help="author a domain's programs (offline replay by default)", description=__doc__
    )
    p.add_argument("domain", metavar="DOMAIN")
    src = p.add_mutually_exclusive_group()
    src.add_argument(
        "--model",
        metavar="M",
        help="author with this model: a Claude model (claude-opus-5; key from ANTHROPIC_API_KEY "
        "or ANTHROPIC_AUTH_TOKEN) or openai:NAME for an OpenAI-compatible server (with --base-url)",
    )
    src.add_argument("--replay", type=Path, metavar="DIR", help="replay a transcript folder")
    src.add_argument(
        "--agent",
        metavar="COMMAND",
        help="author with an agent program: for each request it gets a folder with prompt.md "
        "and the images, and writes response.md (docs/agent.md)",
    )
    p.add_argument(
        "--agent-timeout",
        type=float,
        default=1800.0,
        metavar="S",
        help="--agent: seconds one request may take before the command is killed (default 1800)",
    )
    p.add_argument(
        "--base-url",
        default=None,
        metavar="URL",
        help="the API endpoint (default: ANTHROPIC_BASE_URL / OPENAI_BASE_URL, else the "
        "provider's), e.g. http://localhost:8000/v1 for vLLM",
    )
    think = p.add_mutually_exclusive_group()
    think.add_argument(
        "--thinking",
        type=int,
        default=None,
        metavar="BUDGET",
        help="Claude: extended thinking with this many tokens (≥ 1024), added to max_tokens",
    )
    think.add_argument(
        "--effort",
        choices=("low", "medium", "high"),
        default=None,
        help="Claude: adaptive thinking at this effort; openai:NAME: reasoning_effort",
    )
    p.add_argument(
        "--price",
        default=None,
        metavar="IN,OUT",
        help="USD per million input, output tokens (needed for --max-usd with openai:NAME; "
        "overrides the table for Claude)",
    )
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
        "--gate-trials",
        type=int_at_least(0),
        default=None,
        metavar="K",
        help=f"simulated trials of the gate the set must pass before it is frozen (default "
        f"{GATE_TRIALS} for --model and --agent, none for a replay; 0: no gate; docs/checks.md "
        "'The trial gate')",
    )
    p.add_argument(
        "--max-usd",
        type=float,
        default=None,
        metavar="X",
        help="dollar budget of this invocation (all --runs; --resume counts what the run spent), "
        "checked before each call from its worst case",
    )
    p.add_argument("--max-calls", type=int, default=None, metavar="N", help="model-call budget")
    p.add_argument(
        "--runs",
        type=int,
        default=1,
        metavar="N",
        help="author N independent systems (no freezing)",
    )
    add_sandbox_option(p, what="drafts")
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
