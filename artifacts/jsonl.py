"""Append-only JSON-lines files: the authoring run's journal and `rivet eval`'s trial log.

Each record is one line, on disk (flushed and fsynced) before `append` returns, so a process
killed at any moment leaves every record it reported whole — and at most one torn last line,
which `read` drops.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any


def append(path: Path, record: Any, *, sort_keys: bool = False) -> None:
    """Write `record` (JSON-serialisable) as the file's next line, durable on return."""
    line = json.dumps(record, sort_keys=sort_keys) + "\n"
    with open(path, "a") as f:
        f.write(line)
        f.flush()
        os.fsync(f.fileno())


def read(path: Path) -> list[Any]:
    """The file's records in order, up to a torn line (a kill mid-write), which ends it;
    [] when there is no file."""
    if not path.is_file():
        return []
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            break  # what came before the torn line holds
    return out
