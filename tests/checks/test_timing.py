"""The speed gate's sample: each input's first call, by a content hash of its arguments, and
both CPU and wall time (`checks.timing`, `checks.context.check_fast_enough`)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from checks.budget import WALL_FACTOR
from checks.context import check_fast_enough
from checks.timing import TimingLog, input_key
from sandbox import MESHES


def _records(x: float = 0.4) -> list[dict]:
    T = np.eye(4)
    T[0, 3] = x
    return [{"id": "red", "mesh": "cube", "pose": T}]


def test_equal_values_hash_equal_and_others_do_not():
    a = input_key([_records(), MESHES, {"width": 64, "height": 48}])
    b = input_key([_records(), MESHES, {"height": 48, "width": 64}])  # key order aside
    assert a == b
    assert input_key([_records(0.41), MESHES]) != input_key([_records(), MESHES])
    assert input_key([np.zeros(3, np.float32)]) != input_key([np.zeros(3, np.float64)])
    assert input_key([np.zeros((2, 3))]) != input_key([np.zeros((3, 2))])
    assert input_key([[1, 2]]) != input_key([[12]])
    assert input_key(["1"]) != input_key([1])


def _result(cpu: float, wall: float, verdict: str = "ok", queued: float = 0.0):
    return SimpleNamespace(cpu_seconds=cpu, seconds=wall, queued_seconds=queued, verdict=verdict)


def test_only_first_calls_on_an_input_count():
    log = TimingLog()
    log.record("a", [_records(0.4)], _result(0.6, 0.61))
    log.record("a again", [_records(0.4)], _result(0.001, 0.002))  # remembered
    log.record("b", [_records(0.5)], _result(0.6, 0.62))
    log.record("b again", [_records(0.5)], _result(0.001, 0.002))
    log.record("b again", [_records(0.5)], _result(0.001, 0.002))
    speed = log.speed()
    assert speed is not None
    assert (speed.calls, speed.fresh) == (5, 2)
    assert speed.cpu_median_s == 0.6 and speed.wall_max_label == "b"


def test_derived_inputs_and_calls_that_did_not_return_are_not_counted():
    log = TimingLog()
    log.record("scene", [_records(0.4)], _result(0.6, 0.6))
    moved = [_records(0.45)]
    log.mark_derived(moved)
    log.record("scene moved", moved, _result(0.001, 0.001))  # answered from a normalised cache
    log.record("late", [_records(0.7)], _result(0.0, 10.0, verdict="timeout"))
    log.record("late again", [_records(0.7)], _result(0.001, 0.001))  # seen, though it timed out
    speed = log.speed()
    assert speed is not None and speed.fresh == 1 and speed.cpu_median_s == 0.6


def _gate(cpu: list[float], wall: list[float], budget: float = 0.2, queued: float = 0.0):
    log = TimingLog()
    for k, (c, w) in enumerate(zip(cpu, wall, strict=True)):
        log.record(f"case {k}", [k], _result(c, w, queued=queued))
    return check_fast_enough("relate", SimpleNamespace(timings=log), budget)


def test_a_sleeping_draft_fails_on_wall_time():
    check = _gate([0.01] * 5, [0.5] * 5)
    assert check.failing
    assert "wall time not spent waiting for a CPU" in check.message, check.message
    assert "0.500" in check.message
    assert check.metrics["wall_ready_median_s"] == 0.5 and check.metrics["median_s"] == 0.01


def test_within_budget_passes_and_the_wall_limit_is_the_factor():
    budget = 0.2
    assert not _gate([0.15] * 5, [budget * WALL_FACTOR * 0.99] * 5, budget).failing
    assert _gate([0.15] * 5, [budget * WALL_FACTOR * 1.01] * 5, budget).failing


def test_waiting_for_a_cpu_on_a_busy_machine_is_not_held_against_it():
    """0.15 s of CPU that took 0.9 s of wall time, 0.74 s of it waiting for a CPU."""
    check = _gate([0.15] * 5, [0.9] * 5, queued=0.74)
    assert not check.failing, check.message
    assert check.metrics["wall_median_s"] == 0.9
    assert abs(check.metrics["wall_ready_median_s"] - 0.16) < 1e-9


def test_cpu_over_budget_fails_on_cpu():
    check = _gate([0.3] * 5, [0.31] * 5)
    assert check.failing and "s of CPU per call" in check.message


def test_no_returned_call_is_a_skip():
    check = check_fast_enough("relate", SimpleNamespace(timings=TimingLog()), 0.2)
    assert check.status == "skipped"
