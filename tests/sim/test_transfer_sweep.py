"""The arm along whole construction orders (`benchmarks.transfer_sweep`; the long sweeps are a
benchmark): a dev instance's order plans through, and a step the arm cannot make is refused
and named."""

from __future__ import annotations

import numpy as np
import pytest

import domains
from benchmarks.transfer_sweep import planner, sweep, walk
from sim.trials import OraclePolicy


@pytest.fixture(scope="module")
def cubes():
    d = domains.load("cubes")
    return d, d.benchmark("dev")[0]


def test_a_dev_order_plans_through(cubes):
    d, instance = cubes
    n, planned, refused = sweep(d, iter([instance]))
    assert (n, refused) == (1, [])
    assert planned == len(instance.order) > 0


def test_a_target_out_of_reach_is_refused_at_its_step(cubes):
    d, instance = cubes
    steps = OraclePolicy().solve_from_truth(instance, d).plan["steps"]
    steps[-1]["target_pose"] = np.array(steps[-1]["target_pose"], float)
    steps[-1]["target_pose"][:2, 3] = (1.2, 0.0)  # beyond the arm's reach
    done, why = walk(d, instance.start["objects"], steps, planner())
    assert done == len(steps) - 1
    assert why is not None and why.startswith(f"step {done} ({steps[-1]['object']}): ")
    assert "unreachable" in why or "no_grasp" in why


def test_every_planned_step_is_counted_by_the_way_it_goes(cubes):
    from collections import Counter

    d, instance = cubes
    ways: Counter[str] = Counter()
    n, planned, refused = sweep(d, iter([instance]), grasps=1, ways=ways)
    assert n == 1
    assert refused == [] and sum(ways.values()) == planned
    assert set(ways) <= {"cartesian", "long way", "joint approach", "joint transfer"}


@pytest.mark.slow
def test_with_one_grasp_a_dev_step_goes_by_a_joint_transfer():
    # dev goal10_start1, step 0: the L-block's best grasp has no Cartesian transfer the
    # descent can go on from (tests/sim/test_executor.py has it in the simulator)
    from collections import Counter

    d = domains.load("assembly")
    instance = next(i for i in d.benchmark("dev") if i.name == "goal10_start1")
    ways: Counter[str] = Counter()
    steps = OraclePolicy().solve_from_truth(instance, d).plan["steps"][:1]
    assert walk(d, instance.start["objects"], steps, planner(grasps=1), ways) == (1, None)
    assert ways == {"joint transfer": 1}


def test_the_sweep_refuses_a_grasp_limit_under_one(capsys):
    from benchmarks.transfer_sweep import main

    with pytest.raises(SystemExit) as exit_:
        main(["--dev", "--grasps", "0"])
    assert exit_.value.code == 2
    assert "--grasps must be at least 1" in capsys.readouterr().err
