"""Pose refinement by render-and-compare: rough records in, records that fit the image out.

`refine_poses` moves each object the camera sees to where its drawing best matches the image:
drawn pixels on the observed depth and inside the object's colour segment, the segment drawn.
The whole scene is drawn, so objects hide each other (a cube behind a tower is fitted from the
sliver that shows), and the turns an object's shape cannot rule out (a box's length for its
width) are tried. Check `PoseFit.good`; a seen object's fit is suspect when `iou` < `GOOD_IOU`
(correct fits: 0.9–1.0, less for a sliver), `depth_residual_m` > `GOOD_DEPTH_M` (correct:
0.2–1.5 mm) or `seen_through` > `MAX_SEEN_THROUGH`.

Example, in `perceive(observation, meshes, camera)` once `records` holds your estimate of every
object (`{"id", "mesh", "pose"}`, unseen ones too, found with `camera`) and `colours` maps each
id to its catalogue colour (RGB 0–255):

```python
from toolbox import refine_poses

fits = refine_poses(observation, meshes, records, camera=camera, colors=colours)
records = [fit.record() for fit in fits]
doubtful = [fit.id for fit in fits if fit.pixels > 0 and not fit.good]
```

Cost: 0.15–0.3 s of CPU for 6–8 objects at 1280 × 720 with the defaults.

Design rule: the observation is the judge; deterministic. Each hypothesis is moved onto its
segment's centroid, then improved by a pattern search on the score; objects are refined most
visible first, in `sweeps` passes, against the others' current poses (another object hides
this one only where the observation does not contradict it). Drawing is a numpy rasteriser
(`render_scene`'s pixels and depths, without OpenGL) on the observation reduced `scale` times.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from toolbox._common import camera_matrices, camera_size
from toolbox._compare import (
    _MIN_SEGMENT,
    _Image,
    _Judge,
    _Model,
    _model,
    _Object,
    _objects,
    _Scene,
    _segments,
)
from toolbox.errors import ToolboxError

__all__ = [
    "GOOD_DEPTH_M",
    "GOOD_IOU",
    "MAX_SEEN_THROUGH",
    "PoseFit",
    "mesh_symmetries",
    "refine_poses",
]

GOOD_IOU = 0.8  # silhouette IoU below this: the pose does not explain the object's segment
GOOD_DEPTH_M = 0.004  # [m] median depth residual above this: the surface is off
MAX_SEEN_THROUGH = 0.1  # fraction of drawn pixels where the camera sees past the object

_TARGET_WIDTH = 320  # [px] working image width the default `scale` aims at
_STEP_T = 0.008  # [m] first translation step of the pattern search
_STEP_R = np.radians(8.0)  # [rad] first rotation step
_MIN_STEP_T = 0.0005  # [m] the search stops below this translation step
_COARSE_STEP_T = 0.002  # [m] hypotheses are compared once their steps are this small
_SWEEP_STEP_T = 0.002  # [m] first steps of later sweeps (the pose is already close)
_SWEEP_STEP_R = np.radians(2.0)
_FLOOR = -0.003  # [m] no point of an object may sink deeper into the table (z = 0)
_CENTRING = 2  # moves of each hypothesis onto its segment's centroid before the search
_PRUNE, _PRUNE_AFTER = 0.25, 4  # a hypothesis this much costlier after this many steps stops
_KEEP_HYPOTHESES = 2  # hypotheses refined to the finest step
_HYPOTHESIS_MARGIN = 0.1  # … when their cost is within this of the best


@dataclass(frozen=True, kw_only=True)
class PoseFit:
    """One refined object and how well the observation supports it.

    Attributes:
        id, mesh: the record's id and mesh key.
        pose: refined `T_world_object` (4, 4) [m].
        cost: the score minimised, in [0, 1], 0 perfect: per pixel of the union of drawn
            object and segment, (depth residual / 8 mm)² on the segment, 1 for a segment
            pixel not drawn, 0.5–1 for a drawn pixel off the segment.
        iou: silhouette IoU of the drawn visible object and its segment.
        depth_residual_m: median |drawn − observed depth| [m] on the segment (NaN: none).
        seen_through: fraction of the drawn pixels that are off the segment and where the
            camera sees more than 8 mm past the object.
        pixels: segment pixels at the working resolution; 0: not seen, the input pose kept,
            `good` False, `hypothesis` "unseen".
        drawn_pixels: working pixels where the object is drawn in front of the others.
        good: iou ≥ GOOD_IOU, depth_residual_m ≤ GOOD_DEPTH_M, seen_through ≤
            MAX_SEEN_THROUGH.
        hypothesis: the winner: "given", "yaw+90", "flip yaw+180", … (the turn of the input
            pose about the vertical through its centre it started from).
        hypotheses: (label, cost) of every hypothesis tried.
        scale: the working image is the observation reduced `scale` times.
    """

    id: str
    mesh: str
    pose: np.ndarray
    cost: float
    iou: float
    depth_residual_m: float
    seen_through: float
    pixels: int
    drawn_pixels: int
    good: bool
    hypothesis: str
    hypotheses: tuple[tuple[str, float], ...]
    scale: int

    def record(self) -> dict:
        """The refined record `{"id", "mesh", "pose"}`."""
        return {"id": self.id, "mesh": self.mesh, "pose": self.pose.copy()}


def refine_poses(
    observation: Mapping,
    meshes: Mapping[str, object],
    records: Sequence[Mapping],
    *,
    camera: dict | None = None,
    segments: Mapping[str, object] | None = None,
    colors: Mapping[str, Sequence[float]] | None = None,
    dof: str = "planar",
    hypotheses: str = "symmetric",
    sweeps: int = 2,
    iterations: int = 40,
    max_shift: float = 0.04,
    scale: int | None = None,
) -> list[PoseFit]:
    """Refine rough object poses against an RGB-D observation, jointly and occlusion-aware.

    Pass every object, unseen ones too (they hide others). Objects with a segment of 3 or more
    working pixels are refined; the others keep their pose. Hypotheses: the input pose turned
    by 0, 90, 180, 270 degrees about the vertical through its centre, less those its mesh's
    symmetry makes identical (a cube: 45 degrees instead), each also upside down with
    `hypotheses="flips"`. The search steps start at 8 mm and 8 degrees and halve to 0.5 mm;
    no object moves more than `max_shift` or sinks more than 3 mm below z = 0. The start must
    overlap the object in the image (it corrects about ±20 mm, ±30 degrees and quarter
    turns); the camera's calibration error stays in the result.

    Args:
        observation: {"rgb" (H, W, 3) uint8, "depth" (H, W) [m], "camera"}.
        meshes: {mesh key: trimesh.Trimesh}.
        records: [{"id", "mesh", "pose" (4, 4)}], rough; ids unique.
        camera: the camera the records were estimated with (e.g. `level_camera_on_table`'s);
            None: observation["camera"].
        segments: {id: (H, W) bool mask of the object's visible pixels}; an id missing keeps
            its pose. None: colour segments, one per hue peak of the saturated pixels (hues 8
            degrees apart or more), matched to objects by `colors`.
        colors: {id: (r, g, b) 0–255}: a peak goes to the object of the nearest hue (within
            30 degrees). None: to the object whose input pose draws most of it, which can swap
            two neighbours whose starts overlap. Grey or same-coloured objects need `segments`.
        dof: "planar" (x, y, z, yaw: resting objects keep their tilt) or "full" (6 DoF).
        hypotheses: "given", "symmetric" (the distinct quarter turns) or "flips".
        sweeps: passes over all objects; later ones polish against the others' new poses.
        iterations: most search steps per object, hypothesis and pass.
        max_shift: [m] largest move from the input position.
        scale: the working image is the observation reduced this many times; None: width //
            320.

    Returns:
        One `PoseFit` per record, in order; `fit.record()` is the refined record.

    Raises:
        ToolboxError: unknown mesh key, duplicate ids, bad pose, colour, `dof` or
            `hypotheses`, images or segments not matching the camera.
    """
    if dof not in _DOF_AXES:
        raise ToolboxError(f"unknown dof {dof!r}; known: {', '.join(_DOF_AXES)}")
    if hypotheses not in _HYPOTHESES:
        raise ToolboxError(f"unknown hypotheses {hypotheses!r}; known: {', '.join(_HYPOTHESES)}")
    if int(sweeps) < 1 or int(iterations) < 1 or not max_shift > 0:
        raise ToolboxError("sweeps and iterations must be >= 1 and max_shift > 0")
    cam = observation.get("camera") if camera is None else camera
    if not isinstance(cam, dict):
        raise ToolboxError("no camera: pass camera= or an observation with 'camera'")
    K, T_wc = camera_matrices(cam)
    width, height = camera_size(cam)
    if scale is None:
        scale = max(1, width // _TARGET_WIDTH)
    if int(scale) < 1:
        raise ToolboxError(f"scale must be >= 1, got {scale}")
    image = _Image(observation, cam, K, T_wc, int(scale))
    objects = _objects(records, meshes)
    masks = _segments(segments, colors, image, objects, width, height)
    for obj, mask in zip(objects, masks, strict=True):
        obj.segment = mask
    scene = _Scene(image, objects)
    order = [int(i) for i in np.argsort([-o.segment.sum() for o in objects], kind="stable")]
    for sweep in range(int(sweeps)):
        for i in order:
            obj = objects[i]
            if obj.segment.sum() < _MIN_SEGMENT:
                continue
            _refine_object(
                scene, i, dof, hypotheses if sweep == 0 else None, int(iterations), float(max_shift)
            )
    return [_fit(scene, i) for i in range(len(objects))]


def mesh_symmetries(mesh, *, tolerance: float = 1e-3) -> list[np.ndarray]:
    """The rotations (4, 4) among the 24 that permute the mesh's bounding-box axes (about the
    box centre) that map its vertices onto its vertices within `tolerance` × the box
    diagonal, identity first: 24 for a cube, 4 for a box, 1 for an L-shape. The poses `T` and
    `T @ S` look the same."""
    model = _model(mesh)
    return [S.copy() for S in model.symmetries(tolerance)]


# -- internals -------------------------------------------------------------------------------

_DOF_AXES = {"planar": ("x", "y", "z", "rz"), "full": ("x", "y", "z", "rx", "ry", "rz")}
_HYPOTHESES = ("given", "symmetric", "flips")


# -- search ----------------------------------------------------------------------------------


def _turn(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    R = np.eye(3)
    j, k = [(1, 2), (2, 0), (0, 1)][axis]
    R[j, j], R[j, k], R[k, j], R[k, k] = c, -s, s, c
    return R


def _about_centre(T: np.ndarray, R: np.ndarray, model: _Model) -> np.ndarray:
    """T turned by the world rotation R about the object's box centre."""
    c = T[:3, :3] @ model.centre + T[:3, 3]
    out = T.copy()
    out[:3, :3] = R @ T[:3, :3]
    out[:3, 3] = R @ (T[:3, 3] - c) + c
    return out


def _start_hypotheses(obj: _Object, kind: str) -> list[tuple[str, np.ndarray]]:
    """(label, pose) of the distinct hypotheses around the input pose: the quarter turns about
    the vertical through its centre (and each flipped), and the eighth turn when a quarter turn
    looks the same (a cube, a square pillar standing: 45 degrees is then the farthest off)."""
    if kind == "given":
        return [("given", obj.pose.copy())]
    turns = [("given" if k == 0 else f"yaw+{90 * k}", _turn(2, k * np.pi / 2)) for k in range(4)]
    out = _distinct(obj, turns, kind)
    if not any(name == "yaw+90" for name, _ in out):
        out += _distinct(obj, [("yaw+45", _turn(2, np.pi / 4))], kind, out)
    return out


def _distinct(obj: _Object, turns, kind: str, kept=()) -> list[tuple[str, np.ndarray]]:
    """The turned input poses (and flipped ones for "flips") that look different from each
    other and from `kept`: T and A differ unless A⁻¹ T is a symmetry of the mesh."""
    if kind == "flips":
        turns = [*turns, *((f"flip {name}", R @ _turn(0, np.pi)) for name, R in turns)]
    out: list[tuple[str, np.ndarray]] = []
    for name, R in turns:
        T = _about_centre(obj.pose, R, obj.model)
        if not any(obj.model.same(np.linalg.inv(A) @ T) for _, A in (*kept, *out)):
            out.append((name, T))
    return out


def _step_poses(
    T: np.ndarray, model: _Model, axes: Sequence[str], basis: np.ndarray, st: float, sr: float
):
    """The 2 × len(axes) poses one step away from T along each axis, both ways; translations
    along the columns of `basis` (3, 3)."""
    out = []
    for ax in axes:
        for sign in (1.0, -1.0):
            if ax in ("x", "y", "z"):
                P = T.copy()
                P[:3, 3] += sign * st * basis[:, "xyz".index(ax)]
            else:
                P = _about_centre(T, _turn("xyz".index(ax[1]), sign * sr), model)
            out.append(P)
    return out


def _view_basis(image: _Image, T: np.ndarray, model: _Model) -> np.ndarray:
    """Translation directions (3, 3) [columns]: across the image (right, down) and along the
    viewing ray through the object's centre. The image pins the first two and depth the third,
    so a search along them is not trapped by a move the silhouette and the depth both oppose
    one axis at a time (world x, y and z each change both)."""
    T_wc = np.linalg.inv(image.T_cw)
    ray = T[:3, :3] @ model.centre + T[:3, 3] - T_wc[:3, 3]
    w = ray / np.linalg.norm(ray)
    u = T_wc[:3, 0] - (T_wc[:3, 0] @ w) * w
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(w, u), w], axis=1)


