"""Top-down grasp selection (geometry.grasps, geometry.clearance): geometry only, no physics."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import trimesh

_SHARED = Path(__file__).resolve().parents[3] / "shared" / "menagerie"
if _SHARED.is_dir():
    os.environ.setdefault("MENAGERIE_ROOT", str(_SHARED))

from contracts import se3  # noqa: E402
from geometry.clearance import boxes_hit_triangles  # noqa: E402
from geometry.grasps import Obstacle, plan_grasps  # noqa: E402
from geometry.robot import ROBOT, STROKE  # noqa: E402

CUBE = trimesh.creation.box((0.04, 0.04, 0.04))  # origin at the centre
CUBE_SYMS = se3.cube_group()


def _at(x: float, y: float, z: float, yaw: float = 0.0) -> np.ndarray:
    T = se3.rot_z(yaw)
    T[:3, 3] = [x, y, z]
    return T


def _closing_axis(grasp, which: str = "pick") -> np.ndarray:
    T = grasp.pick_tcp if which == "pick" else grasp.place_tcp
    return np.abs(np.round(T[:3, 1], 6))


def test_cube_grasps_are_top_down_and_clear_the_table():
    report = plan_grasps(CUBE, _at(0.5, 0.0, 0.02), _at(0.4, 0.2, 0.02, 0.3), symmetries=CUBE_SYMS)
    assert report.grasps
    for g in report.grasps:
        assert g.width == pytest.approx(0.04, abs=1e-6)
        assert g.pick_tcp[:3, 2] == pytest.approx([0, 0, -1], abs=1e-9)
        assert g.place_tcp[:3, 2] == pytest.approx([0, 0, -1], abs=1e-9)
        assert np.linalg.norm(g.pick_tcp[:2, 3] - [0.5, 0.0]) <= 0.0095  # pads on the faces
        assert 0.04 < g.open_gap < 0.085
        # The grasp is rigid: the object's pose relative to the TCP is the same at both ends.
        T_obj_place = g.place_tcp @ se3.inverse(g.T_object_tcp)
        assert se3.within_tolerance(
            T_obj_place,
            _at(0.4, 0.2, 0.02, 0.3),
            trans_tol=1e-9,
            rot_tol=1e-9,
            symmetries=CUBE_SYMS,
        )
    # The best grasp is centred and turns the wrist least: the 0.3 rad asked for, not more.
    assert report.grasps[0].pick_tcp[:2, 3] == pytest.approx([0.5, 0.0], abs=1e-3)
    assert abs(report.grasps[0].transfer_yaw) == pytest.approx(0.3, abs=1e-6)


def test_a_neighbour_at_the_pick_blocks_one_closing_direction():
    neighbour = Obstacle(id="n", mesh=CUBE, pose=_at(0.5, 0.055, 0.02))  # 15 mm gap along +y
    report = plan_grasps(
        CUBE,
        _at(0.5, 0.0, 0.02),
        _at(0.4, -0.2, 0.02),
        symmetries=CUBE_SYMS,
        pick_obstacles=[neighbour],
    )
    assert report.grasps
    assert all(_closing_axis(g) == pytest.approx([1, 0, 0]) for g in report.grasps)
    assert report.rejected["fingers hit 'n' at the pick"] > 0


def test_symmetric_place_option_is_chosen_when_a_neighbour_blocks_the_other():
    """At the pick only x-closing is free; at the place only y-closing is: the grasp must use a
    quarter-turn symmetric placement of the cube."""
    pick, target = _at(0.5, 0.0, 0.02), _at(0.45, -0.2, 0.02)
    at_pick = [Obstacle(id="p", mesh=CUBE, pose=_at(0.5, 0.055, 0.02))]  # 15 mm gaps
    at_place = [Obstacle(id="q", mesh=CUBE, pose=_at(0.505, -0.2, 0.02))]
    report = plan_grasps(
        CUBE, pick, target, symmetries=CUBE_SYMS, pick_obstacles=at_pick, place_obstacles=at_place
    )
    assert report.grasps
    for g in report.grasps:
        assert _closing_axis(g, "pick") == pytest.approx([1, 0, 0])
        assert _closing_axis(g, "place") == pytest.approx([0, 1, 0])
        assert abs(abs(g.transfer_yaw) - np.pi / 2) < 1e-6
    # Without the symmetries there is no way to do it.
    none = plan_grasps(CUBE, pick, target, pick_obstacles=at_pick, place_obstacles=at_place)
    assert not none.grasps
    assert "fingers hit 'p' at the pick" in none.summary()
    assert "fingers hit 'q' at the place" in none.summary()


def test_too_wide_an_object_has_no_grasp():
    big = trimesh.creation.box((0.1, 0.1, 0.05))
    report = plan_grasps(big, _at(0.5, 0.0, 0.025), _at(0.4, 0.0, 0.025))
    assert not report.grasps
    assert "too wide" in report.summary()


def test_a_tilted_target_has_no_top_down_grasp():
    target = _at(0.4, 0.0, 0.02)
    target[:3, :3] = se3.rotvec_to_matrix([0.7, 0.0, 0.0])  # not a turn about the vertical
    report = plan_grasps(CUBE, _at(0.5, 0.0, 0.02), target)
    assert not report.grasps
    assert "tilted" in report.summary()


def _knob_plate() -> trimesh.Trimesh:
    """A 60 mm square plate, 15 mm thick, with a 15 mm square knob on top (a tangram piece)."""
    plate = trimesh.creation.box((0.06, 0.06, 0.015))
    plate.apply_translation((0, 0, 0.0075))
    knob = trimesh.creation.box((0.015, 0.015, 0.015))
    knob.apply_translation((0, 0, 0.0225))
    return trimesh.util.concatenate([plate, knob])


def test_a_plate_is_gripped_by_its_knob_with_the_fingertips_above_the_plate():
    piece = _knob_plate()
    report = plan_grasps(piece, _at(0.5, 0.0, 0.0), _at(0.45, 0.1, 0.0, 0.5), max_width=0.05)
    assert report.grasps
    for g in report.grasps:
        assert g.width == pytest.approx(0.015, abs=1e-6)
        fingertips = g.pick_tcp[2, 3] - STROKE.tip_at_gap(g.width)
        assert fingertips >= 0.015 + 0.002  # above the plate's top face


def test_box_triangle_overlap():
    tri = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    R = np.eye(3)
    assert boxes_hit_triangles(np.array([0.2, 0.2, 0.0]), np.array([0.05, 0.05, 0.05]), R, tri)
    assert not boxes_hit_triangles(np.array([0.8, 0.8, 0.0]), np.array([0.05, 0.05, 0.05]), R, tri)
    assert not boxes_hit_triangles(np.array([0.2, 0.2, 0.2]), np.array([0.05, 0.05, 0.05]), R, tri)
    # A box straddling the plane inside the triangle without containing a vertex.
    assert boxes_hit_triangles(np.array([0.3, 0.3, 0.0]), np.array([0.01, 0.01, 1.0]), R, tri)


def test_a_tall_pillar_is_gripped_high_enough_to_clear_the_linkage():
    pillar = trimesh.creation.box((0.03, 0.03, 0.08))
    pillar.apply_translation((0, 0, 0.04))
    report = plan_grasps(pillar, _at(0.5, 0.0, 0.0), _at(0.45, 0.1, 0.0))
    assert report.grasps
    fingers = ROBOT.gripper.fingers
    for g in report.grasps:
        tip = g.pick_tcp[2, 3] - STROKE.tip_at_gap(g.width)
        assert tip + fingers.ceiling_at(g.open_gap) >= 0.08  # the top stays below the linkage


def test_a_cylinder_is_gripped_across_its_side():
    cylinder = trimesh.creation.cylinder(radius=0.02, height=0.05, sections=32)
    report = plan_grasps(cylinder, _at(0.5, 0.0, 0.025), _at(0.45, 0.1, 0.025))
    assert report.grasps  # across the round side (its flat ends are horizontal)
    assert all(g.width == pytest.approx(0.04, abs=0.0005) for g in report.grasps)
    closing = {
        round(float(np.arctan2(g.pick_tcp[1, 1], g.pick_tcp[0, 1])) % np.pi, 3)
        for g in report.grasps
    }
    assert len(closing) >= 8  # many directions around the side
