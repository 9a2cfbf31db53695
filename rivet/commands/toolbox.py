"""`rivet toolbox docs`: print the toolbox documentation that goes into model prompts."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    parser = subparsers.add_parser("toolbox", help="the toolbox that generated programs call")
    sub = parser.add_subparsers(dest="toolbox_command", metavar="SUBCOMMAND")
    sub.required = True
    docs = sub.add_parser("docs", help="print the prompt documentation (Markdown)")
    docs.add_argument(
        "--module",
        action="append",
        dest="modules",
        metavar="NAME",
        help="only this toolbox module (repeatable); default: all",
    )
    docs.set_defaults(handler=_docs)


def _docs(args: argparse.Namespace) -> int:
    from contracts.errors import UsageError
    from toolbox.docs import toolbox_docs
    from toolbox.errors import ToolboxError

    try:
        text = toolbox_docs(args.modules)
    except ToolboxError as e:
        raise UsageError(str(e)) from None
    print(text, end="")
    return 0