def _lift(poses: np.ndarray, model: _Model) -> None:
    """Raise poses (b, 4, 4) in place whose lowest point is deeper than `_FLOOR` in the table."""
    low = (model.vertices @ poses[:, 2, :3].T).min(axis=0) + poses[:, 2, 3]
    poses[:, 2, 3] += np.maximum(_FLOOR - low, 0.0)


def _search(
    scene: _Scene,
    i: int,
    starts: list[np.ndarray],
    axes: Sequence[str],
    iterations: int,
    max_shift: float,
    step: tuple[float, float],
    min_step: float,
) -> list[tuple[float, np.ndarray]]:
    """Compass search of each start pose at once (one batch per iteration): (cost, pose).

    A start whose cost trails the best by more than `_PRUNE` after `_PRUNE_AFTER` iterations
    stops; a move repeated in the same direction doubles its step (up to the first step)."""
    obj = scene.objects[i]
    judge = _Judge(scene, i)
    basis = _view_basis(scene.image, starts[0], obj.model)
    first = np.stack(starts)
    _lift(first, obj.model)
    costs = judge(first)[0]
    for _ in range(_CENTRING):  # a cheap first move: what is drawn onto the segment
        moved = judge.centred(first, basis)
        _lift(moved, obj.model)
        c, shift = judge(moved)
        better = (c < costs) & (shift <= max_shift)
        first[better], costs[better] = moved[better], c[better]
    poses, costs = list(first), list(costs)
    steps = [list(step) for _ in starts]
    last = [-1] * len(starts)  # the move each start made last
    n = 2 * len(axes)
    for it in range(iterations):
        best_cost = min(costs)
        active = [
            k
            for k in range(len(poses))
            if steps[k][0] >= min_step and (it < _PRUNE_AFTER or costs[k] <= best_cost + _PRUNE)
        ]
        if not active:
            break
        trial = np.stack(
            [P for k in active for P in _step_poses(poses[k], obj.model, axes, basis, *steps[k])]
        )
        _lift(trial, obj.model)
        c, shift = judge(trial)
        c = np.where(shift > max_shift, np.inf, c)
        for j, k in enumerate(active):
            block = c[j * n : (j + 1) * n]
            best = int(np.argmin(block))
            if block[best] < costs[k] - 1e-9:
                poses[k], costs[k] = trial[j * n + best], float(block[best])
                if best == last[k] and steps[k][0] < step[0]:
                    steps[k] = [steps[k][0] * 2, steps[k][1] * 2]
                last[k] = best
            else:
                steps[k] = [steps[k][0] / 2, steps[k][1] / 2]
                last[k] = -1
    return [(float(c), P) for c, P in zip(costs, poses, strict=True)]


