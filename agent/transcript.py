"""The transcript folder: who wrote it, and one readable, diffable file per response.

```
<dir>/meta.json                    {"format", "domain", "written_by", "cases_seed", "responses": [...]}
<dir>/01-render-attempt1.md        the response text exactly as the model (or a person) wrote it
```
Each `responses` entry names its file, function, attempt, the request hash it answered (null
when it was never asked, e.g. a hand-written file not yet bound to prompts) and usage.
`cases_seed` is the run's seed of the check cases (`checks.inputs.case_seed` draws each
attempt's from it): a replay draws the cases the recorded run was checked on, so its feedback,
and with it every later request, is the recorded one.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from agent.clients.base import Author, Usage
from agent.errors import TranscriptError

FORMAT = "rivet-transcript/1"


@dataclass(kw_only=True)
class Entry:
    file: str
    function: str
    attempt: int
    request_hash: str | None = None
    model: str | None = None
    usage: Usage = field(default_factory=Usage)

    def to_dict(self) -> dict:
        return {
            "file": self.file,
            "function": self.function,
            "attempt": self.attempt,
            "request_hash": self.request_hash,
            "model": self.model,
            "usage": self.usage.to_dict(),
        }


@dataclass(kw_only=True)
class Transcript:
    domain: str
    written_by: Author
    entries: list[Entry] = field(default_factory=list)
    texts: dict[str, str] = field(default_factory=dict)  # file name → response text
    cases_seed: int | None = None  # the run's check-case seed (None: not recorded)

    @classmethod
    def load(cls, directory: Path) -> Transcript:
        meta_path = directory / "meta.json"
        if not meta_path.is_file():
            raise TranscriptError(f"{directory} is not a transcript: no meta.json")
        try:
            meta = json.loads(meta_path.read_text())
            if meta.get("format") != FORMAT:
                raise TranscriptError(
                    f"{meta_path}: format must be '{FORMAT}', got {meta.get('format')!r}"
                )
            author = Author.from_dict(meta["written_by"])
            entries = [
                Entry(
                    file=e["file"],
                    function=e["function"],
                    attempt=int(e["attempt"]),
                    request_hash=e.get("request_hash"),
                    model=e.get("model"),
                    usage=Usage.from_dict(e.get("usage", {})),
                )
                for e in meta["responses"]
            ]
        except (KeyError, TypeError, ValueError) as err:
            raise TranscriptError(f"{meta_path}: malformed ({type(err).__name__}: {err})") from None
        texts = {}
        for e in entries:
            p = directory / e.file
            if not p.is_file():
                raise TranscriptError(f"{meta_path}: response file {e.file} is missing")
            texts[e.file] = p.read_text()
        seed = meta.get("cases_seed")
        if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool) or seed < 0):
            raise TranscriptError(f"{meta_path}: cases_seed must be an integer ≥ 0, got {seed!r}")
        return cls(
            domain=meta["domain"], written_by=author, entries=entries, texts=texts, cases_seed=seed
        )

    def save(self, directory: Path) -> None:
        directory.mkdir(parents=True, exist_ok=True)
        for name, text in self.texts.items():
            atomic_write(directory / name, text)
        meta = {
            "format": FORMAT,
            "domain": self.domain,
            "written_by": self.written_by.to_dict(),
            **({} if self.cases_seed is None else {"cases_seed": self.cases_seed}),
            "responses": [e.to_dict() for e in self.entries],
        }
        atomic_write(directory / "meta.json", json.dumps(meta, indent=2) + "\n")
        for stale in directory.glob("*.md"):
            if stale.name not in self.texts:
                stale.unlink()

    def find(self, function: str, attempt: int) -> Entry | None:
        for e in self.entries:
            if e.function == function and e.attempt == attempt:
                return e
        return None


def atomic_write(path: Path, text: str | bytes) -> None:
    """Write via a temporary file + rename, so a crash never leaves a half-written file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    data = text.encode() if isinstance(text, str) else text
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
