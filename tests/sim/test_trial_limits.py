"""A trial is bounded whatever the policy hands over (issue 35, item 4): a plan over the plan
contract's step cap is refused before the robot gets it, perceived states over the domain's
counts are refused before they are scored, and a trial has a wall-clock deadline that ends it
failed, saying so. Real engine: MuJoCo, the executor, the local sandbox for the programs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import domains
from artifacts.policy import ProgramPolicy
from artifacts.runtime import from_folder
from sim.settle import physical_problems
from sim.trials import OraclePolicy, PolicyOutput, run_trial

REPO = Path(__file__).resolve().parents[2]
PROGRAMS = REPO / "domains" / "cubes" / "programs"
DRAFTS = REPO / "tests" / "checks" / "drafts"


class Handing:
    """A policy that hands over a fixed output; as an oracle (ground-truth belief) or not."""

    name = "handing"

    def __init__(self, output: PolicyOutput, *, oracle: bool = True):
        self.output, self.oracle = output, oracle

    def solve_from_truth(self, instance, domain=None):
        return self.output

    def solve(self, domain, start_obs, goal_obs):
        return self.output


@pytest.fixture(scope="module")
def cubes():
    d = domains.load("cubes")
    return d, d.benchmark_instance(1, 1, physics=physical_problems)


def _still(instance, n: int) -> dict:
    """A plan of `n` steps, each putting the first object back where it is."""
    first = instance.start["objects"][0]
    step = {"object": first["id"], "target_pose": np.asarray(first["pose"], float)}
    return {"status": "ok", "steps": [step] * n}


def test_a_plan_over_the_cap_is_refused_before_execution(cubes):
    domain, instance = cubes
    policy = Handing(PolicyOutput(plan=_still(instance, 40_000), start_state=None, goal_state=None))
    r = run_trial(domain, instance, policy)
    assert not (r.plan_ok or r.final_ok)
    assert r.failure == {
        "stage": "planning",
        "reason": "plan refused unexecuted: 40000 plan steps, over the plan contract's cap of 1000",
    }
    assert r.steps == [] and "execute" not in r.timings  # the robot never moved


def test_perceived_states_over_the_counts_are_refused_before_scoring(cubes):
    domain, instance = cubes
    pose = np.eye(4)
    stacked = [{"id": f"s{k}", "mesh": "cube", "pose": pose} for k in range(4000)]
    policy = Handing(
        PolicyOutput(
            plan=_still(instance, 1),
            start_state={"objects": stacked, "relations": {}},
            goal_state={"objects": stacked, "relations": {}},
        ),
        oracle=False,
    )
    r = run_trial(domain, instance, policy)
    assert r.failure == {
        "stage": "perception",
        "reason": "start: the perceived records are refused: 4000 records, but the domain's "
        "catalogue holds 6 objects",
    }
    assert not r.state_ok and r.steps == []


def test_a_program_plan_over_the_cap_fails_the_trial_at_planning(cubes, tmp_path):
    """`rivet eval --policy programs DIR`'s path: the runtime refuses the plan."""
    domain, instance = cubes
    for name in ("render", "perceive", "relate"):
        (tmp_path / f"{name}.py").write_text((PROGRAMS / f"{name}.py").read_text())
    (tmp_path / "plan.py").write_text((DRAFTS / "plan_long.py").read_text())
    policy = ProgramPolicy(from_folder("cubes", tmp_path), "programs", sandbox="local")
    try:
        r = run_trial(domain, instance, policy)
    finally:
        policy.close()
    assert r.failure["stage"] == "planning"
    assert r.failure["reason"].startswith(
        "policy raised ProgramFailed: the frozen `plan` returned a value that cannot be used "
        "(40000 plan steps, over the plan contract's cap of 1000)"
    )
    assert r.steps == []


def test_a_trial_past_its_deadline_ends_failed_before_the_robot_moves(cubes):
    domain, instance = cubes
    r = run_trial(domain, instance, OraclePolicy(), deadline_s=0.0)
    assert not r.final_ok
    assert r.execution_failure["kind"] == "deadline" and r.execution_failure["step"] == 0
    first = instance.order[0]["object"]
    assert r.failure == {
        "stage": "execution",
        "reason": f"the trial ran past its 0 s wall-clock deadline: step 0 ({first}) stopped "
        "before its grasp phase, later steps not run",
    }


@pytest.mark.slow
def test_a_long_plan_within_the_cap_is_cut_off_by_the_deadline(cubes):
    """The reference order, then its last step again and again up to the cap: a plan that
    reaches the goal, and would keep the robot busy for an hour."""
    domain, instance = cubes
    order = [
        {"object": s["object"], "target_pose": np.asarray(s["target_pose"], float)}
        for s in instance.order
    ]
    steps = order + [order[-1]] * (1000 - len(order))
    policy = Handing(
        PolicyOutput(plan={"status": "ok", "steps": steps}, start_state=None, goal_state=None)
    )
    deadline = 10.0
    r = run_trial(domain, instance, policy, deadline_s=deadline)
    assert r.execution_failure["kind"] == "deadline"
    assert 0 < r.execution_failure["step"] < 1000  # some steps ran, most did not
    assert r.failure["reason"].startswith("the trial ran past its 10 s wall-clock deadline")
