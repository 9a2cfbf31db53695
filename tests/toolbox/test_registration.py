"""3D registration: known transforms of synthetic clouds, mesh pose from rendered depth."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from tests.toolbox.conftest import l_block, look_at_camera
from toolbox.errors import ToolboxError
from toolbox.geometry import make_pose, pose_distance, rotation_about_axis, transform_points
from toolbox.registration import (
    global_registration,
    icp,
    register_mesh_to_points,
    register_mesh_to_segment,
)
from toolbox.render import render_scene
from toolbox.vision import depth_to_points


def random_pose(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return make_pose(
        rotation_about_axis(rng.normal(size=3), rng.uniform(0, np.pi)), rng.uniform(-0.2, 0.2, 3)
    )


@pytest.fixture(scope="module")
def part_points() -> np.ndarray:
    pts, _ = trimesh.sample.sample_surface(l_block(), 3000, seed=0)
    return np.asarray(pts)


def test_icp_recovers_a_small_offset(part_points):
    T = make_pose(rotation_about_axis((0, 0, 1), 0.05), (0.004, -0.003, 0.002))
    r = icp(part_points, transform_points(T, part_points), max_distance=0.02)
    d = pose_distance(r.transform, T)
    assert d.translation < 1e-4 and d.rotation < 1e-3
    assert r.fitness > 0.99 and r.rmse < 1e-4


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_global_registration_recovers_any_transform(part_points, seed):
    T = random_pose(seed)
    noisy = transform_points(T, part_points) + np.random.default_rng(seed).normal(
        0, 3e-4, part_points.shape
    )
    r = global_registration(part_points, noisy, voxel_size=0.004, seed=0)
    d = pose_distance(r.transform, T)
    assert d.translation < 2e-3 and d.rotation < np.deg2rad(1.5), d
    again = global_registration(part_points, noisy, voxel_size=0.004, seed=0)
    np.testing.assert_array_equal(again.transform, r.transform)  # seeded: deterministic


def render_segment(T, occluder=None):
    mesh = l_block()
    cam = look_at_camera((0.35, -0.35, 0.45), (0.0, 0.0, 0.03), width=320, height=240, f=350.0)
    recs = [{"id": "part", "mesh": "part", "pose": T}]
    meshes = {"part": mesh}
    if occluder is not None:
        recs.append({"id": "occluder", "mesh": "box", "pose": occluder})
        meshes["box"] = trimesh.creation.box((0.04, 0.04, 0.12))
    out = render_scene(recs, meshes, cam)
    return mesh, depth_to_points(out["depth"], cam, out["mask"] == 0)


@pytest.mark.parametrize("seed", [4, 5])
def test_mesh_pose_from_a_rendered_view(seed):
    rng = np.random.default_rng(seed)
    T = make_pose(
        rotation_about_axis(rng.normal(size=3), rng.uniform(0, np.pi)), (0.02, -0.01, 0.05)
    )
    mesh, pts = render_segment(T)
    r = register_mesh_to_points(mesh, pts)
    d = pose_distance(r.transform, T)
    assert d.translation < 3e-3 and d.rotation < np.deg2rad(2.0), d
    assert r.fitness > 0.9


def test_mesh_pose_of_a_partially_occluded_part():
    T = make_pose(rotation_about_axis((0, 0, 1), 0.7), (0.0, 0.0, 0.015))
    occluder = make_pose(None, (0.06, -0.04, 0.06))  # a post between the camera and the part
    mesh, pts = render_segment(T, occluder)
    _, full = render_segment(T)
    assert len(pts) < 0.9 * len(full)
    r = register_mesh_to_points(mesh, pts)
    d = pose_distance(r.transform, T)
    assert d.translation < 3e-3 and d.rotation < np.deg2rad(2.0), d


def test_registration_rejects_too_few_points():
    with pytest.raises(ToolboxError, match="at least 10"):
        register_mesh_to_points(l_block(), np.zeros((5, 3)))
    with pytest.raises(ToolboxError, match="at least 3"):
        icp(np.zeros((2, 3)), np.zeros((10, 3)))


def test_segment_registration_resolves_a_single_view_ambiguity():
    # Seen from this side the part's visible surface fits a flipped pose as well as the true
    # one; only the depth image (nothing is seen where the flipped part would show) tells.
    cam = look_at_camera((0.6, -0.6, 0.7), (0.0, 0.0, 0.0), width=640, height=360, f=450.0)
    T = make_pose(None, (-0.2, -0.1, 0.03))
    out = render_scene([{"id": "p", "mesh": "p", "pose": T}], {"p": l_block()}, cam)
    r = register_mesh_to_segment(l_block(), out["depth"], out["mask"] == 0, cam)
    d = pose_distance(r.transform, T)
    assert d.translation < 3e-3 and d.rotation < np.deg2rad(2.0), d
    assert r.fitness > 0.9 and r.consistency > 0.9


def test_segment_registration_excuses_occlusion_by_other_objects():
    mesh = l_block()
    cam = look_at_camera((0.35, -0.35, 0.45), (0.0, 0.0, 0.03), width=320, height=240, f=350.0)
    T = make_pose(rotation_about_axis((0, 0, 1), 0.7), (0.0, 0.0, 0.015))
    recs = [
        {"id": "part", "mesh": "part", "pose": T},
        {"id": "post", "mesh": "post", "pose": make_pose(None, (0.06, -0.04, 0.06))},
    ]
    out = render_scene(recs, {"part": mesh, "post": trimesh.creation.box((0.04, 0.04, 0.12))}, cam)
    r = register_mesh_to_segment(mesh, out["depth"], out["mask"] == 0, cam)
    d = pose_distance(r.transform, T)
    assert d.translation < 3e-3 and d.rotation < np.deg2rad(2.0), d
    assert r.consistency > 0.9
    with pytest.raises(ToolboxError, match="camera is 240x320"):
        register_mesh_to_segment(mesh, out["depth"][:10], out["mask"] == 0, cam)
