"""SE(3) for generated programs: poses, rotations, symmetry-aware pose distance.

Design rule: plain numpy, no state. A pose is a 4×4 homogeneous float matrix `T_a_b` that maps
a point expressed in frame b into frame a (`p_a = T_a_b @ [p_b, 1]`); records store
`T_world_object`. Metres and radians. A symmetry of an object is an object-frame transform `S`
such that the object looks identical at poses `T` and `T @ S`.

These are the programs' names for `contracts.se3`, the one SE(3) implementation that the
checks, the simulator and the domains use too: each function here checks its arguments
(raising `ToolboxError` naming the problem) and calls it. The maths is shared on purpose: a
pose convention the programs and their judges disagreed on would fail every draft for a
reason no feedback could name. The geometry that decides the verdicts is shared too:
`toolbox.stability` (collision, support, stability) and `toolbox.robot` (the hand) are the
judges' own functions, re-exported.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from contracts import se3
from toolbox.errors import ToolboxError

__all__ = [
    "PoseDistance",
    "as_pose",
    "axis_angle_from_rotation",
    "cube_symmetries",
    "cyclic_symmetries",
    "invert_pose",
    "is_proper_rotation",
    "make_pose",
    "pose_distance",
    "pose_from_xyz_yaw",
    "project_to_rotation",
    "rotation_about_axis",
    "rotation_angle_between",
    "transform_points",
    "yaw_of",
]


class PoseDistance(NamedTuple):
    """Distance between two poses: `translation` [m] and `rotation` [rad, in [0, π]]."""

    translation: float
    rotation: float


def _matrix(value: object, shape: tuple[int, ...], what: str) -> np.ndarray:
    """`value` as a finite float array of `shape`, or ToolboxError naming `what`."""
    try:
        M = np.array(value, dtype=float)
    except (TypeError, ValueError) as e:
        raise ToolboxError(f"{what} is not numeric: {e}") from None
    if M.shape != shape:
        raise ToolboxError(f"{what} must have shape {shape}, got {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ToolboxError(f"{what} contains NaN or inf")
    return M


def _rotation_part(value: object, what: str) -> np.ndarray:
    """The rotation (3, 3) of a rotation (3, 3) or a pose (4, 4)."""
    try:
        M = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as e:
        raise ToolboxError(f"{what} is not numeric: {e}") from None
    if M.shape not in ((3, 3), (4, 4)):
        raise ToolboxError(f"{what} must have shape (3, 3) or (4, 4), got {M.shape}")
    return M[:3, :3]


def _axis(axis: object) -> np.ndarray:
    """A rotation axis as a float (3,) array."""
    a = np.asarray(axis, dtype=float).reshape(-1)
    if a.shape != (3,):
        raise ToolboxError(f"rotation axis must have 3 entries, got {a.shape[0]}")
    return a


def as_pose(T: object) -> np.ndarray:
    """Convert a pose (4×4 nested lists or array) into a float (4, 4) numpy copy.

    Raises:
        ToolboxError: the shape is not (4, 4) or an entry is not finite.
    """
    return _matrix(T, (4, 4), "pose")


def make_pose(rotation: object = None, translation: object = None) -> np.ndarray:
    """Build a 4×4 pose from a rotation (3, 3) and a translation (3,) [m].

    Either argument may be None (identity rotation / zero translation).
    """
    R = None
    if rotation is not None:
        R = np.asarray(rotation, dtype=float)
        if R.shape != (3, 3):
            raise ToolboxError(f"rotation must have shape (3, 3), got {R.shape}")
    t = None
    if translation is not None:
        t = np.asarray(translation, dtype=float).reshape(-1)
        if t.shape != (3,):
            raise ToolboxError(f"translation must have 3 entries, got {t.shape[0]}")
    return se3.make(R, t)


def pose_from_xyz_yaw(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """Pose at position (x, y, z) [m], rotated by `yaw` [rad] about the world z axis.

    The object's z axis stays vertical: this is how flat-lying objects on the table are placed.
    """
    return make_pose(se3.rot_z(yaw)[:3, :3], [x, y, z])


def invert_pose(T: object) -> np.ndarray:
    """Inverse of a rigid transform: `T_b_a` from `T_a_b` (uses Rᵀ, exact for rotations)."""
    return se3.inverse(as_pose(T))


def transform_points(T: object, points: object) -> np.ndarray:
    """Apply pose `T_a_b` to points (N, 3) given in frame b; returns (N, 3) in frame a.

    A single point (3,) returns a single point (3,).
    """
    M = as_pose(T)
    P = np.asarray(points, dtype=float)
    if P.shape[-1:] != (3,) or P.ndim > 2:
        raise ToolboxError(f"points must have shape (N, 3) or (3,), got {P.shape}")
    return se3.transform_points(M, P)


def rotation_about_axis(axis: object, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) turning by `angle` [rad] about `axis` (3,), right-hand rule.

    The axis need not be unit length. Raises ToolboxError for a zero axis.
    """
    try:
        return se3.rotation_about(_axis(axis), angle)
    except ValueError as e:
        raise ToolboxError(str(e)) from None


