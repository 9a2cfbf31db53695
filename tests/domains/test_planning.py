"""Construction orders the robot can execute: the grasp-aware planner (geometry only)."""

from __future__ import annotations

import numpy as np
import pytest

import domains
from geometry import yaw_pose
from sim.settle import check_order

# The cubes reference pyramid (goal 1) from a start where the geometric planner parks cyan
# 12 mm from the pyramid's base: the fingers then cannot reach between it and the base, and
# cannot pick cyan again once the second level stands beside it.
PYRAMID = (
    ("red", -0.046, 0.0),
    ("green", 0.0, 0.0),
    ("blue", 0.046, 0.0),
    ("yellow", -0.023, 1.0),
    ("purple", 0.023, 1.0),
    ("cyan", 0.0, 2.0),
)
START = (
    ("cyan", 0.4946, 0.0073, -138.3),
    ("yellow", 0.5057, -0.1531, 79.4),
    ("purple", 0.3577, 0.1711, 62.0),
    ("red", 0.4514, 0.2072, 164.4),
    ("blue", 0.4248, 0.0935, -70.5),
    ("green", 0.5913, -0.0678, -129.5),
)


def _records(placed):
    return [{"id": i, "mesh": "cube", "pose": p} for i, p in placed]


@pytest.fixture(scope="module")
def cubes():
    return domains.load("cubes")


@pytest.fixture(scope="module")
def pyramid_instance():
    goal = _records(
        (i, yaw_pose(0.5, y, 0.02 + 0.04 * level, np.pi / 2)) for i, y, level in PYRAMID
    )
    start = _records((i, yaw_pose(x, y, 0.02, np.radians(a))) for i, x, y, a in START)
    return start, goal


def test_a_geometric_order_can_be_unexecutable(cubes, pyramid_instance):
    start, goal = pyramid_instance
    steps = cubes.reference_planner.order(start, goal)
    bad = cubes.grasps.first_infeasible(start, steps)
    assert bad is not None
    assert "fingers hit" in bad.verdict.reason and bad.verdict.blockers


def test_the_robot_planner_finds_an_executable_order(cubes, pyramid_instance):
    start, goal = pyramid_instance
    steps = cubes.robot_reference_planner.order(start, goal)
    assert cubes.grasps.first_infeasible(start, steps) is None
    scene = lambda records: {"domain": "cubes", "objects": records}  # noqa: E731
    assert check_order(cubes, scene(start), steps, scene(goal), physics=False) == []


def test_an_executable_geometric_order_is_kept(cubes):
    inst = cubes.generate(3, grasps=False)
    steps = cubes.reference_planner.order(inst.start["objects"], inst.goal["objects"])
    assert cubes.grasps.first_infeasible(inst.start["objects"], steps) is None  # premise
    robot = cubes.robot_reference_planner.order(inst.start["objects"], inst.goal["objects"])
    assert [s["object"] for s in robot] == [s["object"] for s in steps]
    assert all(
        np.allclose(a["target_pose"], b["target_pose"]) for a, b in zip(robot, steps, strict=True)
    )


def test_grasp_verdicts_name_the_blocking_neighbour(cubes):
    cube = yaw_pose(0.5, 0.0, 0.02, 0.0)
    # neighbours 10 mm away on all four sides: no room for a finger anywhere
    others = {
        n: ("cube", yaw_pose(0.5 + dx, dy, 0.02, 0.0))
        for n, dx, dy in (("a", 0.05, 0), ("b", -0.05, 0), ("c", 0, 0.05), ("d", 0, -0.05))
    }
    verdict = cubes.grasps.pickable("x", "cube", cube, others)
    assert not verdict.ok and verdict.blockers and set(verdict.blockers) <= set(others)
    del others["a"], others["b"]  # the x axis is free again
    assert cubes.grasps.pickable("x", "cube", cube, others).ok


def test_nothing_may_hang_above_a_pick_or_a_place():
    assembly = domains.load("assembly")
    roof = yaw_pose(0.5, 0.0, 0.0, 0.0)
    # the beam 40 mm above the roof's end, as if laid across pillars over it
    beam = {"beam": ("beam", yaw_pose(0.58, 0.0, 0.08, np.pi / 2))}
    verdict = assembly.grasps.pickable("roof", "roof", roof, beam)
    assert not verdict.ok and verdict.blockers == ("beam",)
    assert "above the object at the pick" in verdict.reason
    clear = {"beam": ("beam", yaw_pose(0.5, 0.2, 0.08, np.pi / 2))}
    assert assembly.grasps.pickable("roof", "roof", roof, clear).ok
    # and none may come down onto a place under it
    target = yaw_pose(0.5, 0.3, 0.0, 0.0)
    over_target = {"beam": ("beam", yaw_pose(0.5, 0.3, 0.08, 0.0))}
    verdict = assembly.grasps.move("roof", "roof", roof, target, {}, over_target)
    assert not verdict.ok and "at the place" in verdict.reason


def test_an_overhang_must_clear_the_sweep_a_neighbour_beside_may_touch_it():
    # the L-block brushing the edge of a block that overhangs its place knocked the block's
    # pillar over (a dev-goal instance from a cluttered start); beside the place, touching is
    # what adjacent parts do
    from geometry import TOLERANCES

    assembly = domains.load("assembly")
    x_max = float(np.asarray(assembly.mesh("block").vertices)[:, 0].max())  # the block's +x end
    beam_half = float(np.asarray(assembly.mesh("beam").vertices)[:, 0].max())
    block = yaw_pose(0.5, 0.0, 0.0, 0.0)
    here = yaw_pose(0.5, 0.2, 0.0, 0.0)

    def beam_at(gap: float, z: float) -> dict:
        # the beam along x, its -x end `gap` beyond the block's +x end at the place
        return {"beam": ("beam", yaw_pose(0.5 + x_max + gap + beam_half, 0.0, z, 0.0))}

    def move(others):
        return assembly.grasps.move("block", "block", here, block, {}, others)

    overhang = 0.05  # the beam's underside 20 mm above the block's top
    inside = move(beam_at(-TOLERANCES.sweep_touch / 2, overhang))
    assert not inside.ok and inside.blockers == ("beam",), inside.reason
    assert "above the object at the place" in inside.reason
    assert not move(beam_at(TOLERANCES.sweep_clearance / 2, overhang)).ok
    assert move(beam_at(2 * TOLERANCES.sweep_clearance, overhang)).ok
    # lying on the table beside the place, the beam may touch the sweep
    assert move(beam_at(-TOLERANCES.sweep_touch / 2, 0.0)).ok