def _refine_object(
    scene: _Scene, i: int, dof: str, hypotheses: str | None, iterations: int, max_shift: float
) -> None:
    obj = scene.objects[i]
    axes = _DOF_AXES[dof]
    if hypotheses is None:  # a later pass: polish the current pose
        ((_, T),) = _search(
            scene,
            i,
            [obj.pose],
            axes,
            iterations,
            max_shift,
            (_SWEEP_STEP_T, _SWEEP_STEP_R),
            _MIN_STEP_T,
        )
        obj.pose = T
        scene.update(i)
        return
    hyps = _start_hypotheses(obj, hypotheses)
    coarse = _search(
        scene,
        i,
        [T for _, T in hyps],
        axes,
        iterations,
        max_shift,
        (_STEP_T, _STEP_R),
        _COARSE_STEP_T,
    )
    best = min(c for c, _ in coarse)
    ranked = sorted(range(len(hyps)), key=lambda k: (coarse[k][0], k))
    keep = [k for k in ranked[:_KEEP_HYPOTHESES] if coarse[k][0] <= best + _HYPOTHESIS_MARGIN]
    fine = _search(
        scene,
        i,
        [coarse[k][1] for k in keep],
        axes,
        iterations,
        max_shift,
        (_COARSE_STEP_T, _COARSE_STEP_T / _STEP_T * _STEP_R),
        _MIN_STEP_T,
    )
    results = {k: fine[j] for j, k in enumerate(keep)}
    tried = [(name, results.get(k, coarse[k])[0]) for k, (name, _) in enumerate(hyps)]
    win = min(keep, key=lambda k: (results[k][0], k))
    obj.pose = results[win][1]
    obj.hypothesis = hyps[win][0]
    obj.tried = tried
    scene.update(i)


