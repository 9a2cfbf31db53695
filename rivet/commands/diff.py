"""`rivet diff DOMAIN [REV]`: Markdown for a pull request comparing the artifacts at REV
(default HEAD) with the working tree."""

from __future__ import annotations

import argparse


def run(args: argparse.Namespace) -> int:
    import domains
    from artifacts.review import diff_markdown

    domains.load(args.domain)  # unknown domain → exit 2 with the known names
    print(diff_markdown(args.domain, args.rev), end="")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "diff", help="Markdown review of a domain's artifact changes", description=__doc__
    )
    p.add_argument("domain", metavar="DOMAIN")
    p.add_argument("rev", nargs="?", default="HEAD", metavar="REV")
    p.set_defaults(handler=run)
