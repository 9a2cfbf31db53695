"""One interface for every model client: `complete(request) -> response`.

A request is provider-neutral: system blocks (the stable, cacheable prefix first), then user
content blocks of text and PNG images. Its `hash` identifies it for replay: the same prompt
bytes give the same hash, whatever the client.
"""

from __future__ import annotations

import base64
import hashlib
import json
import re
from dataclasses import dataclass, field
from typing import Literal, Protocol


@dataclass(frozen=True, kw_only=True)
class TextBlock:
    kind: Literal["text"] = "text"
    text: str
    cache: bool = False  # end of the stable prefix: mark it for prompt caching


@dataclass(frozen=True, kw_only=True)
class ImageBlock:
    kind: Literal["image"] = "image"
    png: bytes
    caption: str = ""

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.png).hexdigest()

    def b64(self) -> str:
        return base64.b64encode(self.png).decode("ascii")


Block = TextBlock | ImageBlock


# Figures a check measured (CPU seconds per call) differ between two runs of the same draft;
# the request hash leaves them out, so a replayed transcript still matches its prompts. The
# model reads them as they were measured.
_MEASURED = re.compile(
    r"\d+(?:\.\d+)?(?= s of CPU)"
    r"|(?<=slowest )\d+(?:\.\d+)? s on [^),;]*"  # the slowest call, and which case it was
    r"|(?<=median )\d+(?:\.\d+)?(?= s)"
    r"|(?<=max_s = )\d+(?:\.\d+)?"
    r"|(?<=median_s = )\d+(?:\.\d+)?"
)


def steady_text(text: str) -> str:
    """`text` with the measured timings masked (what `ModelRequest.hash` hashes)."""
    return _MEASURED.sub("#", text)


@dataclass(frozen=True, kw_only=True)
class ModelRequest:
    """One call: what the model reads, and which function/attempt it is for."""

    function: str
    attempt: int
    system: tuple[TextBlock, ...]
    content: tuple[Block, ...]
    max_tokens: int = 16000

    @property
    def hash(self) -> str:
        """sha256 of the prompt (text and image bytes, measured timings masked: `steady_text`);
        independent of the client."""

        def enc(b: Block) -> dict:
            if isinstance(b, TextBlock):
                return {"text": steady_text(b.text)}
            return {"image": b.sha256}

        payload = {
            "system": [enc(b) for b in self.system],
            "content": [enc(b) for b in self.content],
            "max_tokens": self.max_tokens,
        }
        return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()

    def text(self) -> str:
        """The prompt as plain text (images as placeholders), for journals and reports."""
        parts = [b.text for b in self.system]
        for b in self.content:
            parts.append(b.text if isinstance(b, TextBlock) else f"[image: {b.caption}]")
        return "\n\n".join(parts)


@dataclass(frozen=True, kw_only=True)
class Usage:
    input_tokens: int = 0
    output_tokens: int = 0
    cache_write_tokens: int = 0
    cache_read_tokens: int = 0
    usd: float = 0.0

    def __add__(self, other: Usage) -> Usage:
        return Usage(
            input_tokens=self.input_tokens + other.input_tokens,
            output_tokens=self.output_tokens + other.output_tokens,
            cache_write_tokens=self.cache_write_tokens + other.cache_write_tokens,
            cache_read_tokens=self.cache_read_tokens + other.cache_read_tokens,
            usd=self.usd + other.usd,
        )

    def to_dict(self) -> dict:
        return {
            "input_tokens": self.input_tokens,
            "output_tokens": self.output_tokens,
            "cache_write_tokens": self.cache_write_tokens,
            "cache_read_tokens": self.cache_read_tokens,
            "usd": round(self.usd, 6),
        }

    @classmethod
    def from_dict(cls, d: dict) -> Usage:
        return cls(**{k: d.get(k, 0) for k in cls.__dataclass_fields__})


@dataclass(frozen=True, kw_only=True)
class ModelResponse:
    """One answer. `stop_reason` uses Anthropic's words whatever the client (an OpenAI-compatible
    `finish_reason: length` is `max_tokens`, `stop` is `end_turn`); None when unknown."""

    text: str
    model: str
    usage: Usage = field(default_factory=Usage)
    stop_reason: str | None = None

    @property
    def truncated(self) -> bool:
        """The answer was cut off at the output limit (`max_tokens`) before it ended."""
        return self.stop_reason == STOP_MAX_TOKENS


STOP_MAX_TOKENS = "max_tokens"


@dataclass(frozen=True, kw_only=True)
class Author:
    """Who wrote a transcript's responses: a model (provider, name) or people."""

    kind: Literal["model", "people"]
    provider: str | None = None
    model: str | None = None
    names: tuple[str, ...] = ()
    note: str | None = None

    def to_dict(self) -> dict:
        d: dict = {"kind": self.kind}
        if self.provider:
            d["provider"] = self.provider
        if self.model:
            d["model"] = self.model
        if self.names:
            d["names"] = list(self.names)
        if self.note:
            d["note"] = self.note
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Author:
        return cls(
            kind=d["kind"],
            provider=d.get("provider"),
            model=d.get("model"),
            names=tuple(d.get("names", ())),
            note=d.get("note"),
        )


class ModelClient(Protocol):
    """Anything that answers model requests."""

    @property
    def author(self) -> Author: ...

    def complete(self, request: ModelRequest) -> ModelResponse: ...
