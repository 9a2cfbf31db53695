"""Packing on a table: footprints, signed gaps, spreading a tight figure, finger room."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, seed, settings
from hypothesis import strategies as st

from toolbox.errors import ToolboxError
from toolbox.geometry import pose_from_xyz_yaw
from toolbox.packing import finger_footprints, footprint, polygon_gap, spread_footprints

SQUARE = np.array([[0.0, 0.0], [0.04, 0.0], [0.04, 0.04], [0.0, 0.04]]) - 0.02
TRIANGLE = np.array([[-0.04, -0.0133], [0.04, -0.0133], [0.0, 0.0267]])


def moved(p, dx=0.0, dy=0.0, yaw=0.0):
    c, s = np.cos(yaw), np.sin(yaw)
    return p @ np.array([[c, s], [-s, c]]) + [dx, dy]


def test_footprint_of_a_posed_box_and_of_a_height_band():
    mesh = trimesh.creation.box(extents=(0.08, 0.04, 0.015))
    mesh.apply_translation((0, 0, 0.0075))
    knob = trimesh.creation.box(extents=(0.016, 0.016, 0.02))
    knob.apply_translation((0, 0, 0.025))
    part = trimesh.util.concatenate([mesh, knob])
    fp = footprint(part, pose_from_xyz_yaw(0.5, 0.1, 0.0, np.pi / 2))
    assert np.allclose(np.sort(fp[:, 0]), [0.48, 0.48, 0.52, 0.52], atol=1e-9)
    assert np.allclose(np.sort(fp[:, 1]), [0.06, 0.06, 0.14, 0.14], atol=1e-9)
    area = 0.5 * np.sum(fp[:, 0] * np.roll(fp[:, 1], -1) - np.roll(fp[:, 0], -1) * fp[:, 1])
    assert area == pytest.approx(0.08 * 0.04)  # counter-clockwise: positive area
    top = footprint(part, pose_from_xyz_yaw(0.5, 0.1, 0.0, 0.0), z_range=(0.016, 1.0))
    assert np.allclose(np.ptp(top, axis=0), [0.016, 0.016])
    with pytest.raises(ToolboxError):
        footprint(part, np.eye(3))


def test_gap_is_signed_and_its_axis_points_from_b_to_a():
    g, axis = polygon_gap(moved(SQUARE, 0.045), SQUARE)
    assert g == pytest.approx(0.005)
    assert np.allclose(axis, [1.0, 0.0])
    g, axis = polygon_gap(moved(SQUARE, 0.037), SQUARE)
    assert g == pytest.approx(-0.003)
    assert np.allclose(axis, [1.0, 0.0])
    with pytest.raises(ToolboxError):
        polygon_gap(SQUARE[:2], SQUARE)


@seed(3)
@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    st.floats(-0.1, 0.1),
    st.floats(-0.1, 0.1),
    st.floats(-np.pi, np.pi),
)
def test_gap_is_symmetric_and_moving_along_the_axis_adds_to_it(dx, dy, yaw):
    a, b = moved(TRIANGLE, dx, dy, yaw), SQUARE
    g, axis = polygon_gap(a, b)
    g2, axis2 = polygon_gap(b, a)
    assert g == pytest.approx(g2, abs=1e-12)
    assert np.allclose(axis, -axis2)
    g3, _ = polygon_gap(a + 0.002 * axis, b)
    assert g3 >= g + 0.002 - 1e-9  # the true gap grows at least as much along the axis


def test_spread_opens_a_packed_row_and_respects_the_limits():
    row = [moved(SQUARE, 0.0405 * k) for k in range(4)]  # 0.5 mm apart
    t = spread_footprints(row, gap=0.002, max_shift=0.003)
    out = [p + d for p, d in zip(row, t, strict=True)]
    gaps = [polygon_gap(out[k + 1], out[k])[0] for k in range(3)]
    assert min(gaps) >= 0.002 - 1e-6
    assert np.linalg.norm(t, axis=1).max() <= 0.003 + 1e-9
    assert np.allclose(t[:, 1], 0.0, atol=1e-9)  # nothing moves sideways for nothing


def test_spread_resolves_overlap_around_fixed_parts():
    a, b = SQUARE, moved(SQUARE, 0.039)  # overlapping by 1 mm
    t = spread_footprints([a, b], gap=0.001, max_shift=0.003, fixed=[0])
    assert np.allclose(t[0], 0.0)
    assert polygon_gap(b + t[1], a)[0] >= 0.001 - 1e-6


def test_spread_does_its_best_when_the_gap_cannot_be_reached():
    a, b, c = SQUARE, moved(SQUARE, 0.0405), moved(SQUARE, 0.081)
    t = spread_footprints([a, b, c], gap=0.005, max_shift=0.001, fixed=[0, 2])
    assert np.allclose(t[[0, 2]], 0.0)
    assert abs(t[1, 0]) < 1e-6  # centred: both gaps equal, as large as they can be


def test_far_apart_parts_are_left_alone():
    t = spread_footprints([SQUARE, moved(SQUARE, 0.2)], gap=0.002)
    assert np.allclose(t, 0.0)


def test_finger_footprints_of_a_2f85_on_a_knob():
    left, right = finger_footprints((0.5, 0.0), (0.0, 1.0), 0.024, margin=0.0)
    assert np.allclose(np.sort(np.unique(np.round(left[:, 1], 6))), [0.012, 0.029])
    assert np.allclose(np.sort(np.unique(np.round(right[:, 1], 6))), [-0.029, -0.012])
    assert np.allclose(np.ptp(left[:, 0]), 0.024)
    knob_near = moved(np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * 0.008, 0.5, 0.03)
    knob_far = moved(knob_near, 0.0, 0.02)
    assert polygon_gap(left, knob_near)[0] < 0
    assert polygon_gap(left, knob_far)[0] > 0
    assert (
        min(polygon_gap(f, knob_near)[0] for f in finger_footprints((0.5, 0.0), (1, 0), 0.024)) > 0
    )
    with pytest.raises(ToolboxError):
        finger_footprints((0, 0), (0, 0), 0.02)


def test_one_tight_pair_does_not_hold_back_the_others():
    # b is wedged between the fixed a and c (0.2 mm each side); d, touching c on its other
    # side, still gets its full gap
    a, b, c, d = (moved(SQUARE, 0.0402 * k) for k in range(4))
    t = spread_footprints([a, b, c, d], gap=0.002, max_shift=0.003, fixed=[0, 2])
    assert polygon_gap(b + t[1], a)[0] == pytest.approx(0.0002, abs=1e-6)
    assert polygon_gap(d + t[3], c)[0] >= 0.002 - 1e-6
