"""3D registration: ICP, FPFH/RANSAC global registration, and mesh-to-segment 6D pose fitting.

Design rule: deterministic — the same inputs and seed give bit-identical results (Open3D only
computes FPFH features; ICP and RANSAC are single-threaded numpy). Points are (N, 3)
float arrays [m]. A result's `transform` maps *source* points into the *target* frame
(`target ≈ transform_points(result.transform, source)`); for `register_mesh_to_points` it is
`T_world_object`. `fitness` is the fraction of source points with a target point within
`max_distance`; `rmse` [m] is over those inliers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from toolbox import _icp
from toolbox._common import check_image, check_points
from toolbox._visibility import surface_consistency
from toolbox.errors import ToolboxError
from toolbox.geometry import cube_symmetries, invert_pose, make_pose
from toolbox.vision import depth_to_points, voxel_downsample

__all__ = [
    "RegistrationResult",
    "global_registration",
    "icp",
    "register_mesh_to_points",
    "register_mesh_to_segment",
]


@dataclass(frozen=True, kw_only=True)
class RegistrationResult:
    """Outcome of a registration.

    Attributes:
        transform: (4, 4) rigid transform taking source points into the target frame.
        fitness: fraction in [0, 1] of source points with a target point within max_distance.
        rmse: root-mean-square inlier distance [m] (inf when there are no inliers).
        consistency: fraction of the model's visible surface confirmed by the depth image
            (`register_mesh_to_segment` only; NaN otherwise).
    """

    transform: np.ndarray
    fitness: float
    rmse: float
    consistency: float = float("nan")


def icp(
    source: object,
    target: object,
    *,
    init: object = None,
    max_distance: float = 0.01,
    point_to_plane: bool = False,
    iterations: int = 50,
) -> RegistrationResult:
    """Refine the alignment of `source` (N, 3) onto `target` (M, 3) by ICP.

    ICP only converges from a good start: the initial transform `init` (4, 4, default
    identity) must bring the clouds within roughly `max_distance` [m] of each other; otherwise
    use `global_registration` first. `point_to_plane` converges faster on smooth surfaces
    (normals are estimated on the target).

    Returns:
        RegistrationResult. Raises ToolboxError when either cloud has fewer than 3 points.
    """
    src, tgt = _cloud(source, "source"), _cloud(target, "target")
    T0 = np.eye(4) if init is None else _pose(init)
    tree = cKDTree(tgt)
    normals = _icp.estimate_normals(tgt, tree) if point_to_plane else None
    T, fitness, rmse = _icp.icp(src, tgt, T0, max_distance, iterations, tree=tree, normals=normals)
    return RegistrationResult(transform=T, fitness=fitness, rmse=rmse)


def global_registration(
    source: object,
    target: object,
    *,
    voxel_size: float = 0.005,
    refine: bool = True,
    seed: int = 0,
) -> RegistrationResult:
    """Align `source` (N, 3) onto `target` (M, 3) from any start: FPFH features + RANSAC.

    Both clouds are voxel-downsampled at `voxel_size` [m] (choose ~1/20 of the object size);
    with `refine` the RANSAC estimate is polished by point-to-point ICP. Deterministic for a
    given `seed`. Fails (low fitness) on featureless or highly symmetric shapes, where the
    rotation is ambiguous anyway; check `fitness` before trusting the result.
    """
    src, tgt = _cloud(source, "source"), _cloud(target, "target")
    src_down, fs = _features(src, voxel_size)
    tgt_down, ft = _features(tgt, voxel_size)
    dist = 1.5 * voxel_size
    pairs = _icp.match_features(fs, ft)
    T = _icp.ransac(src_down, tgt_down, pairs, dist, seed=int(seed))
    tree = cKDTree(tgt)
    if refine:
        T, fitness, rmse = _icp.icp(src, tgt, T, dist, 50, tree=tree)
    else:
        fitness, rmse = _icp.score(src, T, tree, dist)
    return RegistrationResult(transform=T, fitness=fitness, rmse=rmse)


def register_mesh_to_points(
    mesh,
    points: object,
    *,
    init: object = None,
    voxel_size: float | None = None,
    max_distance: float | None = None,
    n_samples: int = 4000,
    seed: int = 0,
) -> RegistrationResult:
    """Estimate the 6D pose `T_world_object` of a mesh from its observed surface points.

    Meant for one segmented object (e.g. `depth_to_points(depth, camera, mask)`), possibly
    partially occluded: the observed points are aligned onto points sampled on the mesh, so
    hidden parts of the mesh cost nothing. Hypotheses: FPFH/RANSAC global registration, `init`
    if given, and 24 axis-aligned orientations about the segment's centroid; each is refined
    by ICP and the one explaining most observed points (then lowest rmse) wins. From a single
    view several poses can explain the points equally well (the hidden side is free): prefer
    `register_mesh_to_segment` when you have the depth image and camera.
    Deterministic for a given `seed`; takes ~0.2–1 s.

    Args:
        mesh: trimesh.Trimesh in its canonical object frame [m].
        points: observed world points (N, 3) [m] on the object's visible surface (N >= 10).
        init: optional initial guess `T_world_object` (4, 4).
        voxel_size: downsampling size [m]; default 1/25 of the mesh's bounding-box diagonal.
        max_distance: inlier distance [m] for fitness; default 1.5 × voxel_size.

    Returns:
        RegistrationResult with `transform` = T_world_object; fitness is the fraction of
        observed points within `max_distance` of the posed mesh surface. A symmetric object
        returns one of its equivalent poses. Outliers in `points` (table, neighbours) lower
        fitness and can bias the pose: segment tightly first.

    Raises:
        ToolboxError: fewer than 10 points or an empty mesh.
    """
    fits, *_ = _hypotheses(mesh, points, init, voxel_size, max_distance, n_samples, seed, keep=4)
    T, fitness, rmse = max(fits, key=lambda f: (f[1], -f[2]))
    return RegistrationResult(transform=T, fitness=fitness, rmse=rmse)


def register_mesh_to_segment(
    mesh,
    depth: object,
    mask: object,
    camera: dict,
    *,
    init: object = None,
    voxel_size: float | None = None,
    max_distance: float | None = None,
    n_samples: int = 4000,
    seed: int = 0,
) -> RegistrationResult:
    """Estimate the 6D pose `T_world_object` of a mesh from its segment in a depth image.

    Like `register_mesh_to_points` on `depth_to_points(depth, camera, mask)`, but the
    candidate poses are also checked against what the camera saw: a pose whose camera-facing
    surface would appear where the depth image shows something farther away, or nothing,
    is penalised, while surface hidden behind nearer objects is excused. This resolves the
    single-view ambiguities of partial segments and tolerates occlusion by other objects.

    Args:
        mesh: trimesh.Trimesh in its canonical object frame [m].
        depth: full depth image (H, W) [m], 0 where invalid (not only the segment: other
            objects' depth tells what may hide this one).
        mask: (H, W) bool, the object's pixels (>= 10 with valid depth).
        camera: the camera dict `{"width", "height", "K", "T_world_camera"}` of `depth`.
        init, voxel_size, max_distance, n_samples, seed: as in `register_mesh_to_points`.

    Returns:
        RegistrationResult with `transform` = T_world_object, `fitness` and `rmse` as in
        `register_mesh_to_points`, and `consistency` in [0, 1]: the fraction of the posed
        model's visible surface confirmed by the depth image (> 0.8 for a good fit).

    Raises:
        ToolboxError: fewer than 10 valid segment pixels, shapes not matching the camera.
    """
    D = check_image(depth, camera, "depth", ndim=2)
    M = check_image(mask, camera, "mask", ndim=2).astype(bool)
    points = depth_to_points(D, camera, M)
    fits, model, normals, dist = _hypotheses(
        mesh, points, init, voxel_size, max_distance, n_samples, seed, keep=6
    )
    spacing = float(np.sqrt(mesh.area / len(model)))
    best: tuple[float, float, int, RegistrationResult] | None = None
    for i, (T, fitness, rmse) in enumerate(fits):
        c = surface_consistency(model, normals, T, D, M, camera, dist, spacing)
        r = RegistrationResult(transform=T, fitness=fitness, rmse=rmse, consistency=c)
        key = (fitness * c, -rmse, -i)
        if best is None or key > best[:3]:
            best = (*key, r)
    assert best is not None  # there is always at least one hypothesis
    return best[3]


def _hypotheses(mesh, points, init, voxel_size, max_distance, n_samples, seed, *, keep):
    """([(T_world_object, fitness, rmse)] for the `keep` best-screened starts, model samples
    (n, 3), their normals (n, 3), inlier distance [m])."""
    P = check_points(points, "points")
    if len(P) < 10:
        raise ToolboxError(f"need at least 10 observed points, got {len(P)}")
    if mesh is None or len(getattr(mesh, "faces", ())) == 0:
        raise ToolboxError("mesh has no faces")
    voxel = voxel_size or float(np.linalg.norm(mesh.extents)) / 25.0
    dist = max_distance or 1.5 * voxel
    model, model_normals = _sample_surface(mesh, n_samples, seed)
    obs = voxel_downsample(P, voxel / 2.0)  # for the final fit
    coarse_obs = voxel_downsample(P, voxel)  # for screening the hypotheses
    if len(coarse_obs) < 10:
        obs = coarse_obs = P
    tree = cKDTree(model)
    centroid, model_centre = obs.mean(axis=0), mesh.bounds.mean(axis=0)
    starts = [] if init is None else [invert_pose(_pose(init))]  # T_object_world guesses
    starts.append(
        global_registration(coarse_obs, model, voxel_size=voxel, refine=False, seed=seed).transform
    )
    for S in cube_symmetries():
        R = S[:3, :3]
        starts.append(make_pose(R, model_centre - R @ centroid))
    coarse: list[tuple[float, float, int, np.ndarray]] = []
    for T0 in starts:
        T, fitness, rmse = _icp.icp(coarse_obs, model, T0, 3 * dist, 20, tree=tree)
        coarse.append((-fitness, rmse, len(coarse), T))
    coarse.sort(key=lambda c: c[:3])
    fits = []
    for *_, T0 in coarse[:keep]:
        T, fitness, rmse = _icp.icp(obs, model, T0, dist, 50, tree=tree, normals=model_normals)
        fits.append((invert_pose(T), fitness, rmse))
    return fits, model, model_normals, dist


def _o3d():
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d


def _cloud(points: object, name: str) -> np.ndarray:
    P = check_points(points, name)
    if len(P) < 3:
        raise ToolboxError(f"{name} needs at least 3 points, got {len(P)}")
    return P


def _pose(T: object) -> np.ndarray:
    M = np.asarray(T, dtype=float)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise ToolboxError(f"init must be a finite (4, 4) pose, got shape {M.shape}")
    return M


def _features(P: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Downsampled points (n, 3) and their FPFH descriptors (n, 33) (Open3D, per point, so
    deterministic)."""
    o3d = _o3d()
    down = voxel_downsample(P, voxel)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(down))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    # FPFH depends on the normals' sign, which PCA leaves arbitrary: point them away from
    # the centroid in both clouds so that the same surface gets the same descriptor.
    cloud.orient_normals_towards_camera_location(down.mean(axis=0))
    cloud.normals = o3d.utility.Vector3dVector(-np.asarray(cloud.normals))
    f = o3d.pipelines.registration.compute_fpfh_feature(
        cloud, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
    )
    return down, np.asarray(f.data).T


def _sample_surface(mesh, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Area-uniform surface samples (n, 3) and their face normals (deterministic for a seed)."""
    import trimesh

    pts, face = trimesh.sample.sample_surface(mesh, int(n), seed=seed)
    return np.asarray(pts, dtype=float), np.asarray(mesh.face_normals, dtype=float)[face]
