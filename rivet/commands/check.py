"""`rivet check DOMAIN FUNCTION FILE.py`: one draft's full checks in the sandbox; prints the report.
`rivet check DOMAIN --system DIR`: the trial gate alone on a folder of four programs
(`artifacts.gate`): simulated trials on fresh tasks, each through its own drawn camera.

Exit 0 when every check passes, 1 when one fails, 2 for bad input (an unknown domain or
function, an unreadable file). The set's other programs come from `--deps DIR` (`DIR/<name>.py`,
e.g. the frozen `artifacts/cubes/`): the draft's session holds every one found, as the runtime's
session holds all four. Where the judge needs one that is not there, the domain's ground truth
stands in for it (its reference relations when checking `plan`, the toolbox renderer
when re-rendering what `perceive` found).

The cases are drawn afresh on every run (`checks.inputs`); the report names the seed they were
drawn from, and `--seed S` draws the same ones again. `--only NAME` runs one check alone (with
the interface and schema checks every other rests on), e.g. to see a fix of one failure.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from contracts.errors import UsageError
from contracts.functions import CODE_DEPS, FUNCTIONS
from rivet.commands._options import add_sandbox_option, int_at_least


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "check",
        help="run one draft's full checks in the sandbox and print the report (exit 0 pass, 1 fail)",
        description=__doc__,
    )
    p.add_argument("domain", metavar="DOMAIN")
    p.add_argument(
        "function", nargs="?", choices=FUNCTIONS, metavar="FUNCTION", help=", ".join(FUNCTIONS)
    )
    p.add_argument("file", nargs="?", type=Path, metavar="FILE.py")
    p.add_argument(
        "--system",
        type=Path,
        metavar="DIR",
        help="run the trial gate alone on DIR/{render,perceive,relate,plan}.py instead",
    )
    p.add_argument(
        "--trials", type=int_at_least(1), metavar="K", help="trials of the gate (default: 8)"
    )
    p.add_argument("--thorough", action="store_true", help="more instances and examples (slower)")
    p.add_argument(
        "--deps",
        type=Path,
        metavar="DIR",
        help="folder holding the set's other frozen programs, as <name>.py (all are loaded "
        "beside the draft, as at run time)",
    )
    add_sandbox_option(p, what="the draft and its frozen dependencies")
    p.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="where overlay images go (default runs/checks/DOMAIN/FUNCTION-<draft hash>)",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON instead")
    p.add_argument(
        "--only",
        action="append",
        metavar="NAME",
        help="run only the check NAME (repeatable; e.g. property.translation_invariant), with "
        "the interface and schema checks it rests on; the others are reported skipped",
    )
    p.add_argument(
        "--seed",
        type=_seed,
        metavar="S",
        help="draw the cases from seed S (default: a fresh seed, printed with the report)",
    )
    p.set_defaults(handler=run)


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 <= value < 2**63:
        raise argparse.ArgumentTypeError(f"must be in [0, 2**63), got {value}")
    return value


def _read(path: Path, what: str) -> str:
    try:
        return path.read_text()
    except OSError as e:
        raise UsageError(f"cannot read {what} {path}: {e.strerror}") from None


def dependencies(function: str, folder: Path | None) -> dict[str, str]:
    """The set's other programs found in `folder` ({} without one)."""
    if folder is None:
        return {}
    if not folder.is_dir():
        raise UsageError(f"--deps {folder}: not a folder")
    return {
        name: _read(folder / f"{name}.py", "dependency")
        for name in FUNCTIONS
        if name != function and (folder / f"{name}.py").is_file()
    }


def run(args: argparse.Namespace) -> int:
    import hashlib

    import domains
    import sandbox
    from checks import report_markdown, run_checks

    domains.load(args.domain)  # an unknown domain is a usage error, before any work
    if args.system is not None:
        if args.function is not None or args.file is not None:
            raise UsageError("--system DIR runs the trial gate alone: give no FUNCTION or FILE")
        if args.only:
            raise UsageError("--only picks checks of one draft: give FUNCTION and FILE.py")
        return _gate(args)
    if args.function is None or args.file is None:
        raise UsageError("give FUNCTION and FILE.py (or --system DIR for the trial gate)")
    if args.trials is not None:
        raise UsageError("--trials is the trial gate's: use it with --system DIR")
    if args.only:  # before a sandbox starts
        from checks.run import known_checks

        known_checks(domains.load(args.domain), args.function, args.only)
    source = _read(args.file, "draft")
    deps = dependencies(args.function, args.deps)
    standing_in = [d for d in CODE_DEPS[args.function] if d not in deps]
    out = args.out or Path("runs") / "checks" / args.domain / (
        f"{args.function}-{hashlib.sha256(source.encode()).hexdigest()[:12]}"
    )
    with sandbox.open_executor(args.sandbox) as executor:
        report = run_checks(
            args.domain,
            args.function,
            source,
            deps=deps,
            thorough=args.thorough,
            executor=executor,
            out_dir=out,
            cases_seed=args.seed,
            only=args.only,
        )
    if args.json:
        json.dump(report, sys.stdout, indent=1)
        print()
    else:
        for c in report["checks"]:
            mark = {"passed": "ok  ", "failed": "FAIL", "error": "ERR ", "skipped": "skip"}
            print(f"{mark[c['status']]} {c['name']}")
        print()
        print(report_markdown(report))
        if args.only:
            from checks.suites._common import NOT_ASKED

            left = sum(c.get("optional") == NOT_ASKED for c in report["checks"])
            print(f"\n(--only: {left} other checks not run)")
        if standing_in:
            print(f"\n(ground truth stood in for: {', '.join(standing_in)})")
        print(f"images: {out}" if any(c.get("images") for c in report["checks"]) else "")
        print(
            f"cases drawn from seed {report['cases_seed']} (--seed {report['cases_seed']} draws them again)"
        )
    return 0 if report["passed"] else 1


def _gate(args: argparse.Namespace) -> int:
    """The trial gate on a folder of four programs: exit 0 passed, 1 failed."""
    import sys

    from artifacts.gate import GATE_TRIALS, run_gate
    from artifacts.runtime import read_programs
    from checks.inputs import fresh_seed

    if not args.system.is_dir():
        raise UsageError(f"--system {args.system}: not a folder")
    try:
        sources = read_programs(args.system)
    except Exception as e:  # an ArtifactError naming the missing file
        raise UsageError(str(e)) from None
    seed = fresh_seed() if args.seed is None else args.seed
    result = run_gate(
        args.domain,
        sources,
        seed=seed,
        trials=args.trials or GATE_TRIALS,
        sandbox=args.sandbox,
        out_dir=args.out,
        progress=lambda line: print(line, file=sys.stderr, flush=True),
    )
    if args.json:
        json.dump(result.to_dict(), sys.stdout, indent=1)
        print()
    else:
        print(result.markdown())
        print(
            f"\ntrials drawn from seed {seed} (--seed {seed} draws them again); {result.duration_s:.0f} s"
        )
    return 0 if result.passed else 1
