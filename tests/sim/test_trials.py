"""Trials end to end in MuJoCo: the oracle succeeds; bad plans end a trial with a clear
execution failure naming the step, and the harness goes on."""

from __future__ import annotations

import numpy as np
import pytest

import domains
from sim.evaluation import EvalConfig, run_eval, table
from sim.settle import physical_problems
from sim.trials import OraclePolicy, PolicyOutput, run_trial

pytestmark = pytest.mark.slow


class FixedPlan:
    name = "fixed"

    def __init__(self, make):
        self.make = make

    def solve(self, domain, instance, start_obs, goal_obs):
        return PolicyOutput(plan=self.make(instance), start_state=None, goal_state=None)


def _first(instance):
    s = instance.order[0]
    return s["object"], np.asarray(s["target_pose"], float)


BAD_PLANS = {
    "unknown_object": lambda i: {
        "status": "ok",
        "steps": [{"object": "magenta", "target_pose": _first(i)[1]}],
    },
    "non_rigid_target": lambda i: {
        "status": "ok",
        "steps": [
            {"object": _first(i)[0], "target_pose": np.diag([1.0, 1.0, -1.0, 1.0]) @ _first(i)[1]}
        ],
    },
    "unreachable": lambda i: {
        "status": "ok",
        "steps": [
            {
                "object": _first(i)[0],
                "target_pose": np.eye(4) + np.array([[0, 0, 0, 2.5]] + [[0] * 4] * 3),
            }
        ],
    },
}


@pytest.fixture(scope="module")
def cubes():
    d = domains.load("cubes")
    return d, d.benchmark_instance(1, 1, physics=physical_problems)


def test_oracle_trial_succeeds_with_precise_placements(cubes):
    domain, instance = cubes
    r = run_trial(domain, instance, OraclePolicy())
    assert r.final_ok and r.plan_ok and r.state_ok, r.failure
    errors = [s["position_error"] for s in r.steps]
    assert len(errors) == len(instance.order)
    assert np.median(errors) < 0.003
    assert r.timings["execute_sim"] > 0


@pytest.mark.parametrize("kind", sorted(BAD_PLANS))
def test_bad_plan_is_a_clear_execution_failure(cubes, kind):
    domain, instance = cubes
    r = run_trial(domain, instance, FixedPlan(BAD_PLANS[kind]))
    assert not r.final_ok and not r.plan_ok
    assert r.execution_failure is not None
    assert r.execution_failure["step"] == 0
    expected = {"unknown_object": "unknown_object", "non_rigid_target": "non_rigid_target"}.get(
        kind
    )
    if expected:
        assert r.execution_failure["kind"] == expected
    assert r.execution_failure["reason"]


def test_harness_goes_on_after_failures(cubes):
    _, instance = cubes
    bad = FixedPlan(BAD_PLANS["unknown_object"])
    config = EvalConfig(domain="cubes", policy=("oracle", None))
    from sim import evaluation

    evaluation._init_worker(config)
    evaluation._WORKER["policy"] = bad
    results = [evaluation._run_one(instance.to_dict()) for _ in range(2)]
    summary = evaluation.summarise(config, results)
    assert summary["trials"] == 2 and summary["final_sr"] == 0.0
    assert summary["failures"] == {"planning": 2}
    assert "magenta" in table(summary)


def test_run_eval_reports_metrics(cubes):
    _, instance = cubes
    summary = run_eval(EvalConfig(domain="cubes", policy=("oracle", None)), [instance.to_dict()])
    assert (summary["state_ac"], summary["plan_sr"], summary["final_sr"]) == (1.0, 1.0, 1.0)
    assert summary["precision"]["median_position_error_mm"] < 3.0
    assert set(summary) >= {"domain", "trials", "state_ac", "plan_sr", "final_sr", "per_trial"}


def test_record_writes_a_video_and_the_three_images(cubes, tmp_path):
    from PIL import Image

    from sim.executor import ExecutorConfig

    domain, instance = cubes
    oid, target = _first(instance)
    plan = {"status": "ok", "steps": [{"object": oid, "target_pose": target.tolist()}]}
    r = run_trial(
        domain,
        instance,
        FixedPlan(lambda i: plan),
        record_dir=tmp_path,
        config=ExecutorConfig(record_fps=4.0),  # few frames: this tests the recording only
    )
    assert r.steps and r.execution_failure is None, r.failure
    for name in ("start.png", "goal.png", "final.png"):
        with Image.open(tmp_path / name) as image:
            assert image.size[0] > 0
    video = (tmp_path / "trial.mp4").read_bytes()
    assert video[4:8] == b"ftyp" and len(video) > 10_000  # an MP4 container with frames in it
