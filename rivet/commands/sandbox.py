"""`rivet sandbox run` (one draft, verdict JSON on stdout) and `rivet sandbox doctor`."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from contracts.errors import UsageError
from rivet.commands._options import add_sandbox_option


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("sandbox", help="run a draft in the sandbox; check isolation")
    sub = parser.add_subparsers(dest="sandbox_command", metavar="SUBCOMMAND")
    sub.required = True

    run = sub.add_parser(
        "run", help="run FILE.py's function in the sandbox, print the verdict JSON"
    )
    run.add_argument("file", type=Path, metavar="FILE.py")
    run.add_argument("--function", required=True, help="the function to call")
    run.add_argument(
        "--input", default="{}", help="keyword arguments as a JSON object, or @FILE.json"
    )
    add_sandbox_option(run, what="the file")
    run.add_argument("--timeout", type=float, default=30.0, help="time budget [s] (default 30)")
    run.add_argument("--memory", type=int, default=1024, help="memory limit [MiB] (default 1024)")
    run.add_argument(
        "--module",
        action="append",
        default=[],
        metavar="NAME=FILE.py",
        help="an extra module the draft may import (repeatable)",
    )
    run.set_defaults(handler=run_command)

    doctor = sub.add_parser("doctor", help="test every isolation item live and print pass/fail")
    doctor.set_defaults(handler=doctor_command)


def run_command(args: argparse.Namespace) -> int:
    from sandbox import Job, open_executor

    job = Job(
        source=_read(args.file),
        function=args.function,
        inputs=_inputs(args.input),
        modules=dict(_module(spec) for spec in args.module),
        module_name=_module_name(args.file),
        timeout_s=args.timeout,
        memory_mb=args.memory,
    )
    with open_executor(args.sandbox) as executor:
        report = executor.run(job)
    # strict JSON (no bare NaN), escape sequences made visible, big arrays summarised
    print(json.dumps(report.to_dict(max_elements=10_000), indent=2, allow_nan=False))
    return 0 if report.ok else 1


def doctor_command(args: argparse.Namespace) -> int:
    from sandbox.doctor import format_items, run_doctor

    items = run_doctor()
    print(format_items(items))
    return 0 if all(i.ok for i in items) else 1


def _read(path: Path) -> str:
    try:
        return path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise UsageError(f"cannot read {path}: {e}") from None


def _module_name(path: Path) -> str:
    from sandbox.base import RESERVED_MODULES

    name = path.stem
    ok = name.isidentifier() and name not in RESERVED_MODULES
    return name if ok else "draft"


def _module(spec: str) -> tuple[str, str]:
    name, sep, file = spec.partition("=")
    if not sep or not name or not file:
        raise UsageError(f"--module {spec!r}: expected NAME=FILE.py")
    return name, _read(Path(file))


def _inputs(text: str) -> dict[str, Any]:
    where = "--input"
    if text.startswith("@"):
        where = text[1:]
        text = _read(Path(where))
    try:
        value = json.loads(text)
    except ValueError as e:
        raise UsageError(f"{where} is not JSON: {e}") from None
    if not isinstance(value, dict):
        raise UsageError(
            f"{where} must be a JSON object of keyword arguments, not {type(value).__name__}"
        )
    return value
