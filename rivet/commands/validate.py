"""`rivet validate KIND FILE.json`: exit 0 when valid, 2 with the offending path otherwise."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from contracts import SCHEMA_NAMES, validate
from contracts.errors import UsageError, user_input


def load_json(path: Path) -> object:
    """Read a JSON file; a missing file or a syntax error is a `UsageError` naming line/column."""
    try:
        text = path.read_text()
    except OSError as e:
        raise UsageError(f"cannot read {path}: {e.strerror}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise UsageError(f"{path}: not JSON: {e.msg} at line {e.lineno} column {e.colno}") from None


def run(args: argparse.Namespace) -> int:
    with user_input():  # the user's file: an invalid one exits 2
        validate(args.kind, load_json(args.file))
    print(f"{args.file}: valid {args.kind}", file=sys.stdout)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate",
        help="check a JSON file against a contract (exit 0 valid, 2 invalid)",
        description=__doc__,
    )
    p.add_argument(
        "kind", choices=SCHEMA_NAMES, metavar="KIND", help=f"one of: {', '.join(SCHEMA_NAMES)}"
    )
    p.add_argument("file", type=Path, metavar="FILE.json")
    p.set_defaults(handler=run)
