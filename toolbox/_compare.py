"""Render-and-compare for `toolbox.refine` (private): the working image, the scene of drawn
objects, the objects' segments and the score of candidate poses.

Design rule: everything is computed on the observation reduced `scale` times and gathered at
the pixels a candidate draws (flat whole-image arrays), so a batch of candidate poses costs
one rasterisation and a few vectorised gathers.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from toolbox._common import camera_size, check_image
from toolbox._raster import Window, rasterise
from toolbox.errors import ToolboxError
from toolbox.segmentation import _hue_peaks

_DEPTH_TRUNCATION = 0.008  # [m] a depth residual counts fully from here (noise: σ ≤ 3 mm)
_DEPTH_EDGE = 0.01  # [m] a reduced pixel whose full-resolution depths span more is invalid
_HUE_TOLERANCE = 8.0  # [deg] automatic segments: hue peaks this close merge; pixels this close
# to a peak are its (the domains' hues lie 19 degrees apart or more)
_SAT_MIN, _VAL_MIN = 0.3, 0.1  # automatic segments: colourful pixels
_COLOUR_MATCH = 30.0  # [deg] automatic segments with colors: farthest peak from a colour's hue
_REACH_WEIGHT = 0.25  # automatic segments: a peak pixel within reach counts this much
_MIN_SEGMENT = 3  # [working px] fewer: the object is not seen and keeps its pose
_MODELS: dict[tuple[int, int], _Model] = {}


class _Model:
    """A mesh prepared for drawing: vertices, faces, box centre, symmetry test."""

    def __init__(self, mesh) -> None:
        try:
            V = np.asarray(mesh.vertices, dtype=float)
            F = np.asarray(mesh.faces, dtype=np.int64)
        except AttributeError:
            raise ToolboxError("a mesh must be a trimesh.Trimesh (vertices and faces)") from None
        if V.ndim != 2 or V.shape[1] != 3 or len(F) == 0 or not np.all(np.isfinite(V)):
            raise ToolboxError("a mesh has no faces or bad vertices")
        self.mesh = mesh  # keeps id(mesh) from being reused while cached
        self.vertices, self.faces = V, F
        lo, hi = V.min(axis=0), V.max(axis=0)
        self.centre = (lo + hi) / 2
        self.radius = float(np.linalg.norm(hi - lo)) / 2
        self.cull = bool(getattr(mesh, "is_watertight", False)) and bool(
            getattr(mesh, "is_winding_consistent", False)
        )
        self._tree = cKDTree(V)
        self._symmetries: dict[float, list[np.ndarray]] = {}

    def same(self, S: np.ndarray, tolerance: float = 1e-3) -> bool:
        """Whether the object-frame transform S maps the mesh onto itself."""
        moved = self.vertices @ S[:3, :3].T + S[:3, 3]
        d, _ = self._tree.query(moved)
        return bool(d.max() <= tolerance * 2 * self.radius)

    def symmetries(self, tolerance: float) -> list[np.ndarray]:
        if tolerance not in self._symmetries:
            out = []
            for R in _axis_permutations():
                S = np.eye(4)
                S[:3, :3], S[:3, 3] = R, self.centre - R @ self.centre
                if self.same(S, tolerance):
                    out.append(S)
            self._symmetries[tolerance] = out
        return self._symmetries[tolerance]


def _axis_permutations() -> list[np.ndarray]:
    """The 24 proper signed permutation matrices, identity first."""
    out = []
    for perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1), (0, 2, 1), (2, 1, 0), (1, 0, 2)):
        for signs in np.ndindex(2, 2, 2):
            R = np.zeros((3, 3))
            R[np.arange(3), perm] = [1 - 2 * s for s in signs]
            if np.linalg.det(R) > 0:
                out.append(R)
    return out


def _model(mesh) -> _Model:
    try:
        key = (id(mesh), hash(mesh))
    except TypeError:
        key = (id(mesh), 0)
    model = _MODELS.get(key)
    if model is None:
        if len(_MODELS) > 64:
            _MODELS.clear()
        model = _MODELS[key] = _Model(mesh)
    return model


@dataclass(kw_only=True)
class _Object:
    id: str
    mesh: str
    model: _Model
    pose: np.ndarray  # current T_world_object
    start: np.ndarray  # the input pose
    segment: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), bool))
    hypothesis: str = "given"
    tried: list[tuple[str, float]] = field(default_factory=list)


def _objects(records: Sequence[Mapping], meshes: Mapping[str, object]) -> list[_Object]:
    out, seen = [], set()
    for k, r in enumerate(records):
        try:
            rid, key, pose = r["id"], r["mesh"], r["pose"]
        except (KeyError, TypeError):
            raise ToolboxError(f"records[{k}] must be a dict with 'id', 'mesh', 'pose'") from None
        if key not in meshes:
            known = ", ".join(sorted(map(str, meshes))) or "(none)"
            raise ToolboxError(f"records[{k}].mesh {key!r} is not a known mesh; known: {known}")
        if rid in seen:
            raise ToolboxError(f"records[{k}].id {rid!r} appears twice")
        seen.add(rid)
        T = np.array(pose, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ToolboxError(f"records[{k}].pose must be a finite (4, 4) matrix")
        out.append(_Object(id=rid, mesh=key, model=_model(meshes[key]), pose=T, start=T.copy()))
    return out


class _Image:
    """The observation reduced `scale` times: depth, colour, intrinsics of the small image."""

    def __init__(self, observation: Mapping, camera: dict, K, T_wc, scale: int) -> None:
        width, height = camera_size(camera)
        try:
            rgb, depth = observation["rgb"], observation["depth"]
        except (KeyError, TypeError):
            raise ToolboxError("observation must have 'rgb' and 'depth'") from None
        D = check_image(depth, camera, "depth", ndim=2).astype(np.float32)
        C = check_image(rgb, camera, "rgb", ndim=3)
        s = scale
        h, w = height // s, width // s
        self.scale, self.width, self.height = s, w, h
        D = np.where(np.isfinite(D) & (D > 0), D, 0.0).astype(np.float32)[: h * s, : w * s]
        valid = (D > 0).astype(np.float32)
        area = cv2.INTER_AREA  # exact block means for an integer factor
        n = cv2.resize(valid, (w, h), interpolation=area)
        total = cv2.resize(D, (w, h), interpolation=area)
        block = np.ones((s, s), np.uint8)  # anchored at (0, 0): the block right and down
        hi = cv2.dilate(D, block, anchor=(0, 0))[::s, ::s]
        lo = cv2.erode(np.where(D > 0, D, np.float32(1e9)), block, anchor=(0, 0))[::s, ::s]
        ok = (n >= 0.5) & (hi - lo <= _DEPTH_EDGE)
        self.depth = np.where(ok, total / np.maximum(n, 1e-6), 0.0).astype(float)  # 0 invalid
        rgb_small = cv2.resize(
            np.ascontiguousarray(C[: h * s, : w * s, :3]), (w, h), interpolation=area
        )
        self.rgb = rgb_small.astype(float)
        # the reduced pixel (u', v') averages full-resolution pixels whose centre is at
        # s u' + (s - 1) / 2
        self.K = np.array(K, dtype=float)
        self.K[:2] /= s
        self.K[0, 2] = (K[0, 2] - (s - 1) / 2) / s
        self.K[1, 2] = (K[1, 2] - (s - 1) / 2) / s
        self.T_cw = np.linalg.inv(T_wc)

    def reduce_mask(self, mask: np.ndarray) -> np.ndarray:
        s, h, w = self.scale, self.height, self.width
        m = mask[: h * s, : w * s].reshape(h, s, w, s)
        return 2 * m.sum(axis=(1, 3)) >= s * s

    def whole(self) -> Window:
        return Window(u0=0, v0=0, width=self.width, height=self.height)


class _Scene:
    """Every object's depth drawn over the whole working image, kept current, as an occluder:
    only where the observation does not contradict it (the camera sees nothing farther there
    by more than the depth truncation), so that an object still posed wrongly hides nothing
    where the camera sees past it."""

    def __init__(self, image: _Image, objects: list[_Object]) -> None:
        self.image, self.objects = image, objects
        self.occluders = np.stack([self._occluder(o) for o in objects])

    def update(self, i: int) -> None:
        self.occluders[i] = self._occluder(self.objects[i])

    def _occluder(self, obj: _Object) -> np.ndarray:
        Z = _draw(self.image, obj.model, obj.pose[None], self.image.whole())[0]
        D = self.image.depth
        return np.where((D <= 0) | (Z <= D + _DEPTH_TRUNCATION), Z, np.inf)


def _slices(window: Window) -> tuple[slice, slice]:
    return (
        slice(window.v0, window.v0 + window.height),
        slice(window.u0, window.u0 + window.width),
    )


def _segments(
    segments: Mapping[str, object] | None,
    colors: Mapping[str, Sequence[float]] | None,
    image: _Image,
    objects: list[_Object],
    width: int,
    height: int,
) -> list[np.ndarray]:
    """Each object's segment at the working resolution."""
    shape = (image.height, image.width)
    if segments is not None:
        if not isinstance(segments, Mapping):
            raise ToolboxError("segments must be a dict {record id: (H, W) bool mask}")
        out = []
        for o in objects:
            m = segments.get(o.id)
            if m is None:
                out.append(np.zeros(shape, bool))
                continue
            a = np.asarray(m)
            if a.shape != (height, width):
                raise ToolboxError(
                    f"segments[{o.id!r}] has shape {a.shape} but the camera is {height}x{width}"
                )
            out.append(image.reduce_mask(a.astype(bool)))
        return out
    if colors is not None and not isinstance(colors, Mapping):
        raise ToolboxError("colors must be a dict {record id: (r, g, b) 0-255}")
    return _colour_segments(image, objects, colors)


