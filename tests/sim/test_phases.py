"""The executor runs a transfer's phases by their segments' labels (`sim._motion.split_at`),
not by where they stand in the list."""

from __future__ import annotations

import numpy as np
import pytest

from sim._motion import PlannedSegment, Segment, split_at


def _planned(*labels: str) -> list[PlannedSegment]:
    return [
        PlannedSegment(segment=Segment(label=label, duration=0.1), q=np.zeros((1, 7)), grip=None)
        for label in labels
    ]


def _labels(runs):
    return [[p.segment.label for p in run] for run in runs]


def test_cut_before_each_label_in_order():
    pick = _planned(
        "rising", "moving above", "descending", "reaching", "closing", "squeezing", "lifting"
    )
    assert _labels(split_at(pick, "closing", "lifting")) == [
        ["rising", "moving above", "descending", "reaching"],
        ["closing", "squeezing"],
        ["lifting"],
    ]
    # an approach without the rise is cut the same way: positions differ, labels do not
    assert _labels(split_at(pick[1:], "closing", "lifting"))[1:] == [
        ["closing", "squeezing"],
        ["lifting"],
    ]


def test_a_missing_or_misordered_label_is_an_error():
    place = _planned("transferring", "descending", "reaching")
    with pytest.raises(ValueError, match="no segment 'opening'"):
        split_at(place, "descending", "opening")
    with pytest.raises(ValueError, match="no segment 'descending'"):
        split_at(place, "reaching", "descending")


def test_a_planned_transfer_cuts_into_the_executors_phases():
    """A real pick and place, planned as the executor plans them, cut at the labels the
    executor uses: every phase is there, in order, and nothing is left between them."""
    import domains
    from benchmarks.transfer_sweep import planner
    from sim import robot
    from sim.execution import ExecutorConfig
    from sim.executor import _place_phases
    from sim.transfer import CLOSING, LIFTING, TransferPlanner, obstacles
    from sim.trials import OraclePolicy

    domain = domains.load("cubes")
    instance = domain.benchmark("dev")[0]
    parts = planner()
    transfers = TransferPlanner(parts.ik, ExecutorConfig(), parts.wrist, parts.tick_dt)
    step = OraclePolicy().solve_from_truth(instance, domain).plan["steps"][0]
    records = {r["id"]: r for r in instance.start["objects"]}
    belief = {o: np.asarray(r["pose"], float) for o, r in records.items()}
    meshes = {o: domain.mesh(r["mesh"]) for o, r in records.items()}
    oid = step["object"]
    target = np.asarray(step["target_pose"], float)
    chosen = transfers.choose(
        robot.READY_QPOS, robot.GRIPPER_OPEN, meshes[oid],
        list(domain.symmetries(records[oid]["mesh"])), belief[oid], target,
        obstacles(belief, meshes, oid),
    )  # fmt: skip
    approach, close, lift = split_at(chosen.pick, CLOSING, LIFTING)
    assert approach and _labels([close, lift]) == [["closing", "squeezing"], ["lifting"]]
    place = transfers.place_segments(chosen.pick[-1].q[-1], chosen.grasp, target, chosen.transfer_z)
    assert _labels(_place_phases(place)) == [
        ["transferring"],
        ["descending to the target"],
        ["reaching the target"],
        ["settling before release", "opening", "settling after release"],
        ["retreating"],
    ]
