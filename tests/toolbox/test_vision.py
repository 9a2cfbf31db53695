"""Camera geometry and point clouds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.toolbox.conftest import look_at_camera, top_down_camera
from toolbox import vision as v
from toolbox.errors import ToolboxError

PROPS = settings(max_examples=60, deadline=None, derandomize=True)

eyes = st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(0.3, 1.5))


def plane_depth(camera: dict, plane=(0.0, 0.0, 1.0, 0.0)) -> np.ndarray:
    """Exact depth image of an infinite plane (0 where not seen)."""
    w, h = camera["width"], camera["height"]
    u, vv = np.meshgrid(np.arange(w), np.arange(h))
    pts = v.pixels_to_plane(np.c_[u.ravel(), vv.ravel()], camera, plane)
    _, z = v.project_points(np.nan_to_num(pts), camera)
    z[~np.isfinite(pts).all(axis=1)] = 0.0
    return z.reshape(h, w)


@PROPS
@given(eyes, st.floats(100.0, 800.0), st.floats(-20.0, 20.0))
def test_backprojection_then_projection_returns_the_pixel(eye, f, skew):
    cam = look_at_camera(eye, (0.1, -0.05, 0.0), f=f)
    cam["K"][0, 1] = skew
    rng = np.random.default_rng(0)
    uv = rng.uniform([0, 0], [cam["width"] - 1, cam["height"] - 1], size=(50, 2))
    z = rng.uniform(0.1, 3.0, size=50)
    uv2, z2 = v.project_points(v.backproject_pixels(uv, z, cam), cam)
    np.testing.assert_allclose(uv2, uv, atol=1e-6)
    np.testing.assert_allclose(z2, z, atol=1e-9)


@PROPS
@given(eyes)
def test_projection_then_backprojection_returns_the_point(eye):
    cam = look_at_camera(eye, (0.0, 0.0, 0.0))
    P = np.random.default_rng(1).uniform(-0.2, 0.2, size=(30, 3))
    uv, z = v.project_points(P, cam)
    np.testing.assert_allclose(v.backproject_pixels(uv, z, cam), P, atol=1e-9)


def test_principal_point_is_on_the_optical_axis():
    cam = top_down_camera(1.0)
    uv, z = v.project_points([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]], cam)
    cx, cy = cam["K"][0, 2], cam["K"][1, 2]
    np.testing.assert_allclose(uv[0], [cx, cy])
    assert uv[1, 0] > cx and uv[2, 1] < cy  # +x is image right, +y is image up from above
    np.testing.assert_allclose(z, 1.0)


def test_points_behind_the_camera_project_to_nan():
    uv, z = v.project_points([[0.0, 0.0, 2.0]], top_down_camera(1.0))
    assert np.isnan(uv).all() and z[0] < 0


def test_depth_to_points_lies_on_the_plane_and_respects_mask_and_stride():
    cam = look_at_camera((0.4, -0.5, 0.6), (0.0, 0.0, 0.0))
    depth = plane_depth(cam)
    pts, pix = v.depth_to_points(depth, cam, return_pixels=True)
    assert len(pts) == np.count_nonzero(depth > 0)
    np.testing.assert_allclose(pts[:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(depth[pix[:, 1], pix[:, 0]], v.project_points(pts, cam)[1])
    mask = np.zeros_like(depth, dtype=bool)
    mask[10:20, 30:35] = True
    assert len(v.depth_to_points(depth, cam, mask)) == 50
    assert len(v.depth_to_points(depth, cam, stride=4)) == len(depth[::4, ::4].ravel())
    cam_pts = v.depth_to_points(depth, cam, frame="camera")
    np.testing.assert_allclose(cam_pts[:, 2], depth[depth > 0])


def test_depth_to_points_checks_shapes():
    cam = top_down_camera(1.0)
    with pytest.raises(ToolboxError, match="camera is 240x320"):
        v.depth_to_points(np.ones((10, 10)), cam)
    with pytest.raises(ToolboxError, match="missing K"):
        v.depth_to_points(
            np.ones((240, 320)), {"width": 320, "height": 240, "T_world_camera": np.eye(4)}
        )


def test_plane_fit_and_table_estimation_with_clutter():
    cam = look_at_camera((0.5, -0.4, 0.7), (0.0, 0.0, 0.0))
    depth = plane_depth(cam, (0.0, 0.0, 1.0, -0.01))  # table top at z = 1 cm
    depth[100:140, 150:200] *= 0.9  # an object in front of the table
    plane, inliers = v.estimate_table_plane(depth, cam)
    np.testing.assert_allclose(plane, [0.0, 0.0, 1.0, -0.01], atol=1e-6)
    assert not inliers[120, 170] and inliers[10, 10]
    pts = v.depth_to_points(depth, cam)
    above = v.remove_plane(pts, plane, threshold=0.004)
    assert 0 < len(above) <= 40 * 50
    np.testing.assert_allclose(v.distance_to_plane([[0, 0, 0.11]], plane), [0.1])


def test_fit_plane_ransac_is_seeded_and_handles_degenerate_input():
    rng = np.random.default_rng(3)
    pts = np.c_[rng.uniform(-1, 1, (500, 2)), 0.002 * rng.normal(size=500)]
    pts = np.vstack([pts, rng.uniform(-1, 1, (200, 3))])
    a, b = v.fit_plane_ransac(pts, seed=7), v.fit_plane_ransac(pts, seed=7)
    np.testing.assert_array_equal(a[0], b[0])
    assert abs(a[0][2]) > 0.999
    assert v.fit_plane_ransac(pts[:2]) is None
    assert v.fit_plane_ransac(np.zeros((10, 3))) is None  # all points coincide
    # a vertical wall is rejected when only near-horizontal planes are allowed
    wall = np.c_[np.zeros(300), rng.uniform(-1, 1, (300, 2))]
    assert v.fit_plane_ransac(wall, normal_hint=(0, 0, 1), max_angle=0.3) is None


def test_pixels_to_plane_hits_the_table():
    cam = look_at_camera((0.3, 0.3, 0.5), (0.0, 0.0, 0.0))
    P = np.array([[0.01, 0.02, 0.0], [-0.05, 0.04, 0.0]])
    uv, _ = v.project_points(P, cam)
    np.testing.assert_allclose(v.pixels_to_plane(uv, cam), P, atol=1e-9)
    horizon = v.pixels_to_plane([[160, -5000]], cam)  # far above the horizon: no hit
    assert np.isnan(horizon).all()


def test_voxel_downsample_and_clustering():
    rng = np.random.default_rng(0)
    a = rng.normal([0, 0, 0], 0.005, (200, 3))
    b = rng.normal([0.2, 0, 0], 0.005, (100, 3))
    labels = v.cluster_points(np.vstack([a, b]), eps=0.02, min_points=5)
    assert (labels[:200] == 0).all() and (labels[200:] == 1).all()
    down = v.voxel_downsample(np.vstack([a, b]), 0.05)
    assert 2 <= len(down) <= 20
    assert v.voxel_downsample(np.zeros((0, 3)), 0.1).shape == (0, 3)
    assert v.cluster_points(np.zeros((0, 3))).shape == (0,)


@settings(max_examples=20, deadline=None, derandomize=True)
@given(
    st.floats(-0.004, 0.004),
    st.floats(-0.004, 0.004),
    st.floats(-0.004, 0.004),
    st.floats(-0.006, 0.006),
)
def test_level_camera_on_table_undoes_a_tilt_and_a_height_error(tilt_x, tilt_y, yaw, dz):
    from contracts import se3

    true = look_at_camera((0.9, -0.3, 0.6), (0.45, 0.0, 0.0), width=240, height=180, f=220.0)
    depth = plane_depth(true)
    depth[60:100, 90:150] *= 0.95  # an object standing on the table
    # the calibrated camera: turned about its centre (tilt and yaw) and raised by dz
    wrong = dict(true, T_world_camera=np.array(true["T_world_camera"], float))
    R = se3.rotvec_to_matrix([tilt_x, tilt_y, yaw])
    wrong["T_world_camera"][:3, :3] = R @ wrong["T_world_camera"][:3, :3]
    wrong["T_world_camera"][2, 3] += dz
    fixed = v.level_camera_on_table(depth, wrong)
    T, F = np.asarray(true["T_world_camera"]), np.asarray(fixed["T_world_camera"])
    # the table seen through the corrected camera is z = 0 again, and a table point moves
    # no more than the yaw error (which the table cannot show) accounts for
    pts = v.depth_to_points(depth, fixed)
    table = np.abs(pts[:, 2]) < 0.01
    assert np.abs(np.median(pts[table, 2])) < 2e-4
    p_true = v.depth_to_points(depth, true)
    err = np.linalg.norm(pts - p_true, axis=1)
    reach = np.linalg.norm(p_true[:, :2] - T[:2, 3], axis=1)
    assert np.all(err < abs(yaw) * reach * 1.2 + 1e-3)
    assert fixed["K"] is true["K"] or np.allclose(fixed["K"], true["K"])
    assert not np.allclose(F, np.asarray(wrong["T_world_camera"])) or (
        max(abs(tilt_x), abs(tilt_y), abs(dz)) < 1e-6
    )


def test_level_camera_on_table_leaves_a_camera_without_a_table_alone():
    cam = look_at_camera((0.9, -0.3, 0.6), (0.45, 0.0, 0.0), width=120, height=90, f=110.0)
    wall = plane_depth(cam, (1.0, 0.0, 0.0, -0.3))  # a wall at x = 0.3, no table in view
    out = v.level_camera_on_table(wall, cam)
    np.testing.assert_array_equal(out["T_world_camera"], cam["T_world_camera"])
