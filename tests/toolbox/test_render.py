"""Offscreen renderer: analytic silhouettes and depths, occlusion, caching, speed."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.toolbox.conftest import look_at_camera, top_down_camera
from toolbox.errors import ToolboxError
from toolbox.geometry import make_pose, pose_from_xyz_yaw, rotation_about_axis, transform_points
from toolbox.render import compare_renders, overlay_mask, render_scene
from toolbox.vision import depth_to_points

HALF = 0.025  # half side of the test cube [m]


def cube_record(T, id="cube"):
    return {"id": id, "mesh": "cube", "pose": T}


def test_cube_from_above_matches_the_analytic_silhouette_and_depth(cube):
    cam = top_down_camera(1.0, width=320, height=240, f=400.0)
    cam["K"][0, 2], cam["K"][1, 2] = 160.3, 119.8  # off-grid, so no pixel centre sits on an edge
    out = render_scene([cube_record(pose_from_xyz_yaw(0, 0, HALF, 0))], {"cube": cube}, cam)
    assert out["rgb"].shape == (240, 320, 3) and out["rgb"].dtype == np.uint8
    assert out["depth"].dtype == np.float32 and out["mask"].dtype == np.int32
    # Only the top face (z = 0.05, 0.95 m away) is visible from straight above.
    r = 400.0 * HALF / 0.95
    u, v = np.meshgrid(np.arange(320), np.arange(240))
    expected = (np.abs(u - 160.3) < r) & (np.abs(v - 119.8) < r)
    np.testing.assert_array_equal(out["mask"] == 0, expected)
    assert (out["mask"][~expected] == -1).all()
    np.testing.assert_allclose(out["depth"][expected], 0.95, atol=2e-5)
    assert (out["depth"][~expected] == 0).all()


@settings(max_examples=8, deadline=None, derandomize=True)
@given(
    st.tuples(st.floats(-0.1, 0.1), st.floats(-0.1, 0.1), st.floats(0.0, 0.1)),
    st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(0.1, 1)),
    st.floats(0, 2 * np.pi),
)
def test_depth_backprojects_onto_the_mesh_surface(t, axis, angle):
    cube = trimesh.creation.box((2 * HALF,) * 3)
    cam = look_at_camera((0.35, -0.3, 0.45), (0.0, 0.0, 0.05))
    T = make_pose(rotation_about_axis(axis, angle), t)
    out = render_scene([cube_record(T)], {"cube": cube}, cam)
    pts = depth_to_points(out["depth"], cam, out["mask"] == 0)
    assert len(pts) > 100
    local = transform_points(np.linalg.inv(T), pts)
    # every rendered point lies on the cube's surface: max |coordinate| equals the half side
    np.testing.assert_allclose(np.abs(local).max(axis=1), HALF, atol=2e-4)


def test_nearer_object_owns_the_pixel_whatever_the_record_order(cube):
    cam = top_down_camera(1.0)
    low, high = pose_from_xyz_yaw(0, 0, HALF, 0), pose_from_xyz_yaw(0.02, 0, 3 * HALF, 0.3)
    meshes = {"cube": cube}
    a = render_scene([cube_record(low, "a"), cube_record(high, "b")], meshes, cam)
    b = render_scene([cube_record(high, "b"), cube_record(low, "a")], meshes, cam)
    assert a["mask"][120, 160] == 1 and b["mask"][120, 160] == 0
    np.testing.assert_array_equal(np.where(a["mask"] >= 0, 1 - a["mask"], -1), b["mask"])
    np.testing.assert_allclose(a["depth"], b["depth"])
    assert set(np.unique(a["mask"])) == {-1, 0, 1}


def test_colours_and_background(cube):
    cam = top_down_camera(1.0)
    recs = [cube_record(pose_from_xyz_yaw(0, 0, HALF, 0))]
    out = render_scene(recs, {"cube": cube}, cam, colors=[(255, 0, 0)], background=(10, 20, 30))
    np.testing.assert_array_equal(out["rgb"][0, 0], [10, 20, 30])
    r, g, b = out["rgb"][120, 160].astype(int)
    assert r > 100 and g < r / 2 and b < r / 2
    by_id = render_scene(recs, {"cube": cube}, cam, colors={"cube": (0, 0, 255)})
    assert by_id["rgb"][120, 160, 2] > 100 and by_id["rgb"][120, 160, 0] < 60


def test_empty_scene_and_bad_input(cube):
    cam = top_down_camera(1.0)
    out = render_scene([], {}, cam)
    assert (out["mask"] == -1).all() and (out["depth"] == 0).all()
    with pytest.raises(ToolboxError, match="known: cube"):
        render_scene([{"id": "x", "mesh": "sphere", "pose": np.eye(4)}], {"cube": cube}, cam)
    with pytest.raises(ToolboxError, match=r"records\[0\]\.pose"):
        render_scene([{"id": "x", "mesh": "cube", "pose": np.eye(3)}], {"cube": cube}, cam)
    with pytest.raises(ToolboxError, match=r"0\.\.255"):
        render_scene([cube_record(np.eye(4))], {"cube": cube}, cam, colors=[(300, 0, 0)])
    with pytest.raises(ToolboxError, match="znear"):
        render_scene([], {}, cam, znear=1.0, zfar=0.5)


def test_mesh_edited_in_place_is_rendered_anew():
    mesh = trimesh.creation.box((0.05, 0.05, 0.05))
    cam = top_down_camera(1.0)
    recs = [cube_record(pose_from_xyz_yaw(0, 0, HALF, 0))]
    before = np.count_nonzero(render_scene(recs, {"cube": mesh}, cam)["mask"] == 0)
    mesh.apply_scale(2.0)
    after = np.count_nonzero(render_scene(recs, {"cube": mesh}, cam)["mask"] == 0)
    assert after > 3 * before


def test_renders_from_other_threads_and_sizes(cube):
    recs = [cube_record(pose_from_xyz_yaw(0.01, 0.02, HALF, 0.4))]
    cam = top_down_camera(1.0)
    ref = render_scene(recs, {"cube": cube}, cam)
    with ThreadPoolExecutor(2) as pool:
        outs = list(pool.map(lambda _: render_scene(recs, {"cube": cube}, cam), range(3)))
    for o in outs:
        np.testing.assert_array_equal(o["mask"], ref["mask"])
    small = render_scene(recs, {"cube": cube}, top_down_camera(1.0, width=160, height=120, f=150.0))
    assert small["mask"].shape == (120, 160)
    np.testing.assert_array_equal(render_scene(recs, {"cube": cube}, cam)["mask"], ref["mask"])


def test_compare_renders(cube):
    cam = top_down_camera(1.0)
    a = render_scene([cube_record(pose_from_xyz_yaw(0, 0, HALF, 0))], {"cube": cube}, cam)
    same = compare_renders(a, a)
    assert same == [
        {
            "index": 0,
            "iou": 1.0,
            "area_rendered": same[0]["area_rendered"],
            "area_reference": same[0]["area_rendered"],
            "depth_error_median": 0.0,
            "depth_error_mean": 0.0,
        }
    ]
    b = render_scene(
        [cube_record(pose_from_xyz_yaw(0.01, 0, HALF + 0.002, 0))], {"cube": cube}, cam
    )
    diff = compare_renders(a, b, n_objects=2)
    assert 0.3 < diff[0]["iou"] < 0.9
    assert diff[0]["depth_error_median"] == pytest.approx(0.002, abs=1e-4)
    assert diff[1]["iou"] == 1.0 and np.isnan(diff[1]["depth_error_mean"])
    img = overlay_mask(a["rgb"], a["mask"])
    assert img.shape == a["rgb"].shape and img.dtype == np.uint8


def test_rendering_1280x720_labels_every_object(cube):
    cam = look_at_camera((0.6, -0.6, 0.7), (0.0, 0.0, 0.0), width=1280, height=720, f=900.0)
    recs = [
        cube_record(pose_from_xyz_yaw(0.07 * (i % 4), 0.07 * (i // 4), HALF, 0.1 * i), str(i))
        for i in range(10)
    ]
    first = render_scene(recs, {"cube": cube}, cam)  # context creation and upload
    out = render_scene(recs, {"cube": cube}, cam)  # the cached context renders the same
    assert set(np.unique(out["mask"])) == {-1, *range(10)}
    assert out["rgb"].shape == (720, 1280, 3) and np.array_equal(out["mask"], first["mask"])


def test_every_image_size_draws_with_the_one_context_as_a_fresh_one_would(cube):
    """Drawn cameras come in many sizes: one context re-sized for each, and each size's image
    is what a context made at that size alone draws."""
    from toolbox import render

    recs = [cube_record(pose_from_xyz_yaw(0.01, -0.02, HALF, 0.3))]
    sizes = [(200, 100), (64, 48), (321, 177), (200, 100), (96, 160)]
    drawn = [
        render_scene(recs, {"cube": cube}, top_down_camera(1.0, width=w, height=h, f=w * 0.75))
        for w, h in sizes
    ]
    assert len(render._CONTEXTS) == 1
    for (w, h), got in zip(sizes, drawn, strict=True):
        assert got["mask"].shape == got["depth"].shape == (h, w) and got["rgb"].shape == (h, w, 3)
        ctx = render._Context(w, h)  # a context made for this size alone
        try:
            render._CONTEXTS.insert(0, ctx)
            alone = render_scene(
                recs, {"cube": cube}, top_down_camera(1.0, width=w, height=h, f=w * 0.75)
            )
        finally:
            render._CONTEXTS.remove(ctx)
            ctx.delete()
        np.testing.assert_array_equal(got["mask"], alone["mask"])
        np.testing.assert_array_equal(got["depth"], alone["depth"])
        np.testing.assert_array_equal(got["rgb"], alone["rgb"])
