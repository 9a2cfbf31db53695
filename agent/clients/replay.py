"""Replay and record transcripts (agent/transcript.py has the format).

Replay is the offline default and what CI uses. Strict mode fails on a request whose hash was
not recorded; the default matches by (function, attempt) and warns when the prompt drifted.

A recorded response's `stop_reason` is kept in its `meta.json` entry when it is not the plain
end of an answer (a truncated answer, `max_tokens`, must replay as truncated: the loop raises
the next attempt's `max_tokens` from it, and that is part of the next request's hash).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from agent.clients.base import Author, ModelClient, ModelRequest, ModelResponse
from agent.clients.pricing import Budget
from agent.errors import ReplayMismatch
from agent.transcript import Entry, Transcript, atomic_write

_PLAIN_STOPS = (None, "end_turn", "stop_sequence")


def _stop_reasons(directory: Path) -> dict[str, str]:
    """file → stop_reason, from the entries of `meta.json` that carry one."""
    try:
        meta = json.loads((directory / "meta.json").read_text())
        return {
            e["file"]: e["stop_reason"]
            for e in meta.get("responses", [])
            if isinstance(e, dict) and e.get("stop_reason")
        }
    except (OSError, ValueError, KeyError, TypeError):
        return {}


class ReplayClient:
    def __init__(self, directory: Path, *, strict: bool = False, budget: Budget | None = None):
        self.directory = directory
        self.transcript = Transcript.load(directory)
        self.strict = strict
        self.budget = budget or Budget()
        self.drifted: list[tuple[str, int]] = []
        self._stops = _stop_reasons(directory)

    @property
    def author(self) -> Author:
        return self.transcript.written_by

    @property
    def cases_seed(self) -> int | None:
        """The recorded run's check-case seed: replaying draws the same cases."""
        return self.transcript.cases_seed

    def complete(self, request: ModelRequest) -> ModelResponse:
        self.budget.reserve(0.0)
        if self.strict:
            entry = next(
                (e for e in self.transcript.entries if e.request_hash == request.hash), None
            )
            if entry is None:
                raise ReplayMismatch(
                    f"strict replay: no recorded response for {request.function} attempt "
                    f"{request.attempt} (request {request.hash[:12]}) in {self.directory}; the "
                    "prompt changed since recording — re-record, or replay without --strict"
                )
        else:
            found = self.transcript.find(request.function, request.attempt)
            if found is None:
                raise ReplayMismatch(
                    f"{self.directory} holds no response for {request.function} attempt "
                    f"{request.attempt}"
                )
            entry = found
            if entry.request_hash is not None and entry.request_hash != request.hash:
                self.drifted.append((request.function, request.attempt))
                print(
                    f"warning: prompt for {request.function} attempt {request.attempt} drifted "
                    f"since the transcript was recorded ({entry.request_hash[:12]} → "
                    f"{request.hash[:12]})",
                    file=sys.stderr,
                )
        self.budget.spend(0.0)
        return ModelResponse(
            text=self.transcript.texts[entry.file],
            model=entry.model or (self.author.model or "people"),
            usage=entry.usage,
            stop_reason=self._stops.get(entry.file),
        )


class RecordingClient:
    """Wraps any client and writes every exchange as a transcript in `directory`."""

    def __init__(
        self, inner: ModelClient, directory: Path, *, domain: str, author: Author | None = None
    ):
        self.inner = inner
        self.directory = directory
        self.transcript = Transcript(domain=domain, written_by=author or inner.author)
        self.stops: dict[str, str] = {}  # file → a stop_reason worth keeping

    @property
    def author(self) -> Author:
        return self.transcript.written_by

    @property
    def cases_seed(self) -> int | None:
        """The inner client's recorded seed (a re-recorded replay keeps it), else none yet."""
        return getattr(self.inner, "cases_seed", None)

    def record_cases_seed(self, seed: int) -> None:
        """Keep the run's check-case seed in the transcript (written with the next answer)."""
        self.transcript.cases_seed = int(seed)

    def close(self) -> None:
        close = getattr(self.inner, "close", None)
        if close is not None:
            close()

    def complete(self, request: ModelRequest) -> ModelResponse:
        response = self.inner.complete(request)
        name = (
            f"{len(self.transcript.entries) + 1:02d}-{request.function}-attempt{request.attempt}.md"
        )
        # Re-recording the same (function, attempt) replaces the older entry.
        self.transcript.entries = [
            e
            for e in self.transcript.entries
            if (e.function, e.attempt) != (request.function, request.attempt)
        ]
        self.transcript.entries.append(
            Entry(
                file=name,
                function=request.function,
                attempt=request.attempt,
                request_hash=request.hash,
                model=response.model,
                usage=response.usage,
            )
        )
        self.transcript.texts[name] = response.text
        self.transcript.texts = {
            e.file: self.transcript.texts[e.file] for e in self.transcript.entries
        }
        if response.stop_reason not in _PLAIN_STOPS:
            self.stops[name] = str(response.stop_reason)
        self.transcript.save(self.directory)
        self._save_stops()
        return response

    def _save_stops(self) -> None:
        live = {e.file for e in self.transcript.entries}
        stops = {f: r for f, r in self.stops.items() if f in live}
        if not stops:
            return
        path = self.directory / "meta.json"
        meta = json.loads(path.read_text())
        for e in meta["responses"]:
            if e["file"] in stops:
                e["stop_reason"] = stops[e["file"]]
        atomic_write(path, json.dumps(meta, indent=2) + "\n")