def axis_angle_from_rotation(R: object) -> tuple[np.ndarray, float]:
    """Unit axis (3,) and angle [rad] in [0, π] of a rotation matrix (3, 3).

    For the identity the axis is (0, 0, 1) and the angle 0. At exactly π the axis sign is arbitrary.
    """
    try:
        return se3.axis_angle(np.asarray(R, dtype=float))
    except ValueError as e:
        raise ToolboxError(str(e)) from None


def yaw_of(T: object) -> float:
    """Heading [rad, in (-π, π]] of the object's x axis projected onto the world xy plane.

    Accepts a pose (4, 4) or a rotation (3, 3). Meaningless when the x axis is nearly vertical.
    """
    return se3.yaw(np.asarray(T, dtype=float))


def is_proper_rotation(R: object, tol: float = se3.ROTATION_TOL) -> bool:
    """True when R (3, 3) is orthonormal with determinant +1, within `tol` per entry."""
    return se3.is_proper_rotation(np.asarray(R, dtype=float), tol)


def project_to_rotation(M: object) -> np.ndarray:
    """The proper rotation (3, 3) nearest to M in Frobenius norm (SVD; fixes drift or noise)."""
    try:
        return se3.project_to_rotation(np.asarray(M, dtype=float))
    except ValueError as e:
        raise ToolboxError(str(e)) from None


def rotation_angle_between(R_a: object, R_b: object) -> float:
    """Angle [rad, in [0, π]] of the relative rotation R_aᵀ R_b; accepts (3, 3) or (4, 4)."""
    return se3.angle_between(_rotation_part(R_a, "R_a"), _rotation_part(R_b, "R_b"))


def pose_distance(
    T_a: object,
    T_b: object,
    symmetries: Sequence[object] | None = None,
    *,
    continuous_axis: object = None,
) -> PoseDistance:
    """Translation [m] and rotation [rad] error between two poses, modulo object symmetry.

    Args:
        T_a, T_b: poses (4, 4) `T_world_object` of the same object.
        symmetries: object-frame transforms S (4, 4) (or rotations (3, 3)) under which the
            object looks the same, e.g. `cyclic_symmetries(4)` for a square prism. The
            alternative `T_b @ S` with the smallest rotation error is used (ties: translation).
            Include the identity; None means no symmetry.
        continuous_axis: object-frame axis (3,) of a continuous rotational symmetry (a cylinder's
            axis): rotation error is then the angle between the two poses' axes.

    Returns:
        PoseDistance(translation, rotation).
    """
    A, B = as_pose(T_a), as_pose(T_b)
    group = None
    if symmetries is not None:
        if len(symmetries) == 0:
            raise ToolboxError("symmetries is empty; pass None or include the identity")
        group = []
        for k, S in enumerate(symmetries):
            S_m = np.asarray(S, dtype=float)
            if S_m.shape not in ((3, 3), (4, 4)):
                raise ToolboxError(f"symmetries[{k}] must be (4, 4) or (3, 3), got {S_m.shape}")
            group.append(se3.make(S_m) if S_m.shape == (3, 3) else S_m)
    axis = None
    if continuous_axis is not None:
        axis = np.asarray(continuous_axis, dtype=float).reshape(3)
        if not np.linalg.norm(axis) > 0:
            raise ToolboxError("continuous_axis has zero length")
    return PoseDistance(*se3.pose_error(A, B, group, continuous_axis=axis))


def cyclic_symmetries(n: int, axis: object = (0.0, 0.0, 1.0)) -> list[np.ndarray]:
    """The n poses (4, 4) rotating by multiples of 2π/n about an object-frame `axis`.

    Use with `pose_distance`: n=4 for a square prism about its long axis, n=2 for a box.
    """
    if int(n) < 1:
        raise ToolboxError(f"symmetry order must be >= 1, got {n}")
    try:
        return se3.cyclic_group(int(n), _axis(axis))
    except ValueError as e:
        raise ToolboxError(str(e)) from None


def cube_symmetries() -> list[np.ndarray]:
    """The 24 proper rotations (4, 4) mapping an origin-centred axis-aligned cube onto itself."""
    return se3.cube_group()
