"""Dollar prices per million tokens, the input estimate, and the budget checked before each call.

The table is data: update it when prices change. A model name is priced by an exact entry, or
by an entry followed by a date suffix (`claude-sonnet-4-5-20250929`, `claude-opus-5@20260101`)
or `-latest`; nothing else (so `claude-opus-5-5` is never priced as `claude-opus-5`). Cache
writes (5-minute TTL) cost 1.25× the input price and cache reads 0.1×, as Anthropic bills
prompt caching. Models outside the table (OpenAI-compatible servers) have no known price:
`--price IN,OUT` gives one.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

from agent.clients.base import ImageBlock, ModelRequest, TextBlock, Usage
from agent.errors import BudgetExceeded
from contracts.errors import UsageError

# USD per million tokens: (input, output).
PRICES: dict[str, tuple[float, float]] = {
    "claude-opus-5-5": (5.0, 25.0),
    "claude-opus-5": (5.0, 25.0),
    "claude-opus-4-5": (5.0, 25.0),
    "claude-sonnet-5": (3.0, 15.0),
    "claude-sonnet-4-5": (3.0, 15.0),
    "claude-haiku-4-5": (1.0, 5.0),
}
CACHE_WRITE_FACTOR = 1.25
CACHE_READ_FACTOR = 0.1

# The input estimate used when no token count is available (and before any network call).
CHARS_PER_TOKEN = 3.5
IMAGE_TOKENS_MAX = 1600  # a large image, as Anthropic resizes it (long edge ≤ 1568 px)
IMAGE_PIXELS_PER_TOKEN = 750
REQUEST_OVERHEAD_TOKENS = 50  # role markers, block separators

_SUFFIX = re.compile(r"(?:[-@]\d{8}|-latest)")

Price = tuple[float, float]


def price_of(model: str, price: Price | None = None) -> Price:
    """(input, output) USD per million tokens of `model`; `price` overrides the table."""
    if price is not None:
        return price
    for name in sorted(PRICES, key=len, reverse=True):  # longest first
        if model == name or (model.startswith(name) and _SUFFIX.fullmatch(model[len(name) :])):
            return PRICES[name]
    raise BudgetExceeded(
        f"no price known for model '{model}'; known: {', '.join(PRICES)} "
        "(pass --price IN,OUT in USD per million tokens, or add it to agent/clients/pricing.py)"
    )


def parse_price(text: str) -> Price:
    """`--price IN,OUT` (USD per million input, output tokens)."""
    try:
        pin, pout = (float(x) for x in text.split(","))
    except ValueError:
        raise UsageError(
            f"--price {text!r}: expected IN,OUT in USD per million tokens, e.g. 3,15"
        ) from None
    if pin < 0 or pout < 0:
        raise UsageError(f"--price {text!r}: prices cannot be negative")
    return (pin, pout)


def cost_usd(model: str, usage: Usage, price: Price | None = None) -> float:
    pin, pout = price_of(model, price)
    return (
        usage.input_tokens * pin
        + usage.cache_write_tokens * pin * CACHE_WRITE_FACTOR
        + usage.cache_read_tokens * pin * CACHE_READ_FACTOR
        + usage.output_tokens * pout
    ) / 1e6


def png_size(png: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG header, or None when it is not one."""
    if len(png) >= 24 and png[:8] == b"\x89PNG\r\n\x1a\n" and png[12:16] == b"IHDR":
        w, h = struct.unpack(">II", png[16:24])
        return int(w), int(h)
    return None


def image_tokens(png: bytes) -> int:
    size = png_size(png)
    if size is None:
        return IMAGE_TOKENS_MAX
    w, h = size
    return max(1, min(IMAGE_TOKENS_MAX, -(-w * h // IMAGE_PIXELS_PER_TOKEN)))


def estimate_input_tokens(request: ModelRequest) -> int:
    """Input tokens of `request`, estimated locally: characters / 3.5 for text, width × height
    / 750 (at most 1600) per image, plus a small fixed overhead. Errs high for prose and code."""
    chars = 0
    images = 0
    for b in (*request.system, *request.content):
        if isinstance(b, TextBlock):
            chars += len(b.text)
        elif isinstance(b, ImageBlock):
            images += image_tokens(b.png)
    return int(chars / CHARS_PER_TOKEN) + images + REQUEST_OVERHEAD_TOKENS


def worst_case_usd(input_tokens: int, max_tokens: int, price: Price) -> float:
    """The most a call can cost: every input token written to the cache, every output token."""
    pin, pout = price
    return (input_tokens * pin * CACHE_WRITE_FACTOR + max_tokens * pout) / 1e6


@dataclass
class Budget:
    """Spending limits of one `rivet author` invocation (a ledger across its runs).

    `reserve` is called before a call (and before each retry), `spend` after it with what the
    call cost, failed calls included when their usage is known. A resumed run starts from the
    journal's spending (`spent_usd`, `calls`).
    """

    max_usd: float | None = None
    max_calls: int | None = None
    spent_usd: float = 0.0
    calls: int = 0

    @property
    def left_usd(self) -> float | None:
        return None if self.max_usd is None else self.max_usd - self.spent_usd

    def check_calls(self) -> None:
        if self.max_calls is not None and self.calls + 1 > self.max_calls:
            raise BudgetExceeded(
                f"call budget reached: {self.calls} of --max-calls {self.max_calls}"
            )

    def check_output(self, max_tokens: int, output_price: float) -> None:
        """Refuse when the answer alone (`max_tokens` at the output price) cannot be covered."""
        self.check_calls()
        if self.max_usd is None:
            return
        worst = max_tokens * output_price / 1e6
        if self.spent_usd + worst > self.max_usd:
            raise BudgetExceeded(
                f"the answer alone could cost up to ${worst:.2f} (max_tokens {max_tokens} × "
                f"${output_price:g}/M output); spent ${self.spent_usd:.2f} of --max-usd "
                f"{self.max_usd:.2f}, so ${max(0.0, self.max_usd - self.spent_usd):.2f} is left"
            )

    def reserve(self, worst_case_usd: float) -> None:
        """Refuse a call that could exceed a limit (checked before the call, never after)."""
        self.check_calls()
        if self.max_usd is not None and self.spent_usd + worst_case_usd > self.max_usd:
            raise BudgetExceeded(
                f"the next call could cost up to ${worst_case_usd:.2f}; spent "
                f"${self.spent_usd:.2f} of --max-usd {self.max_usd:.2f}"
            )

    def spend(self, usd: float, *, call: bool = True) -> None:
        """Count a call's cost; `call=False` adds spending without counting another call (the
        partial usage of a failed attempt that is retried within the same call)."""
        if call:
            self.calls += 1
        self.spent_usd += usd

    def carry(self, spent_usd: float, calls: int) -> None:
        """Start from an earlier run's spending (`--resume`)."""
        self.spent_usd += spent_usd
        self.calls += calls
