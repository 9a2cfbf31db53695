"""Camera geometry and point clouds: projection, back-projection, planes.

Design rule: every function takes the representation's camera dict `{"width", "height",
"K" (3, 3), "T_world_camera" (4, 4)}` in the OpenCV convention (x right, y down, z forward) and
works in the world frame unless told otherwise. Pixel coordinates are `(u, v)` = (column, row)
with the centre of pixel `depth[v, u]` at integer `(u, v)`. Depth is metric along the optical
axis [m], 0 where invalid. A plane is `(a, b, c, d)` with unit normal `(a, b, c)`: points p on it
satisfy `a·x + b·y + c·z + d = 0`, and the signed distance is positive on the normal's side.
"""

from __future__ import annotations

import numpy as np

from contracts import se3
from toolbox._common import camera_matrices, check_image, check_points, rng_from
from toolbox.errors import ToolboxError

__all__ = [
    "backproject_pixels",
    "cluster_points",
    "depth_to_points",
    "distance_to_plane",
    "estimate_table_plane",
    "fit_plane_ransac",
    "level_camera_on_table",
    "pixels_to_plane",
    "project_points",
    "remove_plane",
    "voxel_downsample",
]


def project_points(points: object, camera: dict) -> tuple[np.ndarray, np.ndarray]:
    """Project world points (N, 3) [m] into the image.

    Returns:
        (uv, z): pixel coordinates (N, 2) float (u = column, v = row; may lie outside the
        image) and depth along the optical axis (N,) [m]. Points with z <= 0 are behind the
        camera and their uv is NaN.
    """
    K, T_wc = camera_matrices(camera)
    P = check_points(points, "points")
    Tcw = np.linalg.inv(T_wc)
    pc = P @ Tcw[:3, :3].T + Tcw[:3, 3]
    z = pc[:, 2]
    uv = np.full((len(P), 2), np.nan)
    front = z > 1e-12
    uv[front, 0] = K[0, 0] * pc[front, 0] / z[front] + K[0, 1] * pc[front, 1] / z[front] + K[0, 2]
    uv[front, 1] = K[1, 1] * pc[front, 1] / z[front] + K[1, 2]
    return uv, z


