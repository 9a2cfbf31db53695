"""geometry: collisions, support, stability and plan application on cubes (pure geometry), and
the one tolerance the plan checks and the trials' scoring share."""

from __future__ import annotations

import numpy as np
import pytest

import geometry as g
from contracts import se3

H = 0.02  # half edge [m]
CUBE = np.array([[x, y, z] for x in (-H, H) for y in (-H, H) for z in (-H, H)])


@pytest.fixture(scope="module")
def geo():
    return g.Geometry.from_parts({"cube": [CUBE]})


def rec(i, x, y, z, yaw=0.0):
    return {"id": i, "mesh": "cube", "pose": se3.make(se3.rot_z(yaw)[:3, :3], [x, y, z])}


def test_stack_is_valid_and_supported(geo):
    recs = [rec("a", 0.5, 0, H), rec("b", 0.5, 0, 3 * H)]
    assert g.scene_problems(recs, geo) == []
    assert g.supports(recs, geo) == {"a": ["table"], "b": ["a"]}


def test_pyramid_cube_rests_on_two(geo):
    recs = [rec("a", 0.5, -0.023, H), rec("b", 0.5, 0.023, H), rec("c", 0.5, 0.0, 3 * H)]
    assert g.supports(recs, geo)["c"] == ["a", "b"] and g.unstable_objects(recs, geo) == {}


def test_interpenetration_is_a_collision(geo):
    recs = [rec("a", 0.5, 0, H), rec("b", 0.52, 0, H)]
    hits = g.collisions(recs, geo)
    assert [(a, b) for a, b, _ in hits] == [("a", "b")]
    assert hits[0][2] == pytest.approx(0.02, abs=1e-6)


def test_touching_side_by_side_is_not_a_collision(geo):
    recs = [rec("a", 0.5, 0, H), rec("b", 0.5 + 2 * H + 0.001, 0, H, yaw=np.pi / 2)]
    assert g.collisions(recs, geo) == []


def test_floating_and_overhanging_cubes_are_unstable(geo):
    assert "rests on nothing" in g.unstable_objects([rec("a", 0.5, 0, H + 0.01)], geo)["a"]
    overhang = g.unstable_objects([rec("a", 0.5, 0, H), rec("b", 0.5, 0.025, 3 * H)], geo)
    assert set(overhang) == {"b"} and "outside its support" in overhang["b"]


def test_a_load_can_tip_its_supporter(geo):
    """A cube resting half over the edge of another tips it only with its load counted."""
    base = rec("a", 0.5, 0, H)
    top = rec("b", 0.5, 0.0195, 3 * H)  # its centre 0.5 mm inside a's edge: stands
    assert g.unstable_objects([base, top], geo) == {}
    heavier = [base, top, rec("c", 0.5, 0.0395, 5 * H)]  # a third one further out
    assert "with its load" in g.unstable_objects(heavier, geo).get("b", "")


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
    out = g.apply_plan(geo, start, steps, goal, trans_tol=0.01)
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
    ws = g.Workspace(x=(0.25, 0.75), y=(-0.35, 0.35), reach=0.78)
    out = g.apply_plan(geo, start, steps, start, trans_tol=0.01, workspace=ws)
    assert out.problem is not None and out.problem.kind == kind, out.problem


def test_goal_tolerance_is_modulo_symmetry(geo):
    start = [rec("a", 0.5, 0, H)]
    goal = [rec("a", 0.6, 0, H, yaw=np.pi / 2)]
    steps = [{"object": "a", "target_pose": rec("a", 0.6, 0, H)["pose"]}]
    syms = {"cube": se3.cube_group()}
    assert g.apply_plan(geo, start, steps, goal, trans_tol=0.01, rot_tol=0.05, symmetries=syms).ok
    assert not g.apply_plan(geo, start, steps, goal, trans_tol=0.01, rot_tol=0.05).ok


def test_generated_instances_and_their_orders_pass():
    import domains

    d = domains.load("cubes")
    syms = {k: list(d.symmetries(k)) for k in d.mesh_specs}
    for seed in range(6):
        inst = d.generate(seed)
        for side in (inst.start, inst.goal):
            assert g.scene_problems(side["objects"], d.shapes) == []
        out = g.apply_plan(
            d.shapes,
            inst.start["objects"],
            inst.order,
            inst.goal["objects"],
            trans_tol=0.01,
            symmetries=syms,
        )
        assert out.ok, out.problem


@pytest.mark.parametrize(("depth_mm", "accepted"), [(0.8, True), (1.2, False)])
def test_plan_checks_and_trial_scoring_share_one_penetration_tolerance(depth_mm, accepted):
    """A step that puts one cube `depth_mm` into another is judged alike by the plan checks'
    property (`checks.suites.plan`, through `geometry.apply_plan`) and by the trials' plan
    success (`sim.settle.check_order`)."""
    import domains
    from checks.context import DomainSpec
    from sim.settle import check_order

    d = domains.load("cubes")
    spec = DomainSpec.of(d)
    start = [rec(o, 0.40 + 0.06 * k, -0.1, H) for k, o in enumerate(d.object_ids)]
    start = [dict(r, mesh=d.object(r["id"]).mesh) for r in start]
    target = rec(start[1]["id"], start[0]["pose"][0, 3] + 2 * H - depth_mm / 1000, 0.1, H)
    moved = dict(start[1], pose=target["pose"])
    neighbour = dict(start[0], pose=rec(start[0]["id"], start[0]["pose"][0, 3], 0.1, H)["pose"])
    steps = [
        {"object": neighbour["id"], "target_pose": neighbour["pose"]},
        {"object": moved["id"], "target_pose": moved["pose"]},
    ]
    goal = [neighbour, moved, *start[2:]]
    check = g.apply_plan(
        spec.geometry,
        start,
        steps,
        goal,
        trans_tol=spec.trans_tol,
        symmetries=spec.symmetries,
        workspace=spec.workspace,
    )
    trial = check_order(d, d.scene(start), steps, d.scene(goal), physics=False)
    assert check.ok is accepted, check.problem
    assert (trial == []) is accepted, trial
