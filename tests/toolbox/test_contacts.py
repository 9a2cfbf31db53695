"""Collisions, support relations and resting poses from meshes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from toolbox.contacts import (
    poses_collide,
    resting_pose,
    support_relations,
    unsupported_objects,
    world_bounds,
)
from toolbox.errors import ToolboxError
from toolbox.geometry import make_pose, pose_from_xyz_yaw, rotation_about_axis

H = 0.025  # half side of the cube [m]


def rec(id, x, y, z, yaw=0.0):
    return {"id": id, "mesh": "cube", "pose": pose_from_xyz_yaw(x, y, z, yaw)}


@pytest.fixture
def meshes(cube):
    return {"cube": cube}


def test_stack_and_row_are_collision_free_with_the_right_support(meshes):
    recs = [rec("a", 0, 0, H), rec("b", 0.01, 0, 3 * H, 0.3), rec("c", 2 * H, 0, H)]
    assert poses_collide(recs, meshes) == []
    assert support_relations(recs, meshes) == [
        ("a", "table"),
        ("b", "a"),
        ("b", "c"),
        ("c", "table"),
    ]
    assert unsupported_objects(recs, meshes) == []


def test_side_contact_is_not_support(meshes):
    recs = [rec("a", 0, 0, H), rec("c", 2 * H, 0, H)]
    assert ("c", "a") not in support_relations(recs, meshes)


def test_overhang_and_floating_objects_are_unsupported(meshes):
    recs = [rec("a", 0, 0, H), rec("b", 0.035, 0, 3 * H), rec("f", 0.3, 0, 0.1)]
    assert unsupported_objects(recs, meshes) == ["b", "f"]
    assert support_relations(recs, meshes) == [("a", "table"), ("b", "a")]


@pytest.mark.parametrize("overlap", [0.004, 0.02])
def test_interpenetration_is_detected_with_its_depth(meshes, overlap):
    recs = [rec("a", 0, 0, H), rec("b", 2 * H - overlap, 0, H)]
    ((a, b, depth),) = poses_collide(recs, meshes)
    assert (a, b) == ("a", "b")
    assert depth == pytest.approx(overlap, abs=2e-3)


def test_edge_crossing_edge_is_a_collision(meshes):
    # b is turned 45° about x and z and lowered so that only edges cross: no vertex of either
    # cube is inside the other.
    R = rotation_about_axis((1, 0, 0), np.pi / 4) @ rotation_about_axis((0, 0, 1), np.pi / 4)
    b = {"id": "b", "mesh": "cube", "pose": make_pose(R, (0, 0, 2 * H + H * np.sqrt(2) - 0.005))}
    hits = poses_collide([rec("a", 0, 0, H), b], meshes)
    assert [(x, y) for x, y, _ in hits] == [("a", "b")]


def test_below_the_table_is_a_collision(meshes):
    hits = poses_collide([rec("a", 0, 0, H - 0.01)], meshes)
    assert hits == [("a", "table", pytest.approx(0.01))]
    assert poses_collide([rec("a", 0, 0, H - 0.01)], meshes, table_height=None) == []


def test_resting_pose_puts_the_lowest_point_on_the_support():
    mesh = trimesh.creation.cylinder(radius=0.02, height=0.1)
    tilt = rotation_about_axis((1, 0, 0), np.pi / 2)  # lying on its side
    T = resting_pose(mesh, 0.1, -0.2, 0.5, rotation=tilt, height=0.05)
    lo, hi = world_bounds(mesh, T)
    assert lo[2] == pytest.approx(0.05)
    assert hi[2] == pytest.approx(0.09)
    np.testing.assert_allclose(T[:2, 3], (0.1, -0.2))


def test_unknown_mesh_is_reported(meshes):
    with pytest.raises(ToolboxError, match="known: cube"):
        poses_collide([{"id": "x", "mesh": "nope", "pose": np.eye(4)}], meshes)
