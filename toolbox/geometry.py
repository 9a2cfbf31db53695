"""SE(3) for generated programs: poses, rotations, symmetry-aware pose distance.

Design rule: plain numpy, no state. A pose is a 4×4 homogeneous float matrix `T_a_b` that maps
a point expressed in frame b into frame a (`p_a = T_a_b @ [p_b, 1]`); records store
`T_world_object`. Metres and radians. A symmetry of an object is an object-frame transform `S`
such that the object looks identical at poses `T` and `T @ S`. Conventions match
`contracts.se3`, which the checks use.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

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


def as_pose(T: object) -> np.ndarray:
    """Convert a pose (4×4 nested lists or array) into a float (4, 4) numpy copy.

    Raises:
        ToolboxError: the shape is not (4, 4) or an entry is not finite.
    """
    try:
        M = np.array(T, dtype=float)
    except (TypeError, ValueError) as e:
        raise ToolboxError(f"pose is not numeric: {e}") from None
    if M.shape != (4, 4):
        raise ToolboxError(f"pose must have shape (4, 4), got {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ToolboxError("pose contains NaN or inf")
    return M


def make_pose(rotation: object = None, translation: object = None) -> np.ndarray:
    """Build a 4×4 pose from a rotation (3, 3) and a translation (3,) [m].

    Either argument may be None (identity rotation / zero translation).
    """
    T = np.eye(4)
    if rotation is not None:
        R = np.asarray(rotation, dtype=float)
        if R.shape != (3, 3):
            raise ToolboxError(f"rotation must have shape (3, 3), got {R.shape}")
        T[:3, :3] = R
    if translation is not None:
        t = np.asarray(translation, dtype=float).reshape(-1)
        if t.shape != (3,):
            raise ToolboxError(f"translation must have 3 entries, got {t.shape[0]}")
        T[:3, 3] = t
    return T


def pose_from_xyz_yaw(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """Pose at position (x, y, z) [m], rotated by `yaw` [rad] about the world z axis.

    The object's z axis stays vertical: this is how flat-lying objects on the table are placed.
    """
    c, s = np.cos(yaw), np.sin(yaw)
    return make_pose([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], [x, y, z])


def invert_pose(T: object) -> np.ndarray:
    """Inverse of a rigid transform: `T_b_a` from `T_a_b` (uses Rᵀ, exact for rotations)."""
    M = as_pose(T)
    R, t = M[:3, :3], M[:3, 3]
    return make_pose(R.T, -R.T @ t)


def transform_points(T: object, points: object) -> np.ndarray:
    """Apply pose `T_a_b` to points (N, 3) given in frame b; returns (N, 3) in frame a.

    A single point (3,) returns a single point (3,).
    """
    M = as_pose(T)
    P = np.asarray(points, dtype=float)
    if P.shape[-1:] != (3,) or P.ndim > 2:
        raise ToolboxError(f"points must have shape (N, 3) or (3,), got {P.shape}")
    return P @ M[:3, :3].T + M[:3, 3]


def rotation_about_axis(axis: object, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) turning by `angle` [rad] about `axis` (3,), right-hand rule.

    The axis need not be unit length. Raises ToolboxError for a zero axis.
    """
    a = np.asarray(axis, dtype=float).reshape(3)
    n = np.linalg.norm(a)
    if n < 1e-12:
        raise ToolboxError("rotation axis has zero length")
    k = a / n
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def axis_angle_from_rotation(R: object) -> tuple[np.ndarray, float]:
    """Unit axis (3,) and angle [rad] in [0, π] of a rotation matrix (3, 3).

    For the identity the axis is (0, 0, 1) and the angle 0. Near π the axis sign is arbitrary.
    """
    M = project_to_rotation(R)
    angle = rotation_angle_between(np.eye(3), M)
    if angle < 1e-9:
        return np.array([0.0, 0.0, 1.0]), 0.0
    if np.pi - angle > 1e-4:
        w = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
        return w / np.linalg.norm(w), angle
    # Near π the skew part vanishes: the axis is the dominant column of (R + I) / 2 = k kᵀ.
    B = (M + np.eye(3)) / 2.0
    k = B[:, int(np.argmax(np.diag(B)))]
    return k / np.linalg.norm(k), angle


