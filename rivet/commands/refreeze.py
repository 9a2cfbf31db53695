"""`rivet refreeze [DOMAIN ...]`: rebuild what is derived from the people-written programs.

A domain's people-written set has one hand-edited source, `domains/<d>/programs/` (with its
failing drafts in `drafts/`). From it derive the reference replay transcript
(`rivet transcript pack`, on the transcript's own case seed) and the frozen set in
`artifacts/<d>/` (`rivet author D --strict`, a replay of that transcript; the set's eval.json
is moved aside as stale when the set changes, to be measured again with `rivet eval`).

`--check` rebuilds nothing: it reads the committed files and exits 1, naming each, where a
transcript or a frozen set is not what the programs produce — a program edited without a
refreeze, a frozen file edited by hand, a set stamped against other contracts, toolbox or
prompt templates. CI runs it (`make refreeze-check`, and a test).
"""

from __future__ import annotations

import argparse
import sys

from rivet.commands._options import add_sandbox_option


def _domains(names: list[str]) -> list:
    import domains

    chosen = names or list(domains.names())
    return [domains.load(name) for name in chosen]


def run(args: argparse.Namespace) -> int:
    from agent.handwritten import derivation_problems

    chosen = [d for d in _domains(args.domains) if (d.root / "programs").is_dir()]
    if args.check:
        problems = [p for d in chosen for p in derivation_problems(d)]
        for p in problems:
            print(p)
        if problems:
            print("run: make refreeze (or rivet refreeze DOMAIN)", file=sys.stderr)
            return 1
        print(f"derived files match the programs: {', '.join(d.name for d in chosen)}")
        return 0
    from rivet.cli import main

    for d in chosen:
        print(f"[{d.name}] packing domains/{d.name}/programs", file=sys.stderr, flush=True)
        code = main(
            ["transcript", "pack", d.name, str(d.root / "programs"), "--sandbox", args.sandbox]
        )
        if code != 0:
            return code
        print(f"[{d.name}] freezing by replay", file=sys.stderr, flush=True)
        code = main(["author", d.name, "--strict", "--sandbox", args.sandbox])
        if code != 0:
            return code
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "refreeze",
        help="rebuild transcripts and frozen sets from the people-written programs (--check: "
        "only say whether they match)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("domains", nargs="*", metavar="DOMAIN", help="default: every domain")
    p.add_argument("--check", action="store_true", help="rebuild nothing; exit 1 on a mismatch")
    add_sandbox_option(p, what="the programs while they are checked")
    p.set_defaults(handler=run)