def _fit(scene: _Scene, i: int) -> PoseFit:
    obj = scene.objects[i]
    n_seg = int(obj.segment.sum())
    if n_seg < _MIN_SEGMENT:
        return PoseFit(
            id=obj.id,
            mesh=obj.mesh,
            pose=obj.pose.copy(),
            cost=1.0,
            iou=0.0,
            depth_residual_m=float("nan"),
            seen_through=0.0,
            pixels=n_seg,
            drawn_pixels=0,
            good=False,
            hypothesis="unseen",
            hypotheses=(),
            scale=scene.image.scale,
        )
    t = _Judge(scene, i)(obj.pose[None], details=True)
    iou, res, through = float(t.iou[0]), float(t.residual[0]), float(t.through[0])
    good = iou >= GOOD_IOU and res <= GOOD_DEPTH_M and through <= MAX_SEEN_THROUGH
    return PoseFit(
        id=obj.id,
        mesh=obj.mesh,
        pose=obj.pose.copy(),
        cost=float(t.cost[0]),
        iou=iou,
        depth_residual_m=res,
        seen_through=through,
        pixels=n_seg,
        drawn_pixels=int(t.drawn[0]),
        good=bool(good),
        hypothesis=obj.hypothesis,
        hypotheses=tuple(obj.tried),
        scale=scene.image.scale,
    )
