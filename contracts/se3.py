"""SE(3), the one implementation: properness, inverse, composition, axis-angle, error modulo
symmetry, symmetry groups.

Design rule: plain numpy, 4×4 homogeneous matrices `T_a_b` (a point in b's frame maps into a's
frame as `T_a_b @ p`), metres and radians; no simulator, no I/O. A symmetry group is a sequence
of object-frame transforms `S` such that the object looks identical at `T @ S` and at `T`.

Everyone uses this module: the contracts and the checks, the simulator, the domains' symmetry
groups (`domains.symmetry`), and — under documented, argument-checking names — the programs
(`toolbox.geometry`). Functions here raise `ValueError` on malformed input; the toolbox turns
that into `ToolboxError`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

ROTATION_TOL = 1e-4  # max |RᵀR − I| and |det R − 1| for a rotation to count as proper

_IDENTITY = np.eye(4)


def as_matrix(T: object) -> np.ndarray:
    """A float (4, 4) copy of a pose given as nested lists or an array."""
    M = np.array(T, dtype=float)
    if M.shape != (4, 4):
        raise ValueError(f"expected a 4x4 matrix, got shape {M.shape}")
    return M


def rotation_defect(R: np.ndarray) -> tuple[float, float]:
    """How far R is from a rotation: (max |RᵀR − I|, det R)."""
    R = np.asarray(R, dtype=float)
    return float(np.max(np.abs(R.T @ R - np.eye(3)))), float(np.linalg.det(R))


def is_proper_rotation(R: np.ndarray, tol: float = ROTATION_TOL) -> bool:
    """True when R is orthonormal with det +1 within `tol`."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        return False
    ortho, det = rotation_defect(R)
    return ortho <= tol and abs(det - 1.0) <= tol


def is_rigid(T: np.ndarray, tol: float = ROTATION_TOL) -> bool:
    """True when T is a finite homogeneous rigid transform (proper rotation, last row 0 0 0 1)."""
    T = np.asarray(T, dtype=float)
    return (
        T.shape == (4, 4)
        and bool(np.all(np.isfinite(T)))
        and bool(np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=tol))
        and is_proper_rotation(T[:3, :3], tol)
    )


def make(R: np.ndarray | None = None, t: Iterable[float] | None = None) -> np.ndarray:
    """Homogeneous transform from a rotation (3, 3) and a translation (3,) [m]."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if t is not None:
        T[:3, 3] = np.asarray(list(t), dtype=float)
    return T


def identity() -> np.ndarray:
    return np.eye(4)


def inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (uses Rᵀ, not a general matrix inverse)."""
    T = np.asarray(T, dtype=float)
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ t
    return out


def compose(*Ts: np.ndarray) -> np.ndarray:
    """Product T1 @ T2 @ … (the identity for no arguments)."""
    out = np.eye(4)
    for T in Ts:
        out = out @ np.asarray(T, dtype=float)
    return out


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (N, 3) (or one point (3,)) in frame b mapped by `T_a_b` into frame a."""
    M = np.asarray(T, dtype=float)
    return np.asarray(points, dtype=float) @ M[:3, :3].T + M[:3, 3]


def rotation_about(axis: Iterable[float], angle: float) -> np.ndarray:
    """Rodrigues: rotation (3, 3) by `angle` [rad] about `axis` (3,, any length), right hand.

    Raises:
        ValueError: a zero-length axis.
    """
    a = np.asarray(axis, dtype=float).reshape(3)
    n = np.linalg.norm(a)
    if n < 1e-12:
        raise ValueError("rotation axis has zero length")
    k = a / n
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def rotvec_to_matrix(rotvec: Iterable[float]) -> np.ndarray:
    """Rodrigues: axis-angle vector [rad] → rotation (3, 3)."""
    w = np.asarray(list(rotvec), dtype=float)
    theta = float(np.linalg.norm(w))
    if theta < 1e-12:
        return np.eye(3)
    return rotation_about(w, theta)


def rot_z(angle: float) -> np.ndarray:
    """Rotation about z by `angle` [rad] as a 4×4 transform."""
    c, s = np.cos(angle), np.sin(angle)
    return make(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))


def rotation_angle(R: np.ndarray) -> float:
    """Angle [rad] in [0, π] of a rotation matrix (3, 3)."""
    M = np.asarray(R, dtype=float)
    # atan2 keeps full precision near 0 and π, where arccos of the trace loses half the digits.
    w = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
    return float(np.arctan2(np.linalg.norm(w) / 2.0, (np.trace(M) - 1.0) / 2.0))


def angle_between(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle [rad] in [0, π] of the relative rotation R_aᵀ R_b; accepts (3, 3) or (4, 4)."""
    A = np.asarray(R_a, dtype=float)[:3, :3]
    B = np.asarray(R_b, dtype=float)[:3, :3]
    return rotation_angle(A.T @ B)


