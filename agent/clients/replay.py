"""Replay and record transcripts (agent/transcript.py has the format).

Replay is the offline default and what CI uses. Strict mode fails on a request whose hash was
not recorded; the default matches by (function, attempt) and warns when the prompt drifted.
"""

from __future__ import annotations

import sys
from pathlib import Path

from agent.clients.base import Author, ModelClient, ModelRequest, ModelResponse
from agent.clients.pricing import Budget
from agent.errors import ReplayMismatch
from agent.transcript import Entry, Transcript


class ReplayClient:
    def __init__(self, directory: Path, *, strict: bool = False, budget: Budget | None = None):
        self.directory = directory
        self.transcript = Transcript.load(directory)
        self.strict = strict
        self.budget = budget or Budget()
        self.drifted: list[tuple[str, int]] = []

    @property
    def author(self) -> Author:
        return self.transcript.written_by

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
        )


class RecordingClient:
    """Wraps any client and writes every exchange as a transcript in `directory`."""

    def __init__(
        self, inner: ModelClient, directory: Path, *, domain: str, author: Author | None = None
    ):
        self.inner = inner
        self.directory = directory
        self.transcript = Transcript(domain=domain, written_by=author or inner.author)

    @property
    def author(self) -> Author:
        return self.transcript.written_by

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
        self.transcript.save(self.directory)
        return response
