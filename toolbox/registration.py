"""3D registration: ICP, FPFH/RANSAC global registration, and mesh-to-segment 6D pose fitting.

Design rule: thin, deterministic wrappers around Open3D (seeded RANSAC). Points are (N, 3)
float arrays [m]. A result's `transform` maps *source* points into the *target* frame
(`target ≈ transform_points(result.transform, source)`); for `register_mesh_to_points` it is
`T_world_object`. `fitness` is the fraction of source points with a target point within
`max_distance`; `rmse` [m] is over those inliers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from toolbox._common import check_points
from toolbox.errors import ToolboxError
from toolbox.geometry import cube_symmetries, invert_pose, make_pose, rotation_about_axis

__all__ = [
    "RegistrationResult",
    "global_registration",
    "icp",
    "register_mesh_to_points",
]


@dataclass(frozen=True, kw_only=True)
class RegistrationResult:
    """Outcome of a registration.

    Attributes:
        transform: (4, 4) rigid transform taking source points into the target frame.
        fitness: fraction in [0, 1] of source points with a target point within max_distance.
        rmse: root-mean-square inlier distance [m] (inf when there are no inliers).
    """

    transform: np.ndarray
    fitness: float
    rmse: float


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
    o3d = _o3d()
    src, tgt = _cloud(source, "source"), _cloud(target, "target")
    T0 = np.eye(4) if init is None else np.asarray(init, dtype=float)
    if point_to_plane:
        tgt.estimate_normals(
            o3d.geometry.KDTreeSearchParamHybrid(radius=2 * max_distance, max_nn=30)
        )
        method = o3d.pipelines.registration.TransformationEstimationPointToPlane()
    else:
        method = o3d.pipelines.registration.TransformationEstimationPointToPoint()
    r = o3d.pipelines.registration.registration_icp(
        src,
        tgt,
        max_distance,
        T0,
        method,
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=int(iterations)),
    )
    return _result(r)


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
    o3d = _o3d()
    reg = o3d.pipelines.registration
    src, fs = _features(_cloud(source, "source"), voxel_size)
    tgt, ft = _features(_cloud(target, "target"), voxel_size)
    o3d.utility.random.seed(int(seed))
    dist = 1.5 * voxel_size
    r = reg.registration_ransac_based_on_feature_matching(
        src,
        tgt,
        fs,
        ft,
        True,
        dist,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [
            reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
            reg.CorrespondenceCheckerBasedOnDistance(dist),
        ],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )
    result = _result(r)
    if refine:
        result = icp(source, target, init=result.transform, max_distance=dist)
    return result


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
    by ICP and the one explaining most observed points (then lowest rmse) wins.

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
    P = check_points(points, "points")
    if len(P) < 10:
        raise ToolboxError(f"need at least 10 observed points, got {len(P)}")
    if mesh is None or len(getattr(mesh, "faces", ())) == 0:
        raise ToolboxError("mesh has no faces")
    diag = float(np.linalg.norm(mesh.extents))
    voxel = voxel_size or diag / 25.0
    dist = max_distance or 1.5 * voxel
    model = _sample_surface(mesh, n_samples, seed)
    obs = _voxel(P, voxel)
    if len(obs) < 10:
        obs = P
    centroid = obs.mean(axis=0)
    model_centre = mesh.bounds.mean(axis=0)
    starts = []  # T_object_world guesses
    if init is not None:
        starts.append(invert_pose(init))
    glob = global_registration(obs, model, voxel_size=voxel, refine=False, seed=seed)
    starts.append(glob.transform)
    for S in cube_symmetries():
        for yaw in (0.0, np.pi / 4):
            R = S[:3, :3] @ rotation_about_axis((0, 0, 1), yaw)
            starts.append(make_pose(R, model_centre - R @ centroid))
    coarse = [icp(obs, model, init=T, max_distance=3 * dist, iterations=30) for T in starts]
    coarse.sort(key=lambda r: (-r.fitness, r.rmse))
    best = None
    for c in coarse[:4]:
        fine = icp(obs, model, init=c.transform, max_distance=dist, point_to_plane=True)
        if best is None or (fine.fitness, -fine.rmse) > (best.fitness, -best.rmse):
            best = fine
    return RegistrationResult(
        transform=invert_pose(best.transform), fitness=best.fitness, rmse=best.rmse
    )


def _o3d():
    import open3d as o3d

    # Open3D prints warnings (e.g. "too few correspondences") straight to stdout.
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d


def _cloud(points: object, name: str):
    P = check_points(points, name)
    if len(P) < 3:
        raise ToolboxError(f"{name} needs at least 3 points, got {len(P)}")
    o3d = _o3d()
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))


def _features(cloud, voxel: float):
    o3d = _o3d()
    down = cloud.voxel_down_sample(voxel)
    down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    f = o3d.pipelines.registration.compute_fpfh_feature(
        down, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
    )
    return down, f


def _voxel(P: np.ndarray, voxel: float) -> np.ndarray:
    o3d = _o3d()
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    return np.asarray(cloud.voxel_down_sample(voxel).points)


def _sample_surface(mesh, n: int, seed: int) -> np.ndarray:
    """Evenly spread surface samples (deterministic for a seed)."""
    import trimesh

    pts, _ = trimesh.sample.sample_surface_even(mesh, int(n), seed=seed)
    if len(pts) < n // 2:  # sample_surface_even rejects points; top up
        extra, _ = trimesh.sample.sample_surface(mesh, int(n) - len(pts), seed=seed)
        pts = np.vstack([pts, extra])
    return np.asarray(pts, dtype=float)


def _result(r) -> RegistrationResult:
    T = np.array(r.transformation, dtype=float)
    rmse = float(r.inlier_rmse) if r.fitness > 0 else float("inf")
    return RegistrationResult(transform=T, fitness=float(r.fitness), rmse=rmse)
