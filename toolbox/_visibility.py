"""Agreement between a posed model and an observed depth image (private to registration)."""

from __future__ import annotations

import numpy as np

from toolbox._common import camera_matrices, camera_size


def surface_consistency(
    samples: np.ndarray,
    normals: np.ndarray,
    T_world_object: np.ndarray,
    depth: np.ndarray,
    mask: np.ndarray,
    camera: dict,
    tolerance: float,
    spacing: float,
) -> float:
    """Fraction of the model's camera-visible surface samples that the observation confirms.

    A visible sample is confirmed when its pixel is in `mask` with observed depth within
    `tolerance` [m]; it is excused when something nearer hides it (observed depth in front by
    more than `tolerance`) or its in-mask depth is missing; otherwise it contradicts the
    observation (the model would be seen where the camera sees something farther or nothing).
    Self-occlusion is resolved by a z-buffer whose cells are about `spacing` [m] (the sample
    spacing) wide. Returns 0.0 when no sample is visible.
    """
    K, T_wc = camera_matrices(camera)
    width, height = camera_size(camera)
    T_co = np.linalg.inv(T_wc) @ T_world_object
    pc = samples @ T_co[:3, :3].T + T_co[:3, 3]
    nc = normals @ T_co[:3, :3].T
    front = (np.einsum("ij,ij->i", nc, pc) < 0) & (pc[:, 2] > 1e-6)
    pc = pc[front]
    if len(pc) == 0:
        return 0.0
    z = pc[:, 2]
    u = K[0, 0] * pc[:, 0] / z + K[0, 1] * pc[:, 1] / z + K[0, 2]
    v = K[1, 1] * pc[:, 1] / z + K[1, 2]
    ui, vi = np.round(u).astype(int), np.round(v).astype(int)
    inside = (ui >= 0) & (ui < width) & (vi >= 0) & (vi < height)
    ui, vi, z = ui[inside], vi[inside], z[inside]
    if len(z) == 0:
        return 0.0
    cell = max(1, round(spacing * K[0, 0] / float(np.median(z))))
    key = (vi // cell) * (width // cell + 1) + ui // cell
    zbuf = np.full(int(key.max()) + 1, np.inf)
    np.minimum.at(zbuf, key, z)
    visible = z <= zbuf[key] + tolerance
    ui, vi, z = ui[visible], vi[visible], z[visible]
    D = np.asarray(depth, dtype=float)[vi, ui]
    M = np.asarray(mask, dtype=bool)[vi, ui]
    confirmed = M & (np.abs(D - z) < tolerance)
    excused = ((D > 0) & (D + tolerance < z)) | (M & ~(D > 0))
    contradicted = ~confirmed & ~excused
    n_ok, n_bad = int(np.count_nonzero(confirmed)), int(np.count_nonzero(contradicted))
    return n_ok / (n_ok + n_bad) if n_ok + n_bad else 0.0
