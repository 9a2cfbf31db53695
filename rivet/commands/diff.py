"""`rivet diff DOMAIN [REV]`: Markdown for a pull request comparing the artifacts at REV
(default HEAD) with the working tree.

Metrics are shown only for the set they measured: a side whose `eval.json` names another set
hash (or none, or is missing) reads "not evaluated", with the command that measures it.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def run(args: argparse.Namespace) -> int:
    import domains
    from artifacts.hashing import REPO
    from artifacts.review import diff_markdown

    domains.load(args.domain)  # unknown domain → exit 2 with the known names
    repo = Path(args.repo) if args.repo else REPO
    print(diff_markdown(args.domain, args.rev, repo), end="")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "diff", help="Markdown review of a domain's artifact changes", description=__doc__
    )
    p.add_argument("domain", metavar="DOMAIN")
    p.add_argument("rev", nargs="?", default="HEAD", metavar="REV")
    p.add_argument(
        "--repo",
        default=None,
        metavar="DIR",
        help="the git checkout whose artifacts/ to review (default: this one)",
    )
    p.set_defaults(handler=run)
