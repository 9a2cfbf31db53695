"""Where a result came from: the repository's commit (and whether the checkout differed from
it), the command, the date. Written into authoring journals and evaluation JSON, read by the
generated docs/results.md."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(
            ["git", *args], capture_output=True, text=True, timeout=10, cwd=REPO, check=False
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout if out.returncode == 0 else None


def commit() -> str | None:
    """The checkout's commit, 12 hex digits (None outside a git checkout)."""
    out = _git("rev-parse", "--short=12", "HEAD")
    return out.strip() or None if out is not None else None


def dirty() -> bool | None:
    """Whether a tracked file differs from the commit (None outside a git checkout), results
    aside — files that runs write and no run reads: artifacts/<d>/eval.json (`rivet eval`'s
    dev runs), and docs/results/ and docs/results.md (`make results-runs` writes each run's
    file there as it goes, so every run after the first would otherwise count as dirty)."""
    out = _git("status", "--porcelain", "--untracked-files=no", "--", ".",
               ":(exclude,glob)artifacts/*/eval.json", ":(exclude,glob)docs/results/*.json",
               ":(exclude)docs/results.md")  # fmt: skip
    return None if out is None else bool(out.strip())


def run_record(argv: Sequence[str] | None = None, *, program: Sequence[str] = ("rivet",)) -> dict:
    """What produced a result: the command line (`program` and its arguments), the commit, whether
    the checkout differed from it, the UTC date and the machine's CPU count."""
    args = list(sys.argv[1:] if argv is None else argv)
    return {
        "command": shlex.join([*program, *args]),
        "commit": commit(),
        "dirty": dirty(),
        "date": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "cpus": os.cpu_count(),
    }


__all__ = ["commit", "dirty", "run_record"]