def backproject_pixels(uv: object, depth: object, camera: dict) -> np.ndarray:
    """World points (N, 3) [m] seen at pixels uv (N, 2) with depths (N,) [m] (z along the axis).

    Inverse of `project_points`: `project_points(backproject_pixels(uv, z, cam), cam)`
    returns `(uv, z)`. Subpixel uv is allowed.
    """
    K, T_wc = camera_matrices(camera)
    UV = np.asarray(uv, dtype=float).reshape(-1, 2)
    z = np.asarray(depth, dtype=float).reshape(-1)
    if len(z) != len(UV):
        raise ToolboxError(f"got {len(UV)} pixels but {len(z)} depths")
    y = (UV[:, 1] - K[1, 2]) / K[1, 1]
    x = (UV[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    pc = np.stack([x * z, y * z, z], axis=1)
    return pc @ T_wc[:3, :3].T + T_wc[:3, 3]


def depth_to_points(
    depth: object,
    camera: dict,
    mask: object = None,
    *,
    stride: int = 1,
    frame: str = "world",
    return_pixels: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Point cloud from a depth image (H, W) [m], optionally restricted to a boolean mask (H, W).

    Args:
        stride: keep every `stride`-th row and column (fast, coarse clouds).
        frame: "world" (default) or "camera" (OpenCV camera frame).
        return_pixels: also return the integer pixels (N, 2) as (u, v) of each point, e.g. to
            look up colours with `rgb[v, u]`.

    Returns:
        points (N, 3) [m] for the valid (depth > 0, finite) pixels in row-major order, or
        (points, pixels) when `return_pixels`. N may be 0.
    """
    camera_matrices(camera)  # validates
    D = check_image(depth, camera, "depth", ndim=2).astype(float)
    valid = np.isfinite(D) & (D > 0)
    if mask is not None:
        valid &= check_image(mask, camera, "mask", ndim=2).astype(bool)
    if stride > 1:
        keep = np.zeros_like(valid)
        keep[::stride, ::stride] = True
        valid &= keep
    v, u = np.nonzero(valid)
    pixels = np.stack([u, v], axis=1)
    if frame not in ("world", "camera"):
        raise ToolboxError(f"frame must be 'world' or 'camera', got {frame!r}")
    cam = camera if frame == "world" else {**camera, "T_world_camera": np.eye(4)}
    pts = backproject_pixels(pixels, D[v, u], cam) if len(u) else np.zeros((0, 3))
    return (pts, pixels) if return_pixels else pts


def pixels_to_plane(uv: object, camera: dict, plane: object = (0.0, 0.0, 1.0, 0.0)) -> np.ndarray:
    """Intersect the viewing rays of pixels uv (N, 2) with a world plane (default: table z = 0).

    Use it for flat objects seen from above, where depth is too coarse. Returns world points
    (N, 3) [m]; rows are NaN where the ray is parallel to the plane or the hit is behind the
    camera.
    """
    _, T_wc = camera_matrices(camera)
    UV = np.asarray(uv, dtype=float).reshape(-1, 2)
    pl = _check_plane(plane)
    d_cam = backproject_pixels(UV, np.ones(len(UV)), {**camera, "T_world_camera": np.eye(4)})
    rays = d_cam @ T_wc[:3, :3].T  # (N, 3) world directions with unit optical-axis depth
    origin = T_wc[:3, 3]
    denom = rays @ pl[:3]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -(origin @ pl[:3] + pl[3]) / denom
    out = origin + s[:, None] * rays
    out[~(np.abs(denom) > 1e-12) | ~(s > 0)] = np.nan
    return out


def distance_to_plane(points: object, plane: object) -> np.ndarray:
    """Signed distances (N,) [m] of points (N, 3) to a plane (a, b, c, d); > 0 on the normal side."""
    pl = _check_plane(plane)
    return check_points(points, "points") @ pl[:3] + pl[3]


def fit_plane_ransac(
    points: object,
    *,
    threshold: float = 0.004,
    iterations: int = 300,
    normal_hint: object = None,
    max_angle: float = np.pi,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Fit the dominant plane to points (N, 3) [m] with RANSAC, then refine by least squares.

    Args:
        threshold: inlier distance [m].
        normal_hint: direction (3,); the returned normal is flipped to agree with it, and
            planes whose normal is more than `max_angle` [rad] away from ±hint are rejected.
        seed: random seed (results are deterministic for a given seed).

    Returns:
        (plane (4,), inliers (N,) bool), or None when fewer than 3 points or no plane has at
        least 3 inliers.
    """
    P = check_points(points, "points")
    if len(P) < 3:
        return None
    rng = rng_from(seed)
    hint = None
    if normal_hint is not None:
        hint = np.asarray(normal_hint, dtype=float).reshape(3)
        hint = hint / np.linalg.norm(hint)
    cos_min = np.cos(max_angle) if max_angle < np.pi / 2 else -1.0
    best, best_count = None, 2
    for _ in range(int(iterations)):
        a, b, c = P[rng.choice(len(P), 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-12:
            continue
        n /= norm
        if hint is not None and abs(n @ hint) < cos_min:
            continue
        count = int(np.count_nonzero(np.abs((P - a) @ n) < threshold))
        if count > best_count:
            best, best_count = np.append(n, -n @ a), count
    if best is None:
        return None
    inliers = np.abs(P @ best[:3] + best[3]) < threshold
    centroid = P[inliers].mean(axis=0)
    n = np.linalg.svd(P[inliers] - centroid, full_matrices=False)[2][2]
    if n @ best[:3] < 0:
        n = -n
    if hint is not None and n @ hint < 0:
        n = -n
    plane = np.append(n, -n @ centroid)
    return plane, np.abs(P @ plane[:3] + plane[3]) < threshold


def estimate_table_plane(
    depth: object, camera: dict, *, threshold: float = 0.004, max_tilt: float = 0.35, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Estimate the table plane from a depth image (H, W) [m] with RANSAC.

    Only near-horizontal planes (normal within `max_tilt` [rad] of world +z) are accepted, and
    the normal points up. Distances to the plane are heights above the table.

    Returns:
        (plane (4,), inlier mask (H, W) bool).

    Raises:
        ToolboxError: fewer than 100 valid depth pixels or no near-horizontal plane found.
    """
    D = check_image(depth, camera, "depth", ndim=2)
    stride = max(1, int(np.sqrt(D.size / 20000)))
    pts = depth_to_points(D, camera, stride=stride)
    if len(pts) < 100:
        raise ToolboxError(f"only {len(pts)} valid depth pixels; cannot estimate a table plane")
    fit = fit_plane_ransac(
        pts, threshold=threshold, normal_hint=(0, 0, 1), max_angle=max_tilt, seed=seed
    )
    if fit is None:
        raise ToolboxError("no near-horizontal plane found in the depth image")
    plane = fit[0]
    all_pts, pix = depth_to_points(D, camera, return_pixels=True)
    mask = np.zeros(D.shape, dtype=bool)
    on = np.abs(all_pts @ plane[:3] + plane[3]) < threshold
    mask[pix[on, 1], pix[on, 0]] = True
    return plane, mask


def level_camera_on_table(
    depth: object,
    camera: dict,
    *,
    band: float = 0.02,
    max_tilt: float = 0.03,
    max_shift: float = 0.03,
    min_points: int = 500,
) -> dict:
    """The camera corrected so that the table it sees is the plane z = 0.

    A calibrated camera is off by a few millimetres and tenths of a degree, which moves every
    point back-projected through it. The table (z = 0) shows two of the three rotation errors
    (the tilt) and the height error: the points within `band` [m] of z = 0 are fitted with a
    plane (least squares, trimmed twice), the camera is turned about its own centre by the
    smallest rotation that makes the plane horizontal and shifted vertically so that it lies at
    z = 0. Errors of yaw and of horizontal position cannot be seen from the table and remain.

    Args:
        depth: (H, W) [m], 0 where invalid.
        camera: the camera the depth was taken with (the calibrated one).
        max_tilt, max_shift: larger corrections [rad, m] are not trusted (too few table
            points, or the table not the dominant plane near z = 0): the camera comes back
            unchanged.
        min_points: table points needed for a correction.

    Returns:
        a camera dict like `camera`, with the corrected "T_world_camera".
    """
    D = check_image(depth, camera, "depth", ndim=2)
    stride = max(1, int(np.sqrt(D.size / 12000)))
    pts = np.asarray(depth_to_points(D, camera, stride=stride))
    P = pts[np.abs(pts[:, 2]) < band] if len(pts) else pts
    if len(P) < min_points:
        return dict(camera)
    keep = np.ones(len(P), dtype=bool)
    for trim in (0.004, 0.002):
        c = P[keep].mean(axis=0)
        n = np.linalg.svd(P[keep] - c, full_matrices=False)[2][2]
        n = n if n[2] > 0 else -n
        keep = np.abs((P - c) @ n) < trim
        if np.count_nonzero(keep) < min_points:
            return dict(camera)
    c = P[keep].mean(axis=0)
    n = np.linalg.svd(P[keep] - c, full_matrices=False)[2][2]
    n = n if n[2] > 0 else -n
    axis = np.cross(n, [0.0, 0.0, 1.0])
    tilt = float(np.arcsin(np.clip(np.linalg.norm(axis), 0.0, 1.0)))
    if tilt > max_tilt:
        return dict(camera)
    R = se3.rotvec_to_matrix(axis / max(np.linalg.norm(axis), 1e-12) * tilt)
    T = np.array(camera["T_world_camera"], dtype=float)
    eye = T[:3, 3].copy()
    out = T.copy()
    out[:3, :3] = R @ T[:3, :3]
    height = float(eye[2] + (R @ (c - eye))[2])  # the table's height once level
    if abs(height) > max_shift:
        return dict(camera)
    out[2, 3] -= height
    return {**camera, "T_world_camera": out}


def remove_plane(points: object, plane: object, *, threshold: float = 0.004) -> np.ndarray:
    """Keep the points (N, 3) lying more than `threshold` [m] above the plane (normal side)."""
    P = check_points(points, "points")
    return P[distance_to_plane(P, plane) > threshold]


def voxel_downsample(points: object, voxel_size: float) -> np.ndarray:
    """Average the points (N, 3) [m] falling in each cube of side `voxel_size` [m]; returns (M, 3)."""
    P = check_points(points, "points")
    if voxel_size <= 0:
        raise ToolboxError(f"voxel_size must be > 0, got {voxel_size}")
    if len(P) == 0:
        return P
    keys = np.floor(P / voxel_size).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse.reshape(-1), P)
    return sums / counts[:, None]


def cluster_points(points: object, *, eps: float = 0.01, min_points: int = 10) -> np.ndarray:
    """Euclidean clustering (DBSCAN) of points (N, 3) [m] into objects.

    Args:
        eps: neighbour distance [m] that links points into one cluster.
        min_points: minimum neighbours for a core point.

    Returns:
        labels (N,) int: cluster index 0, 1, … (largest cluster first), -1 for noise.
    """
    import open3d as o3d

    P = check_points(points, "points")
    if len(P) == 0:
        return np.zeros(0, dtype=int)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    raw = np.asarray(pcd.cluster_dbscan(eps=eps, min_points=min_points))
    labels = np.full(len(P), -1, dtype=int)
    ids, counts = np.unique(raw[raw >= 0], return_counts=True)
    for new, old in enumerate(ids[np.argsort(-counts, kind="stable")]):
        labels[raw == old] = new
    return labels


def _check_plane(plane: object) -> np.ndarray:
    pl = np.asarray(plane, dtype=float).reshape(-1)
    if pl.shape != (4,) or not np.all(np.isfinite(pl)):
        raise ToolboxError(f"plane must be 4 finite numbers (a, b, c, d), got {pl.shape}")
    n = np.linalg.norm(pl[:3])
    if n < 1e-12:
        raise ToolboxError("plane normal has zero length")
    return pl / n
