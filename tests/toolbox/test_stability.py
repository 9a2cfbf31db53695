"""Convex pieces, resting poses, separation, support and load-carrying stability."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from toolbox.errors import ToolboxError
from toolbox.geometry import pose_from_xyz_yaw
from toolbox.stability import (
    Shape,
    collisions,
    separation,
    stable_poses,
    supports,
    unstable_objects,
)


def box(sx, sy, sz) -> trimesh.Trimesh:
    """A box with its origin at the centre of its bottom face."""
    m = trimesh.creation.box((sx, sy, sz))
    m.apply_translation((0, 0, sz / 2))
    return m


def gate() -> trimesh.Trimesh:
    """A 90 x 30 x 60 mm gate: two 30 mm legs, 45 mm tall, under a 15 mm lintel, as an x-z
    profile extruded along y, origin at the centre of its bottom."""
    u = 0.03
    legs = [[0, 0], [u, 0], [u, 1.5 * u], [0, 1.5 * u], [2 * u, 0], [3 * u, 0]]
    v = np.array([*legs, [3 * u, 1.5 * u], [2 * u, 1.5 * u], [3 * u, 2 * u], [0, 2 * u]], float)
    tri = np.array(
        [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [9, 3, 2], [9, 2, 7], [9, 7, 6], [9, 6, 8]]
    )
    m = trimesh.creation.extrude_triangulation(v, tri, height=u)
    m.apply_translation((-1.5 * u, 0, -u / 2))  # profile in x-y, extruded along z
    m.apply_transform([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # y → z
    assert m.is_watertight and m.volume > 0
    return m


@pytest.fixture
def shapes():
    return {
        "pillar": Shape.from_mesh(box(0.03, 0.03, 0.08)),
        "beam": Shape.from_mesh(box(0.16, 0.035, 0.02)),
        "block": Shape.from_mesh(box(0.05, 0.035, 0.03)),
        "gate": Shape.from_mesh(gate()),
    }


def rec(id, mesh, x, y, z, yaw=0.0):
    return {"id": id, "mesh": mesh, "pose": pose_from_xyz_yaw(x, y, z, yaw)}


def test_convex_mesh_is_one_exact_piece(shapes):
    s = shapes["beam"]
    assert len(s.pieces) == 1 and s.exact
    assert s.volume == pytest.approx(0.16 * 0.035 * 0.02)
    np.testing.assert_allclose(s.centre_of_mass, [0, 0, 0.01], atol=1e-9)


def test_extruded_profile_decomposes_exactly_into_slabs(shapes):
    s, mesh = shapes["gate"], gate()
    assert s.exact and len(s.pieces) == 3  # leg, lintel over the opening, leg
    assert s.volume == pytest.approx(mesh.volume, rel=1e-6)
    np.testing.assert_allclose(s.centre_of_mass, mesh.center_mass, atol=1e-7)
    # nothing of the gate lies inside its opening
    probe = Shape.from_mesh(box(0.02, 0.02, 0.02))
    gap, _ = separation(probe, pose_from_xyz_yaw(0, 0, 0.0, 0), s, np.eye(4))
    assert gap > 0.004


def test_stable_poses_of_a_box_and_a_faceted_cylinder():
    poses = stable_poses(box(0.05, 0.035, 0.03))
    assert len(poses) == 6
    upright = [p for p in poses if np.allclose(p.rotation, np.eye(3))]
    assert len(upright) == 1 and upright[0].height == pytest.approx(0.0, abs=1e-12)
    assert upright[0].margin == pytest.approx(0.0175)
    for p in poses:
        assert np.allclose(p.rotation @ p.rotation.T, np.eye(3)) and np.linalg.det(p.rotation) > 0
    cyl = trimesh.creation.cylinder(radius=0.02, height=0.06, sections=48)
    assert len(stable_poses(cyl)) == 2  # on either end; it rolls on its side


def test_separation_reports_the_gap_and_its_axis(shapes):
    a = shapes["block"]
    gap, axis = separation(a, pose_from_xyz_yaw(0.06, 0, 0, 0), a, pose_from_xyz_yaw(0, 0, 0, 0))
    assert gap == pytest.approx(0.01) and np.allclose(axis, [1, 0, 0])
    gap, axis = separation(a, pose_from_xyz_yaw(0, 0, 0.03, 0), a, pose_from_xyz_yaw(0, 0, 0, 0))
    assert gap == pytest.approx(0.0, abs=1e-12) and np.allclose(axis, [0, 0, 1])
    gap, _ = separation(a, pose_from_xyz_yaw(0.04, 0, 0, 0), a, pose_from_xyz_yaw(0, 0, 0, 0))
    assert gap == pytest.approx(-0.01)


def test_supports_and_collisions_of_a_portal(shapes):
    recs = [
        rec("p1", "pillar", 0, -0.055, 0),
        rec("p2", "pillar", 0, 0.055, 0),
        rec("beam", "beam", 0, 0, 0.08, np.pi / 2),
        rec("gate", "gate", 0.2, 0, 0),
        rec("block", "block", 0.2, 0, 0.06),
    ]
    assert supports(recs, shapes) == {
        "p1": ["table"],
        "p2": ["table"],
        "beam": ["p1", "p2"],
        "gate": ["table"],
        "block": ["gate"],
    }
    assert collisions(recs, shapes) == []
    assert unstable_objects(recs, shapes) == {}
    sunk = [*recs[:4], rec("block", "block", 0.2, 0, 0.05)]
    (hit,) = collisions(sunk, shapes)
    assert hit[:2] == ("gate", "block") and hit[2] == pytest.approx(0.01)


def test_loads_are_carried_down_to_the_supports(shapes):
    portal = [
        rec("p1", "pillar", 0, -0.055, 0),
        rec("p2", "pillar", 0, 0.055, 0),
        rec("beam", "beam", 0, 0, 0.08, np.pi / 2),
    ]
    assert unstable_objects([*portal, rec("blk", "block", 0, 0.05, 0.1, np.pi / 2)], shapes) == {}
    # one pillar under the middle of the beam: the beam alone balances, with a block on one
    # end it tips
    tee = [rec("p1", "pillar", 0, 0, 0), rec("beam", "beam", 0, 0, 0.08, np.pi / 2)]
    assert unstable_objects(tee, shapes) == {}
    bad = unstable_objects([*tee, rec("blk", "block", 0, 0.05, 0.1, np.pi / 2)], shapes)
    assert list(bad) == ["beam"] and "with its load" in bad["beam"]
    floating = unstable_objects([rec("blk", "block", 0, 0, 0.02)], shapes)
    assert floating == {"blk": "rests on nothing"}


def test_unknown_mesh_and_bad_pose_are_refused(shapes):
    with pytest.raises(ToolboxError, match="no shape; known"):
        supports([{"id": "x", "mesh": "cube", "pose": np.eye(4)}], shapes)
    with pytest.raises(ToolboxError, match="pose"):
        collisions([{"id": "x", "mesh": "beam", "pose": np.eye(3)}], shapes)
