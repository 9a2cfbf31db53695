"""The run journal: every state change of an authoring run, on disk before it counts.

```
runs/<domain>/<run>/journal.jsonl            one JSON event per line, fsynced
runs/<domain>/<run>/responses/<fn>-<k>.md    each model response, written before its event
runs/<domain>/<run>/drafts/<fn>-<k>.py       the draft extracted from it
runs/<domain>/<run>/reports/<fn>-<k>.json    its check report (+ .md, + images folder)
runs/<domain>/<run>/frozen/<fn>.py           the passing draft
```
A run killed at any point resumes from these files: a saved response is never requested
again, and a frozen function is never authored again.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agent.clients.base import ModelResponse, Usage
from agent.transcript import atomic_write


@dataclass
class RunState:
    frozen: dict[str, str] = field(default_factory=dict)  # function → source
    attempts: dict[str, int] = field(default_factory=dict)  # function → attempts with a response
    usage: Usage = field(default_factory=Usage)
    calls: int = 0
    config: dict[str, Any] = field(default_factory=dict)


class Journal:
    def __init__(self, run_dir: Path) -> None:
        self.dir = run_dir
        self.path = run_dir / "journal.jsonl"
        run_dir.mkdir(parents=True, exist_ok=True)

    # --- writing ---------------------------------------------------------------------------

    def event(self, kind: str, **fields: Any) -> None:
        line = json.dumps({"t": round(time.time(), 3), "event": kind, **fields}, sort_keys=True)
        with open(self.path, "a") as f:
            f.write(line + "\n")
            f.flush()
            os.fsync(f.fileno())

    def save_response(
        self, function: str, attempt: int, response: ModelResponse, request_hash: str
    ) -> None:
        atomic_write(self._file("responses", function, attempt, "md"), response.text)
        self.event(
            "response",
            function=function,
            attempt=attempt,
            request_hash=request_hash,
            model=response.model,
            usage=response.usage.to_dict(),
        )

    def save_draft(self, function: str, attempt: int, source: str) -> Path:
        path = self._file("drafts", function, attempt, "py")
        atomic_write(path, source)
        return path

    def save_report(self, function: str, attempt: int, report: dict, markdown: str) -> None:
        atomic_write(self._file("reports", function, attempt, "md"), markdown)
        atomic_write(self._file("reports", function, attempt, "json"), json.dumps(report, indent=2))
        self.event(
            "checked",
            function=function,
            attempt=attempt,
            passed=bool(report["passed"]),
            first_failure=report.get("first_failure"),
        )

    def freeze(self, function: str, attempt: int, source: str) -> None:
        atomic_write(self.dir / "frozen" / f"{function}.py", source)
        self.event("frozen", function=function, attempt=attempt)

    # --- reading ---------------------------------------------------------------------------

    def images_dir(self, function: str, attempt: int) -> Path:
        return self.dir / "reports" / f"{function}-{attempt}"

    def saved_response(self, function: str, attempt: int) -> str | None:
        path = self._file("responses", function, attempt, "md")
        return path.read_text() if path.is_file() else None

    def saved_report(self, function: str, attempt: int) -> dict | None:
        path = self._file("reports", function, attempt, "json")
        return json.loads(path.read_text()) if path.is_file() else None

    def saved_markdown(self, function: str, attempt: int) -> str | None:
        path = self._file("reports", function, attempt, "md")
        return path.read_text() if path.is_file() else None

    def events(self) -> list[dict[str, Any]]:
        if not self.path.is_file():
            return []
        out = []
        for line in self.path.read_text().splitlines():
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError:
                break  # a torn last line from a kill mid-write: everything before it holds
        return out

    def state(self) -> RunState:
        st = RunState()
        for e in self.events():
            if e["event"] == "started":
                st.config = e.get("config", {})
            elif e["event"] == "response":
                st.attempts[e["function"]] = max(st.attempts.get(e["function"], 0), e["attempt"])
                st.usage = st.usage + Usage.from_dict(e.get("usage", {}))
                st.calls += 1
            elif e["event"] == "frozen":
                st.frozen[e["function"]] = (self.dir / "frozen" / f"{e['function']}.py").read_text()
        return st

    def _file(self, sub: str, function: str, attempt: int, ext: str) -> Path:
        return self.dir / sub / f"{function}-{attempt}.{ext}"


def new_run_dir(root: Path, domain: str) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    base = root / domain / stamp
    path, n = base, 1
    while path.exists():
        n += 1
        path = base.with_name(f"{stamp}-{n}")
    return path


def latest_run_dir(root: Path, domain: str) -> Path | None:
    runs = sorted(p for p in (root / domain).glob("*") if (p / "journal.jsonl").is_file())
    return runs[-1] if runs else None