def _colour_segments(
    image: _Image, objects: list[_Object], colors: Mapping[str, Sequence[float]] | None
) -> list[np.ndarray]:
    """Automatic segments: the image's hue peaks are matched one to one with the objects; an
    object's segment is its peak's pixels within its reach. With `colors`, a peak goes to the
    object whose colour's hue is nearest (at most `_COLOUR_MATCH` away), else to the object
    whose input pose draws most of its pixels (plus a quarter of those within its reach)."""
    shape = (image.height, image.width)
    out = [np.zeros(shape, bool) for _ in objects]
    hsv = cv2.cvtColor((image.rgb / 255.0).astype(np.float32), cv2.COLOR_RGB2HSV)
    hue, sat, val = hsv[..., 0].astype(float), hsv[..., 1], hsv[..., 2]
    colourful = (sat >= _SAT_MIN) & (val >= _VAL_MIN)
    if not colourful.any():
        return out
    peaks = _hue_peaks(hue[colourful], sat[colourful], _HUE_TOLERANCE)
    diff = np.abs((hue[..., None] - peaks + 180.0) % 360.0 - 180.0)  # (h, w, peaks)
    label = np.where(colourful & (diff.min(axis=2) <= _HUE_TOLERANCE), diff.argmin(axis=2), -1)
    reach = [_reach(image, o) for o in objects]
    n = len(peaks)
    peak_of = np.full(len(objects), -1)
    if colors is not None:
        far = np.full((len(objects), n), 1e3)  # hue distance [deg], 1e3: no colour given
        for i, o in enumerate(objects):
            if o.id in colors:
                h = _hue_of(colors[o.id], o.id)
                if h is not None:
                    far[i] = np.abs((peaks - h + 180.0) % 360.0 - 180.0)
        rows, cols = linear_sum_assignment(far)
        for i, p in zip(rows, cols, strict=True):
            if far[i, p] <= _COLOUR_MATCH:
                peak_of[i] = p
    else:
        depths = np.stack([_draw(image, o.model, o.pose[None], image.whole())[0] for o in objects])
        drawn = np.where(np.isfinite(depths.min(axis=0)), depths.argmin(axis=0), -1)
        inside = np.array(
            [
                np.bincount(label[(drawn == i) & (label >= 0)], minlength=n)
                for i in range(len(objects))
            ]
        )  # (objects, peaks)
        near = np.array([np.bincount(label[r & (label >= 0)], minlength=n) for r in reach])
        score = inside + _REACH_WEIGHT * near
        rows, cols = linear_sum_assignment(-score)  # one peak per object, most pixels in all
        for i, p in zip(rows, cols, strict=True):
            if score[i, p] >= _MIN_SEGMENT:
                peak_of[i] = p
    for i, p in enumerate(peak_of):
        if p >= 0:
            out[i] = (label == p) & reach[i]
    return out


