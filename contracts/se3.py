"""SE(3) helpers the contracts need: properness, inverse, composition, error modulo symmetry.

Design rule: plain numpy, 4×4 homogeneous matrices `T_a_b` (a point in b's frame maps into a's
frame as `T_a_b @ p`), metres and radians; no simulator, no I/O. A symmetry group is a sequence
of object-frame transforms `S` such that the object looks identical at `T @ S` and at `T`.
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


def rotvec_to_matrix(rotvec: Iterable[float]) -> np.ndarray:
    """Rodrigues: axis-angle vector [rad] → rotation (3, 3)."""
    w = np.asarray(list(rotvec), dtype=float)
    theta = float(np.linalg.norm(w))
    if theta < 1e-12:
        return np.eye(3)
    k = w / theta
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * Kx + (1 - np.cos(theta)) * (Kx @ Kx)


def rot_z(angle: float) -> np.ndarray:
    """Rotation about z by `angle` [rad] as a 4×4 transform."""
    c, s = np.cos(angle), np.sin(angle)
    return make(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))


def rotation_angle(R: np.ndarray) -> float:
    """Angle [rad] in [0, π] of a rotation matrix."""
    c = (np.trace(np.asarray(R, dtype=float)) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def yaw(T: np.ndarray) -> float:
    """Heading [rad] of the object's x axis projected on the world xy plane."""
    T = np.asarray(T, dtype=float)
    return float(np.arctan2(T[1, 0], T[0, 0]))


def pose_error(
    T_a: np.ndarray, T_b: np.ndarray, symmetries: Sequence[np.ndarray] | None = None
) -> tuple[float, float]:
    """(translation error [m], rotation error [rad]) between two poses, modulo a symmetry group.

    The symmetric alternative of `T_b` with the smallest rotation error is chosen (ties by
    translation); with no symmetries the plain error is returned.
    """
    A = np.asarray(T_a, dtype=float)
    best: tuple[float, float] | None = None
    for S in symmetries if symmetries else (_IDENTITY,):
        B = np.asarray(T_b, dtype=float) @ np.asarray(S, dtype=float)
        err = (
            float(np.linalg.norm(A[:3, 3] - B[:3, 3])),
            rotation_angle(A[:3, :3].T @ B[:3, :3]),
        )
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
    for S in symmetries if symmetries else (_IDENTITY,):
        B = np.asarray(T_b, dtype=float) @ np.asarray(S, dtype=float)
        if np.linalg.norm(A[:3, 3] - B[:3, 3]) > trans_tol:
            continue
        if rot_tol is None or rotation_angle(A[:3, :3].T @ B[:3, :3]) <= rot_tol:
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
    for S in symmetries if symmetries else (_IDENTITY,):
        pb = V @ (np.asarray(T_b, dtype=float) @ np.asarray(S, dtype=float)).T
        best = min(best, float(np.max(np.linalg.norm(pa[:, :3] - pb[:, :3], axis=1))))
    return best


def cyclic_group_z(n: int) -> list[np.ndarray]:
    """The n rotations about the object's z axis by multiples of 2π/n."""
    if n < 1:
        raise ValueError(f"cyclic group order must be >= 1, got {n}")
    return [rot_z(2.0 * np.pi * k / n) for k in range(n)]


def cube_group() -> list[np.ndarray]:
    """The 24 proper rotations that map an axis-aligned cube centred at the origin onto itself."""
    out = []
    for perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1), (1, 0, 2), (0, 2, 1), (2, 1, 0)):
        for signs in np.ndindex(2, 2, 2):
            R = np.zeros((3, 3))
            for row, col in enumerate(perm):
                R[row, col] = -1.0 if signs[row] else 1.0
            if np.linalg.det(R) > 0:
                out.append(make(R))
    return out
