"""SE(3) helpers: group axioms, round trips and symmetry-aware errors (pinned seeds)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contracts import se3
from tests.contracts.strategies import poses, rotations

PROPS = settings(max_examples=300, deadline=None, derandomize=True)


@PROPS
@given(poses(), poses(), poses())
def test_composition_is_associative_and_closed(a, b, c):
    left = se3.compose(se3.compose(a, b), c)
    right = se3.compose(a, se3.compose(b, c))
    np.testing.assert_allclose(left, right, atol=1e-9)
    assert se3.is_rigid(left)


@PROPS
@given(poses())
def test_identity_and_inverse(T):
    np.testing.assert_allclose(se3.compose(T, se3.identity()), T, atol=1e-12)
    np.testing.assert_allclose(se3.compose(T, se3.inverse(T)), np.eye(4), atol=1e-9)
    np.testing.assert_allclose(se3.compose(se3.inverse(T), T), np.eye(4), atol=1e-9)
    np.testing.assert_allclose(se3.inverse(se3.inverse(T)), T, atol=1e-9)


@PROPS
@given(poses(), poses())
def test_inverse_of_product_reverses_order(a, b):
    np.testing.assert_allclose(
        se3.inverse(se3.compose(a, b)), se3.compose(se3.inverse(b), se3.inverse(a)), atol=1e-9
    )


@PROPS
@given(rotations())
def test_generated_rotations_are_proper_and_reflections_are_not(R):
    assert se3.is_proper_rotation(R)
    assert not se3.is_proper_rotation(R @ np.diag([1.0, 1.0, -1.0]))
    assert not se3.is_proper_rotation(2.0 * R)


@PROPS
@given(st.floats(-np.pi + 1e-6, np.pi - 1e-6))
def test_rot_z_yaw_round_trip(angle):
    assert se3.yaw(se3.rot_z(angle)) == pytest.approx(angle, abs=1e-9)
    assert se3.rotation_angle(se3.rot_z(angle)[:3, :3]) == pytest.approx(abs(angle), abs=1e-6)


@PROPS
@given(st.lists(st.floats(-3, 3), min_size=3, max_size=3))
def test_rotvec_matches_angle(w):
    R = se3.rotvec_to_matrix(w)
    assert se3.is_proper_rotation(R)
    assert se3.rotation_angle(R) == pytest.approx(
        min(np.linalg.norm(w), 2 * np.pi - np.linalg.norm(w)), abs=1e-6
    )


def test_cube_group_has_24_distinct_proper_rotations():
    group = se3.cube_group()
    assert len(group) == 24
    assert len({tuple(np.round(g, 6).ravel()) for g in group}) == 24
    assert all(se3.is_rigid(g) for g in group)


@PROPS
@given(poses(), st.integers(1, 8), st.integers(0, 7))
def test_error_is_zero_modulo_symmetry(T, n, k):
    group = se3.cyclic_group(n)
    S = group[k % n]
    assert se3.pose_error(T, T @ S, group) == pytest.approx((0.0, 0.0), abs=1e-6)
    assert se3.within_tolerance(T, T @ S, trans_tol=1e-6, rot_tol=1e-6, symmetries=group)
    verts = np.random.default_rng(0).uniform(-0.05, 0.05, (30, 3))
    assert se3.mssd(T, T @ S, verts, group) == pytest.approx(0.0, abs=1e-9)


@PROPS
@given(poses(), st.floats(0.001, 0.5), st.floats(0.01, 3.0))
def test_error_measures_a_known_offset(T, d, angle):
    offset = se3.make(se3.rot_z(angle)[:3, :3], [d, 0.0, 0.0])
    moved = se3.compose(offset, T)  # world-frame rotation about T's position's parallel axis
    t_err, r_err = se3.pose_error(T, moved)
    assert r_err == pytest.approx(angle, abs=1e-6)
    assert t_err == pytest.approx(
        np.linalg.norm(offset[:3, :3] @ T[:3, 3] + offset[:3, 3] - T[:3, 3]), abs=1e-9
    )
    assert not se3.within_tolerance(
        T, moved, trans_tol=t_err / 2 if t_err > 0 else -1, rot_tol=None
    )


@PROPS
@given(rotations(), st.floats(1e-9, 1e-3))
def test_rotation_angle_is_precise_near_zero_and_pi(R, eps):
    axis = np.array([0.3, -0.5, 0.8])
    for angle in (eps, np.pi - eps):
        turn = R @ se3.rotation_about(axis, angle) @ R.T  # the same angle about R's axis
        assert se3.rotation_angle(turn) == pytest.approx(angle, rel=1e-6, abs=1e-12)
        assert se3.angle_between(R, turn @ R) == pytest.approx(angle, rel=1e-6, abs=1e-12)


@PROPS
@given(rotations())
def test_axis_angle_rebuilds_the_rotation(R):
    axis, angle = se3.axis_angle(R)
    np.testing.assert_allclose(se3.rotation_about(axis, angle), R, atol=1e-7)
    np.testing.assert_allclose(se3.rotvec_to_matrix(axis * angle), R, atol=1e-7)


def test_cyclic_group_about_any_axis():
    group = se3.cyclic_group(3, (1.0, 1.0, 0.0))
    assert len(group) == 3 and np.allclose(group[0], np.eye(4))
    np.testing.assert_allclose(group[1] @ group[2], np.eye(4), atol=1e-12)
    with pytest.raises(ValueError, match=">= 1"):
        se3.cyclic_group(0)
    with pytest.raises(ValueError, match="zero length"):
        se3.rotation_about((0, 0, 0), 1.0)