def _hue_of(color: Sequence[float], rid: str) -> float | None:
    """Hue [deg] of an RGB colour 0–255; None for a grey (saturation under `_SAT_MIN`)."""
    c = np.asarray(color, dtype=float).reshape(-1)
    if c.shape not in ((3,), (4,)) or not np.all((c >= 0) & (c <= 255)):
        raise ToolboxError(f"colors[{rid!r}] must be RGB in 0..255, got {color!r}")
    hsv = cv2.cvtColor((c[None, None, :3] / 255.0).astype(np.float32), cv2.COLOR_RGB2HSV)[0, 0]
    return float(hsv[0]) if hsv[1] >= _SAT_MIN else None


def _reach(image: _Image, obj: _Object) -> np.ndarray:
    """Pixels the object could cover from its input pose (its bounding sphere, grown by 4 cm)."""
    win = _sphere_window(image, obj.start, obj.model, 0.04)
    out = np.zeros((image.height, image.width), bool)
    if win is not None:
        sl = _slices(win)
        out[sl] = True
    return out


def _sphere_window(image: _Image, pose: np.ndarray, model: _Model, grow: float) -> Window | None:
    c = image.T_cw @ np.append(pose[:3, :3] @ model.centre + pose[:3, 3], 1.0)
    r = model.radius + grow
    z = c[2] - r
    if z <= 1e-3:
        return image.whole()
    u = image.K[0, 0] * c[0] / c[2] + image.K[0, 2]
    v = image.K[1, 1] * c[1] / c[2] + image.K[1, 2]
    ru, rv = image.K[0, 0] * r / z, image.K[1, 1] * r / z
    return _clip(image, u - ru, v - rv, u + ru, v + rv)


