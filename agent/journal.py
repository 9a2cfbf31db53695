"""The run journal: every state change of an authoring run, on disk before it counts.

```
runs/<domain>/<run>/journal.jsonl            one JSON event per line, fsynced
runs/<domain>/<run>/responses/<fn>-<k>.md    each model response, written before its event
runs/<domain>/<run>/drafts/<fn>-<k>.py       the draft extracted from it
runs/<domain>/<run>/reports/<fn>-<k>.json    its check report (+ .md, + images folder)
runs/<domain>/<run>/frozen/<fn>.py           the passing draft
runs/<domain>/<run>/requests/<fn>-<k>.md     the prompt of each call, as the model read it
runs/<domain>/<run>/requests/images/<sha>.png  its images, stored once by content hash
```
A run killed at any point resumes from these files: a saved response is never requested
again, and a frozen function is never authored again.

The journal is also the run's ledger: each `response` event carries its usage in dollars, and a
call that failed after the API billed something (a refusal, a stream cut off and never
finished) leaves a `call_failed` event with the usage known. `RunState.spent_usd` sums both,
and `rivet author --resume` starts its budget from it. A `response` event also keeps the
answer's `stop_reason` and the `max_tokens` it was asked with, so a resumed run knows which
saved answers were cut off.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agent.clients.base import ModelRequest, ModelResponse, Usage
from agent.transcript import atomic_write
from artifacts import jsonl


@dataclass
class RunState:
    frozen: dict[str, str] = field(default_factory=dict)  # function → source
    attempts: dict[str, int] = field(default_factory=dict)  # function → attempts with a response
    usage: Usage = field(default_factory=Usage)  # of the responses
    calls: int = 0  # billed calls: responses, and failed calls with a known usage
    config: dict[str, Any] = field(default_factory=dict)
    failed_usage: Usage = field(default_factory=Usage)  # of the failed calls

    @property
    def spent_usd(self) -> float:
        return self.usage.usd + self.failed_usage.usd


class Journal:
    def __init__(self, run_dir: Path) -> None:
        self.dir = run_dir
        self.path = run_dir / "journal.jsonl"
        run_dir.mkdir(parents=True, exist_ok=True)

    # --- writing ---------------------------------------------------------------------------

    def event(self, kind: str, **fields: Any) -> None:
        jsonl.append(
            self.path, {"t": round(time.time(), 3), "event": kind, **fields}, sort_keys=True
        )

    def save_response(
        self,
        function: str,
        attempt: int,
        response: ModelResponse,
        request_hash: str,
        *,
        max_tokens: int | None = None,
    ) -> None:
        atomic_write(self._file("responses", function, attempt, "md"), response.text)
        extra: dict[str, Any] = {}
        if response.stop_reason is not None:
            extra["stop_reason"] = response.stop_reason
        if max_tokens is not None:
            extra["max_tokens"] = max_tokens
        self.event(
            "response",
            function=function,
            attempt=attempt,
            request_hash=request_hash,
            model=response.model,
            usage=response.usage.to_dict(),
            **extra,
        )

    def call_failed(
        self,
        function: str,
        attempt: int,
        request_hash: str,
        error: BaseException,
        usage: Usage | None,
    ) -> None:
        """A call that raised; its usage (when the API billed something) joins the ledger."""
        fields: dict[str, Any] = {
            "function": function,
            "attempt": attempt,
            "request_hash": request_hash,
            "error": f"{type(error).__name__}: {error}"[:2000],
        }
        if usage is not None:
            fields["usage"] = usage.to_dict()
        self.event("call_failed", **fields)

    def save_request(self, request: ModelRequest) -> Path:
        """Keep the prompt of a call — system and content text, images by content hash — as
        Markdown, before the call is made (a reviewer reads what the model read)."""
        from agent.clients.base import ImageBlock, TextBlock

        images = self.dir / "requests" / "images"
        parts = [f"<!-- request {request.hash} -->", "# system", ""]
        parts += [b.text for b in request.system]
        parts += ["", "# user", ""]
        for block in request.content:
            if isinstance(block, TextBlock):
                parts.append(block.text)
            elif isinstance(block, ImageBlock):
                path = images / f"{block.sha256}.png"
                if not path.is_file():
                    images.mkdir(parents=True, exist_ok=True)
                    path.write_bytes(block.png)
                parts.append(f"![{block.caption}](images/{block.sha256}.png)")
        out = self._file("requests", request.function, request.attempt, "md")
        atomic_write(out, "\n".join(parts) + "\n")
        return out

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

    def saved_stop_reason(self, function: str, attempt: int) -> str | None:
        """The stop_reason journaled with the saved response of (function, attempt)."""
        reason = None
        for e in self.events():
            if e["event"] == "response" and (e["function"], e["attempt"]) == (function, attempt):
                reason = e.get("stop_reason")
        return reason

    def saved_markdown(self, function: str, attempt: int) -> str | None:
        path = self._file("reports", function, attempt, "md")
        return path.read_text() if path.is_file() else None

    def events(self) -> list[dict[str, Any]]:
        return jsonl.read(self.path)

    def state(self) -> RunState:
        st = RunState()
        for e in self.events():
            if e["event"] == "started":
                st.config = e.get("config", {})
            elif e["event"] == "response":
                st.attempts[e["function"]] = max(st.attempts.get(e["function"], 0), e["attempt"])
                st.usage = st.usage + Usage.from_dict(e.get("usage", {}))
                st.calls += 1
            elif e["event"] == "call_failed" and e.get("usage"):
                st.failed_usage = st.failed_usage + Usage.from_dict(e["usage"])
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
