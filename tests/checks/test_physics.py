"""geometry.physics: collisions, support and plan application on cubes (pure geometry)."""

from __future__ import annotations

import numpy as np
import pytest

from contracts import se3
from geometry import physics as ph

H = 0.02  # half edge [m]
CUBE = np.array([[x, y, z] for x in (-H, H) for y in (-H, H) for z in (-H, H)])


@pytest.fixture(scope="module")
def geo():
    return ph.Geometry({"cube": [CUBE]})


def rec(i, x, y, z, yaw=0.0):
    return {"id": i, "mesh": "cube", "pose": se3.make(se3.rot_z(yaw)[:3, :3], [x, y, z])}


def test_stack_is_valid_and_supported(geo):
    recs = [rec("a", 0.5, 0, H), rec("b", 0.5, 0, 3 * H)]
    assert ph.scene_problems(geo, recs) == []
    sup = ph.supports(geo.bodies(recs))
    assert sup["a"].on == ("table",) and sup["b"].on == ("a",)


def test_pyramid_cube_rests_on_two(geo):
    recs = [rec("a", 0.5, -0.023, H), rec("b", 0.5, 0.023, H), rec("c", 0.5, 0.0, 3 * H)]
    sup = ph.supports(geo.bodies(recs))
    assert sup["c"].on == ("a", "b") and sup["c"].stable


def test_interpenetration_is_a_collision(geo):
    recs = [rec("a", 0.5, 0, H), rec("b", 0.52, 0, H)]
    hits = ph.collisions(geo.bodies(recs))
    assert [(c.a, c.b) for c in hits] == [("a", "b")]
    assert hits[0].depth == pytest.approx(0.02, abs=1e-6)


def test_touching_side_by_side_is_not_a_collision(geo):
    recs = [rec("a", 0.5, 0, H), rec("b", 0.5 + 2 * H + 0.001, 0, H, yaw=np.pi / 2)]
    assert ph.collisions(geo.bodies(recs)) == []


def test_floating_and_overhanging_cubes_are_unsupported(geo):
    floating = ph.supports(geo.bodies([rec("a", 0.5, 0, H + 0.01)]))["a"]
    assert not floating.stable and "rests on nothing" in floating.reason
    overhang = ph.supports(geo.bodies([rec("a", 0.5, 0, H), rec("b", 0.5, 0.025, 3 * H)]))["b"]
    assert overhang.on == ("a",) and not overhang.stable and "tip over" in overhang.reason


def test_apply_plan_reaches_goal(geo):
    start = [rec("a", 0.5, 0, H), rec("b", 0.5, 0, 3 * H)]
    goal = [rec("b", 0.5, 0, H), rec("a", 0.5, 0, 3 * H)]
    steps = [
        {"object": "b", "target_pose": rec("b", 0.6, 0, H)["pose"]},
        {"object": "a", "target_pose": rec("a", 0.6, 0, 3 * H)["pose"]},
        {"object": "a", "target_pose": rec("a", 0.4, 0, H)["pose"]},
        {"object": "b", "target_pose": goal[0]["pose"]},
        {"object": "a", "target_pose": goal[1]["pose"]},
    ]
    out = ph.apply_plan(geo, start, steps, goal, trans_tol=0.01)
    assert out.ok and len(out.states) == 5


@pytest.mark.parametrize(
    ("steps", "kind"),
    [
        ([{"object": "a", "target_pose": rec("a", 0.6, 0, H)["pose"]}], "not_clear"),
        ([{"object": "b", "target_pose": rec("b", 0.51, 0, H)["pose"]}], "collision"),
        ([{"object": "b", "target_pose": rec("b", 0.6, 0, 3 * H)["pose"]}], "unsupported"),
        ([{"object": "z", "target_pose": np.eye(4)}], "unknown_object"),
        ([{"object": "b", "target_pose": rec("b", 0.95, 0, H)["pose"]}], "workspace"),
        ([{"object": "b", "target_pose": rec("b", 0.6, 0, H)["pose"]}], "goal"),
    ],
)
def test_apply_plan_names_the_first_problem(geo, steps, kind):
    start = [rec("a", 0.5, 0, H), rec("b", 0.5, 0, 3 * H)]
    ws = ph.Workspace(x=(0.25, 0.75), y=(-0.35, 0.35), reach=0.78)
    out = ph.apply_plan(geo, start, steps, start, trans_tol=0.01, workspace=ws)
    assert out.problem is not None and out.problem.kind == kind, out.problem


def test_goal_tolerance_is_modulo_symmetry(geo):
    start = [rec("a", 0.5, 0, H)]
    goal = [rec("a", 0.6, 0, H, yaw=np.pi / 2)]
    steps = [{"object": "a", "target_pose": rec("a", 0.6, 0, H)["pose"]}]
    syms = {"cube": se3.cube_group()}
    assert ph.apply_plan(geo, start, steps, goal, trans_tol=0.01, rot_tol=0.05, symmetries=syms).ok
    assert not ph.apply_plan(geo, start, steps, goal, trans_tol=0.01, rot_tol=0.05).ok


def test_generated_instances_and_their_orders_pass():
    import domains

    d = domains.load("cubes")
    geo = ph.Geometry({k: [m.vertices for m in ms] for k, ms in d.collision_meshes.items()})
    syms = {k: list(d.symmetries(k)) for k in d.mesh_specs}
    for seed in range(6):
        inst = d.generate(seed, physics=False)
        for side in (inst.start, inst.goal):
            assert ph.scene_problems(geo, side["objects"]) == []
        out = ph.apply_plan(
            geo,
            inst.start["objects"],
            inst.order,
            inst.goal["objects"],
            trans_tol=0.01,
            symmetries=syms,
        )
        assert out.ok, out.problem
