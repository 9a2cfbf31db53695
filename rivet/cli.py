"""`rivet`: the user's command line.

Each command group lives in `rivet/commands/<name>.py` and exposes
`register(subparsers) -> None`; a registered handler returns an exit code.
Exit codes: 0 success, 1 the work failed, 2 bad usage or bad input.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import threading
from collections.abc import Sequence

from contracts.errors import RivetError, UsageError

# Command modules, in the order `rivet --help` lists them.
COMMAND_MODULES = (
    "author",
    "solve",
    "eval",
    "scene",
    "sandbox",
    "check",
    "diff",
    "validate",
    "toolbox",
    "transcript",
    "refreeze",
)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # type: ignore[override]
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="rivet", description=__doc__.splitlines()[0] if __doc__ else None)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"rivet.commands.{name}")
        except ModuleNotFoundError as e:
            if e.name == f"rivet.commands.{name}":
                continue  # command not built yet
            raise
        module.register(sub)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM (a CI job cancelled, `kill`): unwound like Ctrl-C, so that every `finally`
    closes its sandbox containers and worker pools."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated()


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # what was asked: for provenance
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if main_thread else None
    try:
        return int(args.handler(args) or 0)
    except UsageError as e:
        print(f"rivet {args.command}: {e}", file=sys.stderr)
        return 2
    except RivetError as e:
        print(f"rivet {args.command}: {e}", file=sys.stderr)
        return 1
    except Terminated:
        print("terminated", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
