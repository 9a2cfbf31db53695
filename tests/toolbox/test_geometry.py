"""SE(3) helpers: round trips, axis-angle, symmetry-aware distance."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from toolbox import geometry as g
from toolbox.errors import ToolboxError

PROPS = settings(max_examples=60, deadline=None, derandomize=True)

finite = st.floats(-1.0, 1.0, allow_nan=False)
quaternions = st.tuples(finite, finite, finite, finite).filter(lambda q: np.linalg.norm(q) > 0.1)
translations = st.tuples(*(st.floats(-2.0, 2.0, allow_nan=False),) * 3)


def rotation(q) -> np.ndarray:
    w, x, y, z = np.asarray(q) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@PROPS
@given(quaternions, translations)
def test_invert_then_compose_is_identity(q, t):
    T = g.make_pose(rotation(q), t)
    np.testing.assert_allclose(T @ g.invert_pose(T), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(g.invert_pose(g.invert_pose(T)), T, atol=1e-12)


@PROPS
@given(quaternions, translations)
def test_transform_points_round_trip(q, t):
    T = g.make_pose(rotation(q), t)
    P = np.random.default_rng(0).normal(size=(7, 3))
    back = g.transform_points(g.invert_pose(T), g.transform_points(T, P))
    np.testing.assert_allclose(back, P, atol=1e-12)
    np.testing.assert_allclose(g.transform_points(T, P[0]), g.transform_points(T, P)[0])


@PROPS
@given(quaternions)
def test_axis_angle_round_trip(q):
    R = rotation(q)
    axis, angle = g.axis_angle_from_rotation(R)
    assert 0.0 <= angle <= np.pi
    np.testing.assert_allclose(g.rotation_about_axis(axis, angle), R, atol=1e-7)
    assert g.is_proper_rotation(R)


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 1), (1, 2, 3)])
def test_axis_angle_at_pi(axis):
    R = g.rotation_about_axis(axis, np.pi)
    a, angle = g.axis_angle_from_rotation(R)
    assert angle == pytest.approx(np.pi)
    np.testing.assert_allclose(g.rotation_about_axis(a, angle), R, atol=1e-9)


@PROPS
@given(quaternions, st.floats(1e-3, 0.1))
def test_project_to_rotation_repairs_noise(q, noise):
    R = rotation(q)
    noisy = R + noise * np.random.default_rng(1).normal(size=(3, 3))
    fixed = g.project_to_rotation(noisy)
    assert g.is_proper_rotation(fixed, tol=1e-9)
    assert g.rotation_angle_between(fixed, R) < 4 * noise


def test_reflection_is_not_proper():
    assert not g.is_proper_rotation(np.diag([1.0, 1.0, -1.0]))
    assert g.is_proper_rotation(g.project_to_rotation(np.diag([1.0, 1.0, -1.0])))


@PROPS
@given(st.floats(-3.1, 3.1), translations)
def test_yaw_round_trip(yaw, t):
    T = g.pose_from_xyz_yaw(*t, yaw)
    assert g.yaw_of(T) == pytest.approx(yaw, abs=1e-12)
    np.testing.assert_allclose(T[:3, 3], t)


@PROPS
@given(quaternions, translations, st.integers(0, 23))
def test_pose_distance_is_zero_modulo_symmetry(q, t, k):
    T = g.make_pose(rotation(q), t)
    S = g.cube_symmetries()[k]
    assert g.pose_distance(T, T @ S, g.cube_symmetries()).rotation < 1e-6
    if k:
        assert g.pose_distance(T, T @ S).rotation > 0.5


def test_pose_distance_values():
    A = g.pose_from_xyz_yaw(0.0, 0.0, 0.0, 0.0)
    B = g.pose_from_xyz_yaw(0.3, 0.4, 0.0, np.pi / 2 + 0.1)
    d = g.pose_distance(A, B)
    assert d.translation == pytest.approx(0.5)
    assert d.rotation == pytest.approx(np.pi / 2 + 0.1)
    assert g.pose_distance(A, B, g.cyclic_symmetries(4)).rotation == pytest.approx(0.1)
    # continuous symmetry about z: any yaw is the same pose
    assert g.pose_distance(A, B, continuous_axis=(0, 0, 1)).rotation == pytest.approx(0.0, abs=1e-7)


@PROPS
@given(quaternions, quaternions, translations)
def test_pose_distance_agrees_with_contracts_se3(q1, q2, t):
    se3 = pytest.importorskip("contracts.se3")
    A, B = g.make_pose(rotation(q1)), g.make_pose(rotation(q2), t)
    syms = g.cyclic_symmetries(4)
    expected = se3.pose_error(A, B, syms)
    got = g.pose_distance(A, B, syms)
    assert got.translation == pytest.approx(expected[0], abs=1e-9)
    assert got.rotation == pytest.approx(expected[1], abs=1e-6)


def test_cube_symmetries_are_24_distinct_proper_rotations():
    syms = g.cube_symmetries()
    assert len(syms) == 24
    assert all(g.is_proper_rotation(S[:3, :3]) for S in syms)
    assert len({tuple(np.round(S, 6).ravel()) for S in syms}) == 24


@pytest.mark.parametrize(
    "bad",
    [np.eye(3), [[1, 2], [3, 4]], np.full((4, 4), np.nan), "pose"],
)
def test_as_pose_rejects_bad_input(bad):
    with pytest.raises(ToolboxError):
        g.as_pose(bad)


def test_errors_name_the_problem():
    with pytest.raises(ToolboxError, match="zero length"):
        g.rotation_about_axis((0, 0, 0), 1.0)
    with pytest.raises(ToolboxError, match="3 entries"):
        g.make_pose(None, [1, 2])
    with pytest.raises(ToolboxError, match="empty"):
        g.pose_distance(np.eye(4), np.eye(4), [])


def test_the_toolbox_wraps_contracts_se3_and_holds_no_maths_of_its_own():
    # one SE(3) implementation: the programs' names call contracts.se3 (so do the domains'
    # symmetry groups); none of them computes a rotation itself
    import ast
    import inspect

    from domains import symmetry

    for module in (g, symmetry):
        calls = {
            node.func.attr
            for node in ast.walk(ast.parse(inspect.getsource(module)))
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
        }
        assert not calls & {"sin", "cos", "arctan2", "arccos", "svd", "det"}, module.__name__
    T = g.make_pose(rotation((0.3, 0.1, -0.5, 0.7)), (0.1, 0.2, 0.3))
    se3 = pytest.importorskip("contracts.se3")
    assert tuple(g.pose_distance(T, np.eye(4), g.cube_symmetries())) == se3.pose_error(
        T, np.eye(4), se3.cube_group()
    )
