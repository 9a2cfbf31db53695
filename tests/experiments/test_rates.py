"""Every rate `rivet eval` reports comes with its Wilson 95 % interval, in the table and the
JSON."""

from __future__ import annotations

import pytest

from experiments.evaluation import EvalConfig, summarise, table, wilson


@pytest.mark.parametrize(
    ("k", "n", "low", "high"),
    [
        (60, 60, 0.9398, 1.0),  # a perfect 60: still not proof of 100 %
        (54, 60, 0.7985, 0.9534),
        (9, 270, 0.0176, 0.0621),
        (0, 180, 0.0, 0.0209),
    ],
)
def test_wilson_intervals(k, n, low, high):
    lo, hi = wilson(k, n)
    assert lo == pytest.approx(low, abs=1e-4) and hi == pytest.approx(high, abs=1e-4)
    assert lo <= k / n <= hi


def test_no_trials_no_interval():
    assert wilson(0, 0) is None


def _trial(ok: bool) -> dict:
    return {
        "name": "t",
        "state_ok": True,
        "plan_ok": ok,
        "final_ok": ok,
        "failure": None if ok else {"stage": "planning", "reason": "x"},
        "timings": {},
        "steps": [],
        "object_errors": [],
    }


def test_the_summary_and_the_table_carry_the_intervals():
    summary = summarise(
        EvalConfig(domain="cubes", policy=("oracle", None)), [_trial(True)] * 9 + [_trial(False)]
    )
    assert summary["intervals"]["state_ac"] == pytest.approx(wilson(10, 10))
    assert summary["intervals"]["final_sr"] == pytest.approx(wilson(9, 10))
    text = table(summary)
    assert "95 % interval" in text and "59.6–98.2%" in text, text


def test_the_fault_table_counts_toppled_parts_apart():
    """A trial not recovered whose fault left a part on another face is counted as toppled, in
    its gave-up or wrong column as well; the recoverable rate leaves those out."""

    def faulted(ok: bool, status: str | None, toppled: list[str], happened: bool = True) -> dict:
        t = {**_trial(ok), "fault": {"name": "push", "happened": happened, "toppled": toppled}}
        return {**t, "loop": None if status is None else {"status": status}}

    from experiments.evaluation import fault_table

    rows = fault_table([
        faulted(True, "done", []),
        faulted(True, "done", ["roof"]),  # tipped, and still the goal: recovered
        faulted(False, "gave_up", ["roof"]),
        faulted(False, "done", ["cylinder"]),
        faulted(False, "gave_up", []),
        faulted(False, None, [], happened=False),
    ])  # fmt: skip
    row = rows["push"]
    assert {
        k: row[k] for k in ("drawn", "happened", "recovered", "gave_up", "wrong", "toppled")
    } == {"drawn": 6, "happened": 5, "recovered": 2, "gave_up": 2, "wrong": 1, "toppled": 2}
    assert row["interval"] == wilson(2, 5) and row["recoverable_interval"] == wilson(2, 3)