def yaw_of(T: object) -> float:
    """Heading [rad, in (-π, π]] of the object's x axis projected onto the world xy plane.

    Accepts a pose (4, 4) or a rotation (3, 3). Meaningless when the x axis is nearly vertical.
    """
    M = np.asarray(T, dtype=float)
    return float(np.arctan2(M[1, 0], M[0, 0]))


def is_proper_rotation(R: object, tol: float = 1e-4) -> bool:
    """True when R (3, 3) is orthonormal with determinant +1, within `tol` per entry."""
    M = np.asarray(R, dtype=float)
    if M.shape != (3, 3) or not np.all(np.isfinite(M)):
        return False
    ortho = np.max(np.abs(M.T @ M - np.eye(3)))
    return bool(ortho <= tol and abs(np.linalg.det(M) - 1.0) <= tol)


def project_to_rotation(M: object) -> np.ndarray:
    """The proper rotation (3, 3) nearest to M in Frobenius norm (SVD; fixes drift or noise)."""
    A = np.asarray(M, dtype=float)
    if A.shape != (3, 3) or not np.all(np.isfinite(A)):
        raise ToolboxError(f"expected a finite (3, 3) matrix, got shape {A.shape}")
    U, _, Vt = np.linalg.svd(A)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def rotation_angle_between(R_a: object, R_b: object) -> float:
    """Angle [rad, in [0, π]] of the relative rotation R_aᵀ R_b; accepts (3, 3) or (4, 4)."""
    A = np.asarray(R_a, dtype=float)[:3, :3]
    B = np.asarray(R_b, dtype=float)[:3, :3]
    M = A.T @ B
    # atan2 keeps full precision near 0 and π, where arccos of the trace loses half the digits.
    w = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
    return float(np.arctan2(np.linalg.norm(w) / 2.0, (np.trace(M) - 1.0) / 2.0))


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
    A = as_pose(T_a)
    B0 = as_pose(T_b)
    axis = None
    if continuous_axis is not None:
        axis = np.asarray(continuous_axis, dtype=float).reshape(3)
        axis = axis / np.linalg.norm(axis)
    best: PoseDistance | None = None
    if symmetries is not None and len(symmetries) == 0:
        raise ToolboxError("symmetries is empty; pass None or include the identity")
    for S in (np.eye(4),) if symmetries is None else symmetries:
        S_m = np.asarray(S, dtype=float)
        B = B0 @ (make_pose(S_m) if S_m.shape == (3, 3) else S_m)
        if axis is None:
            rot = rotation_angle_between(A, B)
        else:
            cos = float(np.dot(A[:3, :3] @ axis, B[:3, :3] @ axis))
            rot = float(np.arccos(np.clip(cos, -1.0, 1.0)))
        d = PoseDistance(float(np.linalg.norm(A[:3, 3] - B[:3, 3])), rot)
        if best is None or (d.rotation, d.translation) < (best.rotation, best.translation):
            best = d
    assert best is not None  # at least one alternative was scored
    return best


def cyclic_symmetries(n: int, axis: object = (0.0, 0.0, 1.0)) -> list[np.ndarray]:
    """The n poses (4, 4) rotating by multiples of 2π/n about an object-frame `axis`.

    Use with `pose_distance`: n=4 for a square prism about its long axis, n=2 for a box.
    """
    if int(n) < 1:
        raise ToolboxError(f"symmetry order must be >= 1, got {n}")
    return [make_pose(rotation_about_axis(axis, 2.0 * np.pi * k / n)) for k in range(int(n))]


def cube_symmetries() -> list[np.ndarray]:
    """The 24 proper rotations (4, 4) mapping an origin-centred axis-aligned cube onto itself."""
    out = []
    for perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1), (1, 0, 2), (0, 2, 1), (2, 1, 0)):
        for signs in np.ndindex(2, 2, 2):
            R = np.zeros((3, 3))
            for row, col in enumerate(perm):
                R[row, col] = -1.0 if signs[row] else 1.0
            if np.linalg.det(R) > 0:
                out.append(make_pose(R))
    return out
