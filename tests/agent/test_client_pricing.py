"""Prices (exact or dated names, longest first), the local input estimate, the budget ledger."""

from __future__ import annotations

import pytest

from agent.clients import Budget, ImageBlock, ModelRequest, TextBlock, Usage
from agent.clients.pricing import (
    PRICES,
    cost_usd,
    estimate_input_tokens,
    image_tokens,
    parse_price,
    price_of,
)
from agent.errors import BudgetExceeded
from contracts.errors import UsageError

CURRENT = {
    "claude-opus-5": (5, 25),
    "claude-opus-5-5": (5, 25),
    "claude-opus-4-5": (5, 25),
    "claude-sonnet-5": (3, 15),
    "claude-sonnet-4-5": (3, 15),
    "claude-haiku-4-5": (1, 5),
}


@pytest.mark.parametrize(("model", "price"), sorted(CURRENT.items()))
def test_current_models(model, price):
    assert price_of(model) == price
    assert price_of(f"{model}-20260115") == price
    assert price_of(f"{model}@20260115") == price
    assert price_of(f"{model}-latest") == price


def test_every_entry_is_its_own_model():
    assert set(CURRENT) <= set(PRICES)
    # exact or dated only: no entry prices a longer, different name
    for bad in (
        "claude-opus-5-6",
        "claude-sonnet-5-5",
        "claude-opus-5x",
        "claude-sonnet-5-mini",
        "claude-opus",
    ):
        with pytest.raises(BudgetExceeded, match="no price known"):
            price_of(bad)


def test_longest_match_first(monkeypatch):
    monkeypatch.setitem(PRICES, "claude-opus-5-5", (7.0, 35.0))  # were it priced differently
    assert price_of("claude-opus-5-5") == (7.0, 35.0)
    assert price_of("claude-opus-5-5-20270101") == (7.0, 35.0)
    assert price_of("claude-opus-5-20270101") == (5.0, 25.0)


def test_price_override_and_parsing():
    assert price_of("openai-whatever", (0.5, 1.5)) == (0.5, 1.5)
    assert parse_price("3,15") == (3.0, 15.0) and parse_price("0.2, 0.8") == (0.2, 0.8)
    for bad in ("3", "a,b", "1,2,3", "-1,2"):
        with pytest.raises(UsageError, match="--price"):
            parse_price(bad)


def test_cost():
    u = Usage(input_tokens=1000, output_tokens=100, cache_write_tokens=2000, cache_read_tokens=4000)
    assert cost_usd("claude-sonnet-5", u) == pytest.approx(
        (1000 * 3 + 100 * 15 + 2000 * 3 * 1.25 + 4000 * 0.3) / 1e6
    )


def test_the_input_estimate():
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (300, 200)).save(buf, format="PNG")
    png = buf.getvalue()
    assert image_tokens(png) == 80  # 300 × 200 / 750
    big = io.BytesIO()
    Image.new("RGB", (2000, 2000)).save(big, format="PNG")
    assert image_tokens(big.getvalue()) == 1600
    assert image_tokens(b"not a png") == 1600
    request = ModelRequest(
        function="render",
        attempt=1,
        system=(TextBlock(text="x" * 3500),),
        content=(TextBlock(text="y" * 350), ImageBlock(png=png)),
    )
    assert estimate_input_tokens(request) == 1000 + 100 + 80 + 50


def test_the_budget_ledger():
    b = Budget(max_usd=1.0)
    b.check_output(16000, 25.0)  # $0.40 fits
    b.spend(0.7)
    with pytest.raises(
        BudgetExceeded, match=r"the answer alone could cost up to \$0.40 .*\$0.30 is left"
    ):
        b.check_output(16000, 25.0)
    b.spend(0.1, call=False)
    assert b.calls == 1 and b.spent_usd == pytest.approx(0.8)
    b.carry(0.15, 3)
    assert b.calls == 4 and b.left_usd == pytest.approx(0.05)
    with pytest.raises(BudgetExceeded, match="could cost up to"):
        b.reserve(0.06)
    b.reserve(0.04)
    calls = Budget(max_calls=2, calls=2)
    with pytest.raises(BudgetExceeded, match="max-calls 2"):
        calls.check_output(1, 1.0)
