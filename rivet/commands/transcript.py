"""`rivet transcript pack DOMAIN PROGRAMS_DIR`: turn hand-written programs (and their failing
drafts) into the domain's reference replay transcript, labelled as written by people."""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from rivet.commands._options import add_sandbox_option


def pack(args: argparse.Namespace) -> int:
    import domains
    from agent.checking import SuiteChecker
    from agent.context import build_context, reference_observations
    from agent.handwritten import (
        check_sequence_used,
        packing_attempts,
        packing_client,
        program_sequence,
    )
    from agent.journal import Journal, new_run_dir
    from agent.loop import AuthoringRun
    from toolbox.docs import toolbox_docs

    domain = domains.load(args.domain)
    folder = Path(args.programs)
    sequence = program_sequence(folder)
    out = Path(args.out) if args.out else domain.reference_transcript
    staging = out.with_name(out.name + ".packing")
    if staging.exists():
        shutil.rmtree(staging)
    client = packing_client(folder, staging, domain.name, tuple(args.names))
    seed = args.seed
    if seed is None and (out / "meta.json").is_file():
        from agent.transcript import Transcript

        seed = Transcript.load(out).cases_seed  # re-packing keeps the cases it was checked on
    ctx = build_context(domain, reference_observations(domain), toolbox_docs())
    checker = SuiteChecker(sandbox=args.sandbox)
    run = AuthoringRun(
        ctx=ctx,
        client=client,
        checker=checker,
        journal=Journal(new_run_dir(Path("runs"), domain.name)),
        max_attempts=packing_attempts(sequence),
        cases_seed=seed,
    )
    try:
        run.run()
    finally:
        checker.close()
    check_sequence_used(folder, run.history)
    if out.exists():
        shutil.rmtree(out)
    staging.rename(out)
    print(
        f"wrote {out} ({len(client.transcript.entries)} responses); replay it with: make author DOMAIN={domain.name}",
        file=sys.stderr,
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("transcript", help="replay transcripts: pack hand-written programs")
    tsub = p.add_subparsers(dest="transcript_command", metavar="COMMAND", required=True)
    q = tsub.add_parser(
        "pack",
        help="package hand-written programs as a people-written transcript",
        description=__doc__,
    )
    q.add_argument("domain", metavar="DOMAIN")
    q.add_argument("programs", metavar="PROGRAMS_DIR")
    q.add_argument("--out", default=None, help="default: domains/DOMAIN/transcripts/reference")
    q.add_argument("--names", nargs="+", default=["the RIVET team"], help="who wrote the programs")
    q.add_argument(
        "--seed",
        type=int,
        default=None,
        metavar="S",
        help="the run's check-case seed (default: the existing transcript's, else a fresh one)",
    )
    add_sandbox_option(q, what="the replayed drafts")
    q.set_defaults(handler=pack)