def _clip(image: _Image, u0, v0, u1, v1) -> Window | None:
    a, b = max(int(np.floor(u0)), 0), max(int(np.floor(v0)), 0)
    c, d = min(int(np.ceil(u1)), image.width - 1), min(int(np.ceil(v1)), image.height - 1)
    if c < a or d < b:
        return None
    return Window(u0=a, v0=b, width=c - a + 1, height=d - b + 1)


def _camera_vertices(image: _Image, model: _Model, poses: np.ndarray) -> np.ndarray:
    """The mesh's vertices (b, n, 3) in the camera frame for poses (b, 4, 4)."""
    T = image.T_cw @ poses  # (b, 4, 4) T_camera_object
    return model.vertices @ T[:, :3, :3].transpose(0, 2, 1) + T[:, None, :3, 3]


def _draw(image: _Image, model: _Model, poses: np.ndarray, window: Window) -> np.ndarray:
    """Depth (b, h, w) of the mesh at poses (b, 4, 4) in the window, inf where empty."""
    V = _camera_vertices(image, model, poses)
    return rasterise(V, model.faces, image.K, window, cull=model.cull)


# -- scoring ---------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class _Terms:
    cost: np.ndarray  # (b,)
    iou: np.ndarray
    residual: np.ndarray  # median |r| [m], NaN when none
    through: np.ndarray
    drawn: np.ndarray


