"""Seeded, bounded shrinking: same counterexample every time, within a call budget."""

from __future__ import annotations

from hypothesis import strategies as st

from checks.hypo import Failure, run_property

STRATEGY = st.tuples(st.integers(0, 9), st.integers(-50, 50))


def buggy(x):
    i, d = x
    return Failure(message=f"bad {x}", counterexample=x) if i >= 3 and d > 10 else None


def test_failure_is_shrunk_and_reproducible():
    runs = [run_property(buggy, STRATEGY, max_examples=60, seed=1) for _ in range(3)]
    assert all(r.failure is not None for r in runs)
    assert {r.failure.counterexample for r in runs} == {(3, 11)}
    assert len({r.examples for r in runs}) == 1


def test_explicit_examples_run_first():
    seen = []

    def prop(x):
        seen.append(x)

    run_property(prop, STRATEGY, max_examples=5, seed=1, examples=[(9, 9), (8, 8)])
    assert seen[:2] == [(9, 9), (8, 8)]


def test_shrinking_stops_after_its_budget():
    calls = []

    def prop(x):
        calls.append(x)
        return buggy(x)

    out = run_property(prop, STRATEGY, max_examples=200, seed=3, shrink_calls=2)
    assert out.failure is not None
    first = next(k for k, x in enumerate(calls) if buggy(x))
    assert len(calls) - first - 1 <= 2  # at most 2 new calls after the first failure


def test_a_holding_property_passes():
    out = run_property(lambda x: None, STRATEGY, max_examples=10, seed=0)
    assert out.failure is None and out.examples == 10
