"""Dollar prices per million tokens, and the budget checked before each call.

The table is data: update it when prices change. Cache writes (5-minute TTL) cost 1.25× the
input price and cache reads 0.1×, as Anthropic bills prompt caching.
"""

from __future__ import annotations

from dataclasses import dataclass

from agent.clients.base import Usage
from agent.errors import BudgetExceeded

# USD per million tokens: (input, output).
PRICES: dict[str, tuple[float, float]] = {
    "claude-opus-5": (5.0, 25.0),
    "claude-opus-4-5": (5.0, 25.0),
    "claude-sonnet-4-5": (3.0, 15.0),
    "claude-sonnet-5": (3.0, 15.0),
    "claude-haiku-4-5": (1.0, 5.0),
}
CACHE_WRITE_FACTOR = 1.25
CACHE_READ_FACTOR = 0.1


def price_of(model: str) -> tuple[float, float]:
    for name, price in PRICES.items():
        if model == name or model.startswith(name + "-"):
            return price
    raise BudgetExceeded(
        f"no price known for model '{model}'; known: {', '.join(PRICES)} "
        "(add it to agent/clients/pricing.py to budget it)"
    )


def cost_usd(model: str, usage: Usage) -> float:
    pin, pout = price_of(model)
    return (
        usage.input_tokens * pin
        + usage.cache_write_tokens * pin * CACHE_WRITE_FACTOR
        + usage.cache_read_tokens * pin * CACHE_READ_FACTOR
        + usage.output_tokens * pout
    ) / 1e6


@dataclass
class Budget:
    """Spending limits of a run; `reserve` is called before a call, `spend` after it."""

    max_usd: float | None = None
    max_calls: int | None = None
    spent_usd: float = 0.0
    calls: int = 0

    def reserve(self, worst_case_usd: float) -> None:
        """Refuse a call that could exceed a limit (checked before the call, never after)."""
        if self.max_calls is not None and self.calls + 1 > self.max_calls:
            raise BudgetExceeded(
                f"call budget reached: {self.calls} of --max-calls {self.max_calls}"
            )
        if self.max_usd is not None and self.spent_usd + worst_case_usd > self.max_usd:
            raise BudgetExceeded(
                f"the next call could cost up to ${worst_case_usd:.2f}; spent ${self.spent_usd:.2f} "
                f"of --max-usd {self.max_usd:.2f}"
            )

    def spend(self, usd: float) -> None:
        self.calls += 1
        self.spent_usd += usd