class _Judge:
    """Scores poses of object i against the observation, the other objects held where they
    are (flat whole-image arrays, gathered at the pixels a candidate draws)."""

    def __init__(self, scene: _Scene, i: int) -> None:
        image = scene.image
        self.image, self.model = image, scene.objects[i].model
        self.others = (
            np.delete(scene.occluders, i, axis=0).min(axis=0).ravel()
            if len(scene.objects) > 1
            else np.full(image.width * image.height, np.inf)
        )
        S = scene.objects[i].segment
        self.segment = S.ravel()
        self.near_segment = cv2.dilate(S.astype(np.uint8), np.ones((3, 3), np.uint8)).ravel() > 0
        self.n_segment = int(S.sum())
        self.depth = image.depth.ravel()
        start = scene.objects[i].start
        self.origin = start[:3, :3] @ self.model.centre + start[:3, 3]
        v, u = np.nonzero(S)
        seen = self.depth[self.segment]
        seen = seen[seen > 0]
        self.seg_mean = np.array(  # (u, v, depth [m]) of the segment
            [u.mean(), v.mean(), seen.mean() if len(seen) else np.nan] if len(u) else [np.nan] * 3
        )

    def drawn(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The pixels where poses (b, 4, 4) draw the object in front of the others: candidate
        index, whole-image flat pixel index and depth [m], each (m,)."""
        image, model = self.image, self.model
        V = _camera_vertices(image, model, poses)  # (b, n, 3)
        z = np.maximum(V[..., 2], 1e-6)
        u = image.K[0, 0] * V[..., 0] / z + image.K[0, 1] * V[..., 1] / z + image.K[0, 2]
        v = image.K[1, 1] * V[..., 1] / z + image.K[1, 2]
        win = _clip(image, u.min() - 1, v.min() - 1, u.max() + 1, v.max() + 1)
        if win is None:
            k = np.zeros(0, dtype=np.int64)
            g = k
            Zk = np.zeros(0)
        else:
            Z = rasterise(V, model.faces, image.K, win, cull=model.cull)  # (b, h, w)
            flat = np.flatnonzero(np.isfinite(Z))
            k, p = np.divmod(flat, win.width * win.height)
            pv, pu = np.divmod(p, win.width)
            g = (pv + win.v0) * image.width + pu + win.u0  # whole-image pixel
            Zk = Z.ravel()[flat]
        vis = Zk < self.others[g]
        return k[vis], g[vis], Zk[vis]

    def centred(self, poses: np.ndarray, basis: np.ndarray) -> np.ndarray:
        """Poses (b, 4, 4) moved so that what they draw has the segment's centroid and mean
        depth: across the image along basis[:, 0] and [:, 1], in depth along basis[:, 2]."""
        image = self.image
        k, g, Zk = self.drawn(poses)
        b = len(poses)
        n = np.bincount(k, minlength=b)
        out = poses.copy()
        if self.n_segment == 0:
            return out
        v, u = np.divmod(g, image.width)
        sums = np.stack([np.bincount(k, weights=w, minlength=b) for w in (u, v, Zk)], axis=1)
        mean = sums / np.maximum(n, 1)[:, None]
        z = mean[:, 2]
        across = (self.seg_mean[:2] - mean[:, :2]) * z[:, None] / np.diag(image.K)[:2]
        along = np.where(np.isfinite(self.seg_mean[2]), self.seg_mean[2] - z, 0.0)
        shift = across @ basis[:, :2].T + along[:, None] * basis[:, 2]
        out[:, :3, 3] += np.where(n[:, None] > 0, shift, 0.0)
        return out

    def __call__(self, poses: np.ndarray, *, details: bool = False):
        """Cost (b,) of the poses (b, 4, 4); with `details`, all the terms (`_Terms`)."""
        model = self.model
        b = len(poses)
        k, g, Zk = self.drawn(poses)
        D, S, Sd = self.depth[g], self.segment[g], self.near_segment[g]
        valid = D > 0
        r = Zk - D
        a = np.abs(r)
        tau = _DEPTH_TRUNCATION
        excused = valid & (r > tau) & ~Sd  # something nearer that no record explains
        through = valid & (r < -tau) & ~Sd  # the camera sees past the object
        # squared: residuals of the depth noise and the calibration (a few mm) cost little
        q = np.minimum(a / tau, 1.0) ** 2
        c = np.where(
            Sd,
            np.where(valid, q, 0.0),
            np.where(valid, np.where(a <= tau, 0.5 + 0.5 * q, 1.0), 0.5),
        )
        counted = ~excused
        hits = np.bincount(k, weights=S, minlength=b)
        extra = np.bincount(k, weights=counted & ~S, minlength=b)
        # segment pixels: where drawn, the depth residual (in c); where not, a full miss
        num = np.bincount(k, weights=c * counted, minlength=b) + self.n_segment - hits
        union = np.maximum(self.n_segment + extra, 1)
        centre = poses[:, :3, :3] @ model.centre + poses[:, :3, 3]
        cost = num / union
        if not details:
            return cost, np.linalg.norm(centre - self.origin, axis=1)
        good = S & valid
        residual = np.array(
            [
                float(np.median(a[(k == j) & good])) if np.any((k == j) & good) else np.nan
                for j in range(b)
            ]
        )
        return _Terms(
            cost=cost,
            iou=hits / union,
            residual=residual,
            through=np.bincount(k, weights=through, minlength=b)
            / np.maximum(np.bincount(k, weights=counted, minlength=b), 1),
            drawn=np.bincount(k, minlength=b),
        )
