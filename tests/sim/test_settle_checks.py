"""Physical validity: workspace, penetration, settling, construction orders."""

from __future__ import annotations

import numpy as np
import pytest

import domains
from sim.errors import InvalidSceneError
from sim.settle import check_order, check_scene, settle, validate_scene


def _at(x, y, z, yaw=0.0):
    c, s = np.cos(yaw), np.sin(yaw)
    p = np.eye(4)
    p[:2, :2] = [[c, -s], [s, c]]
    p[:3, 3] = (x, y, z)
    return p


def _scene(*placed):
    return {"domain": "cubes", "objects": [{"id": i, "mesh": "cube", "pose": p} for i, p in placed]}


@pytest.fixture(scope="module")
def cubes():
    return domains.load("cubes")


def test_a_resting_stack_is_valid(cubes):
    s = _scene(("red", _at(0.5, 0, 0.02)), ("blue", _at(0.5, 0, 0.06, 0.3)))
    assert check_scene(cubes, s) == []
    r = settle(cubes, s)
    assert r.settled and max(r.motion.values()) < 5e-4


def test_interpenetration_names_both_objects(cubes):
    s = _scene(("red", _at(0.5, 0, 0.02)), ("blue", _at(0.535, 0, 0.02)))
    (p,) = check_scene(cubes, s)
    assert p.object == "red" and "penetrates 'blue' by 5.0 mm" in p.problem


def test_a_floating_cube_is_not_at_rest(cubes):
    s = _scene(("red", _at(0.5, 0, 0.05)))
    (p,) = check_scene(cubes, s)
    assert p.object == "red" and "not at rest" in p.problem


def test_an_overhanging_cube_falls(cubes):
    s = _scene(("red", _at(0.5, 0, 0.02)), ("blue", _at(0.5, 0.035, 0.06)))
    assert [p.object for p in check_scene(cubes, s)] == ["blue"]


def test_outside_the_workspace(cubes):
    s = _scene(("red", _at(0.9, 0, 0.02)))
    (p,) = check_scene(cubes, s)
    assert "outside the reachable workspace" in p.problem


def test_table_penetration(cubes):
    (p,) = check_scene(cubes, _scene(("red", _at(0.5, 0, 0.015))))
    assert "penetrates the table by 5.0 mm" in p.problem


def test_validate_scene_raises_with_object_and_problem(cubes):
    with pytest.raises(InvalidSceneError, match="start: object 'red': penetrates the table") as e:
        validate_scene(cubes, _scene(("red", _at(0.5, 0, 0.0))), where="start")
    assert e.value.object == "red"


def test_check_order_refuses_moving_a_loaded_object(cubes):
    start = _scene(("red", _at(0.5, 0, 0.02)), ("blue", _at(0.5, 0, 0.06)))
    goal = _scene(("red", _at(0.6, 0, 0.02)), ("blue", _at(0.5, 0, 0.02)))
    bad = [{"object": "red", "target_pose": _at(0.6, 0, 0.02)}]
    problems = check_order(cubes, start, bad, goal, physics=False)
    assert "picks 'red' while 'blue' rest(s) on it" in problems[0].problem
    good = [
        {"object": "blue", "target_pose": _at(0.4, 0.1, 0.02)},
        {"object": "red", "target_pose": _at(0.6, 0, 0.02)},
        {"object": "blue", "target_pose": _at(0.5, 0, 0.02)},
    ]
    assert check_order(cubes, start, good, goal) == []
    assert "does not reach the goal" in check_order(cubes, start, good[:2], goal)[0].problem


def test_planner_unstacks_a_wrong_order_stack(cubes):
    start = _scene(
        ("red", _at(0.5, 0, 0.02)), ("blue", _at(0.5, 0, 0.06)), ("green", _at(0.6, 0.1, 0.02))
    )
    goal = _scene(
        ("blue", _at(0.5, 0, 0.02)), ("red", _at(0.5, 0, 0.06)), ("green", _at(0.5, 0, 0.10))
    )
    steps = cubes.reference_planner.order(start["objects"], goal["objects"])
    assert [s["object"] for s in steps] == ["blue", "red", "blue", "red", "green"]
    assert check_order(cubes, start, steps, goal) == []