def project_to_rotation(M: np.ndarray) -> np.ndarray:
    """The proper rotation (3, 3) nearest to M in Frobenius norm (SVD; fixes drift or noise).

    Raises:
        ValueError: M is not a finite (3, 3) matrix.
    """
    A = np.asarray(M, dtype=float)
    if A.shape != (3, 3) or not np.all(np.isfinite(A)):
        raise ValueError(f"expected a finite (3, 3) matrix, got shape {A.shape}")
    U, _, Vt = np.linalg.svd(A)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def axis_angle(R: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit axis (3,) and angle [rad] in [0, π] of a rotation (3, 3) (projected onto SO(3)).

    For the identity the axis is (0, 0, 1) and the angle 0. At exactly π the axis sign is arbitrary.
    """
    M = project_to_rotation(R)
    angle = rotation_angle(M)
    if angle < 1e-9:
        return np.array([0.0, 0.0, 1.0]), 0.0
    w = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])  # 2 sin θ k
    if np.pi - angle > 1e-4:
        return w / np.linalg.norm(w), angle
    # Near π the skew part vanishes: the axis is the dominant column of the symmetric part,
    # (R + Rᵀ)/2 − cos θ I = (1 − cos θ) k kᵀ, its sign that of the skew part.
    B = (M + M.T) / 2.0 - np.cos(angle) * np.eye(3)
    k = B[:, int(np.argmax(np.diag(B)))]
    k = k / np.linalg.norm(k)
    return (-k if float(np.dot(k, w)) < 0.0 else k), angle


def yaw(T: np.ndarray) -> float:
    """Heading [rad] in (-π, π] of the object's x axis projected on the world xy plane; a pose
    (4, 4) or a rotation (3, 3)."""
    T = np.asarray(T, dtype=float)
    return float(np.arctan2(T[1, 0], T[0, 0]))


def _group(symmetries: Sequence[np.ndarray] | None) -> Sequence[np.ndarray]:
    """The transforms to try: the group, or the identity alone for None or an empty group."""
    return symmetries if symmetries is not None and len(symmetries) else (_IDENTITY,)


def pose_error(
    T_a: np.ndarray,
    T_b: np.ndarray,
    symmetries: Sequence[np.ndarray] | None = None,
    *,
    continuous_axis: Iterable[float] | None = None,
) -> tuple[float, float]:
    """(translation error [m], rotation error [rad]) between two poses, modulo a symmetry group.

    The symmetric alternative `T_b @ S` with the smallest rotation error is chosen (ties by
    translation); with no symmetries the plain error is returned. With `continuous_axis` (an
    object-frame axis of continuous rotational symmetry, e.g. a cylinder's) the rotation error
    is the angle between the two poses' axes.
    """
    A = np.asarray(T_a, dtype=float)
    axis = None
    if continuous_axis is not None:
        axis = np.asarray(continuous_axis, dtype=float).reshape(3)
        axis = axis / np.linalg.norm(axis)
    best: tuple[float, float] | None = None
    for S in _group(symmetries):
        B = np.asarray(T_b, dtype=float) @ np.asarray(S, dtype=float)
        if axis is None:
            rot = angle_between(A, B)
        else:
            cos = float(np.dot(A[:3, :3] @ axis, B[:3, :3] @ axis))
            rot = float(np.arccos(np.clip(cos, -1.0, 1.0)))
        err = (float(np.linalg.norm(A[:3, 3] - B[:3, 3])), rot)
        if best is None or (err[1], err[0]) < (best[1], best[0]):
            best = err
    assert best is not None
    return best


def within_tolerance(
    T_a: np.ndarray,
    T_b: np.ndarray,
    *,
    trans_tol: float,
    rot_tol: float | None = None,
    symmetries: Sequence[np.ndarray] | None = None,
) -> bool:
    """True when some symmetric alternative of `T_b` is within both tolerances of `T_a`.

    Args:
        trans_tol: max translation error [m].
        rot_tol: max rotation error [rad]; None ignores rotation.
    """
    A = np.asarray(T_a, dtype=float)
    for S in _group(symmetries):
        B = np.asarray(T_b, dtype=float) @ np.asarray(S, dtype=float)
        if np.linalg.norm(A[:3, 3] - B[:3, 3]) > trans_tol:
            continue
        if rot_tol is None or angle_between(A, B) <= rot_tol:
            return True
    return False


def mssd(
    T_a: np.ndarray,
    T_b: np.ndarray,
    vertices: np.ndarray,
    symmetries: Sequence[np.ndarray] | None = None,
) -> float:
    """Maximum symmetry-aware surface distance [m] (BOP's MSSD) over model `vertices` (n, 3)."""
    V = np.c_[np.asarray(vertices, dtype=float), np.ones(len(vertices))]  # (n, 4)
    pa = V @ np.asarray(T_a, dtype=float).T
    best = np.inf
    for S in _group(symmetries):
        pb = V @ (np.asarray(T_b, dtype=float) @ np.asarray(S, dtype=float)).T
        best = min(best, float(np.max(np.linalg.norm(pa[:, :3] - pb[:, :3], axis=1))))
    return best


def cyclic_group(n: int, axis: Iterable[float] = (0.0, 0.0, 1.0)) -> list[np.ndarray]:
    """The n transforms (4, 4) rotating by multiples of 2π/n about an object-frame `axis`."""
    if int(n) < 1:
        raise ValueError(f"symmetry order must be >= 1, got {n}")
    return [make(rotation_about(axis, 2.0 * np.pi * k / int(n))) for k in range(int(n))]


def cube_group() -> list[np.ndarray]:
    """The 24 proper rotations (4, 4) mapping an axis-aligned cube centred at the origin onto
    itself, identity first."""
    out = []
    for perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1), (1, 0, 2), (0, 2, 1), (2, 1, 0)):
        for signs in np.ndindex(2, 2, 2):
            R = np.zeros((3, 3))
            for row, col in enumerate(perm):
                R[row, col] = -1.0 if signs[row] else 1.0
            if np.linalg.det(R) > 0:
                out.append(make(R))
    return out
