"""2D fitting: tangram-like pieces rendered from above are located to sub-degree accuracy."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.toolbox.conftest import prism, top_down_camera
from toolbox.errors import ToolboxError
from toolbox.geometry import pose_from_xyz_yaw
from toolbox.polygons import approximate_polygon, fit_polygon_pose, fit_rectangle, polygon_symmetry
from toolbox.render import render_scene
from toolbox.segmentation import mask_contour
from toolbox.vision import pixels_to_plane

S = 0.05  # tangram unit [m]
THICK = 0.01
PIECES = {
    "large_triangle": np.array([[0, 0], [2 * S, 0], [0, 2 * S]]) - [2 * S / 3, 2 * S / 3],
    "square": np.array([[0, 0], [S, 0], [S, S], [0, S]]) - [S / 2, S / 2],
    "parallelogram": np.array([[0, 0], [S, 0], [2 * S, S], [S, S]]) - [S, S / 2],
}


def observe(name, x, y, yaw, mirrored=False):
    """Outline (N, 2) [m] on the piece's top plane, from a rendered top-down view."""
    V = PIECES[name] * [1, -1] if mirrored else PIECES[name]
    if mirrored:
        V = V[::-1]  # keep counter-clockwise order for the prism builder
    cam = top_down_camera(0.7, width=640, height=480, f=800.0)
    out = render_scene(
        [{"id": name, "mesh": name, "pose": pose_from_xyz_yaw(x, y, 0, yaw)}],
        {name: prism(V, THICK)},
        cam,
    )
    contour = mask_contour(out["mask"] == 0)
    return pixels_to_plane(contour, cam, (0, 0, 1, -THICK))[:, :2]


def angle_error(a, b, n):
    period = 2 * np.pi / n
    return abs((a - b + period / 2) % period - period / 2)


@settings(max_examples=6, deadline=None, derandomize=True)
@given(
    st.sampled_from(sorted(PIECES)),
    st.floats(-0.08, 0.08),
    st.floats(-0.06, 0.06),
    st.floats(0, 2 * np.pi),
)
def test_fit_recovers_the_pose_of_a_rendered_piece(name, x, y, yaw):
    fit = fit_polygon_pose(PIECES[name], observe(name, x, y, yaw))
    n = polygon_symmetry(PIECES[name])
    assert np.hypot(fit.x - x, fit.y - y) < 1e-3
    assert np.degrees(angle_error(fit.angle, yaw, n)) < 0.5
    assert 0 <= fit.angle < 2 * np.pi / n
    assert fit.iou > 0.95 and not fit.mirrored


def test_fit_detects_a_flipped_parallelogram():
    outline = observe("parallelogram", 0.02, -0.01, 0.7, mirrored=True)
    fit = fit_polygon_pose(PIECES["parallelogram"], outline, allow_mirror=True)
    assert fit.mirrored and fit.iou > 0.95
    assert np.degrees(angle_error(fit.angle, 0.7, 2)) < 0.5
    plain = fit_polygon_pose(PIECES["parallelogram"], outline)
    assert plain.iou < 0.9  # without mirroring the piece cannot be matched


def test_wrong_piece_has_low_iou():
    fit = fit_polygon_pose(PIECES["square"], observe("large_triangle", 0, 0, 0.3))
    assert fit.iou < 0.8


@pytest.mark.parametrize(
    ("vertices", "order"),
    [
        (PIECES["square"], 4),
        (PIECES["large_triangle"], 1),
        (PIECES["parallelogram"], 2),
        ([[0, 0], [2, 0], [2, 1], [0, 1]], 2),
        ([[np.cos(a), np.sin(a)] for a in np.arange(6) * np.pi / 3], 6),
        ([[np.cos(a), np.sin(a)] for a in np.arange(3) * 2 * np.pi / 3], 3),
    ],
)
def test_polygon_symmetry(vertices, order):
    assert polygon_symmetry(np.asarray(vertices, float)) == order


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.floats(0, np.pi - 1e-3), st.floats(0.5, 3), st.floats(0.1, 0.45))
def test_fit_rectangle_recovers_size_and_angle(angle, length, ratio):
    c, s = np.cos(angle), np.sin(angle)
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [length / 2, length * ratio / 2]
    pts = corners @ np.array([[c, -s], [s, c]]).T + [3.0, -2.0]
    r = fit_rectangle(pts)
    np.testing.assert_allclose(r.center, (3.0, -2.0), atol=1e-4)
    np.testing.assert_allclose(r.size, (length, length * ratio), rtol=1e-4)
    assert angle_error(r.angle, angle, 2) < 1e-4


def test_fit_rectangle_on_a_mask_and_bad_input():
    mask = np.zeros((50, 60), bool)
    mask[10:20, 5:45] = True
    r = fit_rectangle(mask)
    np.testing.assert_allclose(r.center, (24.5, 14.5))
    assert r.angle == pytest.approx(0.0) or r.angle == pytest.approx(np.pi)
    with pytest.raises(ToolboxError, match="at least 3"):
        fit_rectangle(np.zeros((2, 2)))
    with pytest.raises(ToolboxError, match="template"):
        fit_polygon_pose(np.zeros((3, 3)), np.zeros((10, 2)))


def test_approximate_polygon_finds_the_corners():
    mask = np.zeros((100, 100), bool)
    mask[20:60, 30:90] = True
    assert len(approximate_polygon(mask_contour(mask), 1.5)) == 4
