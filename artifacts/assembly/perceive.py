# Written by people (the RIVET team), not by a model: the hand-written reference `perceive`
# for the assembly domain, the level a model's program should reach. It uses numpy, scipy, cv2,
# trimesh and the toolbox's exact polyhedral geometry (toolbox.stability).
"""perceive(observation, meshes, camera) -> records: the 6D poses of the parts in one RGB-D image.

1. Colour: every part has its own hue; pixels are labelled by the nearest catalogue hue
   (saturated pixels only: the table and the shadows are grey), and thin lines of blended
   colour along silhouettes are opened away.
2. Hypotheses: a part rests in one of its stable poses (`toolbox.stable_poses`: the faces of
   its hull it can stand on), turned about the vertical. For each part, the resting pose it is
   built to stand in is tried first, from eight headings; its pose (x, y, z, yaw) is fitted by
   visibility-aware point-to-plane ICP: every observed point is matched to the nearest model
   surface point that faces the camera, so the visible front of a part is never matched to its
   hidden back. Other resting poses are tried only when the first fits badly.
3. Scoring by rendering: a hypothesis is judged by how well it explains its points and by
   what its camera-facing surface would hide — projected into the image, it must not lie in
   front of surfaces the camera sees behind it. Surface behind nearer objects is excused, so
   partly occluded parts are fitted from what shows.
4. Physics: parts are settled lowest first onto the table or onto the parts under them (exact
   convex-piece geometry, `toolbox.separation`), side-by-side overlaps from noise are pushed
   apart, and a part that would float or tip over must stand on something the camera cannot
   see: an unseen part of the right height is put under it, on the table or on a seen part's
   flat top (mirroring the visible one for a beam or an arch on two pillars). A part that is not seen and not needed to hold anything up
   is put where the camera cannot see it: behind a seen part, on the table, clear of the
   others (the task text: all eight are reported; where exactly is not scored).
5. Render-and-compare (`toolbox.refine_poses`): the seen parts are drawn together, so they hide
   each other, and moved until the drawing matches their colour segments and the depth. A part
   takes the refined pose where it explains the segment better than the pose it started from
   (the refiner's cost); a quarter or half turn only where the start explains it badly and the
   turn at least twice as well, or where the part shows more than a sliver and the turn
   explains it four times better (a block half hidden behind others, fitted across). A part
   still explained badly is searched again from the centre
   of its points (the ICP's pose can sit a part-length off, turned). A sliver (a few pixels)
   keeps its heading unless the refiner turns it far: it shows where the part is and which
   faces show, but a small turn moves its pixels no more than the calibration error does.
6. Centred loads: a beam or the arch rests centred on its two pillars. A pillar that shows
   only a sliver behind the other is tried at the mirror of the seen one through the load's
   centre, with its own heading and with the seen one's, and moved there where that explains
   its sliver as well.
"""

import hashlib

import cv2
import numpy as np
import trimesh
from scipy.spatial import cKDTree

from toolbox import (
    Shape,
    collisions,
    refine_poses,
    render_scene,
    separation,
    stable_poses,
    supports,
    unstable_objects,
)
from toolbox.vision import level_camera_on_table

PARTS = {  # id → (mesh key, hue of its colour as rendered [deg])
    "pillar_1": ("pillar", 4.0),
    "pillar_2": ("pillar", 32.0),
    "beam": ("beam", 224.0),
    "arch": ("arch", 51.0),
    "roof": ("roof", 131.0),
    "cylinder": ("cylinder", 277.0),
    "lblock": ("lblock", 185.0),
    "block": ("block", 335.0),
}
HUE_TOL = 11.0  # [deg]
SAT_MIN = 0.3
VAL_MIN = 0.1
MIN_PIXELS = 25  # fewer labelled pixels: the part is not seen
WEAK_PIXELS = 400  # fewer: its fit may be moved to where physics needs it
COARSE_POINTS = 80
FINE_POINTS = 200
SAMPLE_EDGE = 0.004  # model surface sampling [m]
TRUNCATE = 0.006  # residuals beyond this count as outliers [m]
SEEN_THROUGH = 0.008  # model surface this far in front of what the camera sees [m]
GRAZING = 0.25  # cosine between a surface and the view ray below which it is not judged
VIOLATION_WEIGHT = 0.02  # [m] per unit fraction of model surface seen through
VIOLATION_SEARCH = 0.0005  # [m] of score from free space above which a pose is slid clear
POOR_FIT = 0.0015  # [m] mean distance above which a pose is searched around
BAD_FIT = 0.004  # mean residual [m] above which other resting poses are tried
OTHER_POSE_PENALTY = 0.0015  # [m] prior for the part's own upright pose
SETTLE_RANGE = 0.03  # a part may drop or rise this much onto its support [m]
SETTLE_TOL = 0.01  # moving a part farther than this onto its support is suspect [m]
CONTEXT_SCORE = 0.0015  # a worse score: try the part where its neighbours suggest [m]
CONFLICT_DEPTH = 0.003  # parts interpenetrating deeper cannot both be right [m]
ALTERNATIVES = 5  # hypotheses weighed for a part in conflict
ALTERNATIVE_MARGIN = 0.003  # how much worse [m] an alternative may explain the image
WIDE_ANCHORS = 5
TIE = 0.0003  # hypotheses this close [m] explain the image equally well
SLIDE_STEP = 0.004  # [m]
FINE_ITERATIONS = 8
GRID_CELL = 0.0025  # [m]
GRID_MARGIN = 0.025  # [m]
NEIGHBOURS = 6
TURN_EVIDENCE = 0.1  # refiner cost above which a part's pose explains its segment badly
TURN_RATIO = 4  # a turn explaining a part's segment this many times better is taken
FEW_PIXELS = 40  # working pixels (`PoseFit.pixels`): a part showing fewer is a sliver
SMALL_TURN = np.radians(60)  # a turn a sliver cannot show
RESEARCH_SHIFT = 0.06  # [m] how far a part searched again may move from its points' centre
BEHIND = (0.05, 0.08, 0.11, 0.15)  # [m] from a seen part, away from the camera: hiding spots
SIGHT_SCALE = 4  # the hiding spot is tested on the image reduced this many times
MIRROR_SLACK = 0.02  # refiner cost a mirrored supporter may add to its sliver's fit
MIRROR_MIN = 0.003  # [m] a mirrored position nearer than this changes nothing
BOX_MARGIN = 4  # [px] around a part's pixels: its morphology sees nothing beyond

_CACHE = {}


def _key(mesh):
    v = np.ascontiguousarray(np.asarray(mesh.vertices, dtype=np.float64))
    f = np.ascontiguousarray(np.asarray(mesh.faces, dtype=np.int64))
    return hashlib.sha1(v.tobytes() + f.tobytes()).hexdigest()


class _Model:
    """A mesh prepared for fitting: surface samples with normals, resting poses, shape."""

    def __init__(self, mesh):
        v, f = trimesh.remesh.subdivide_to_size(
            np.asarray(mesh.vertices, float), np.asarray(mesh.faces, int), SAMPLE_EDGE
        )
        tri = v[f]
        self.samples = tri.mean(axis=1)  # (m, 3) object frame
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.normals = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        # nearest samples of every cell of a grid around the part: a lookup instead of a
        # tree query in the inner loop of the fit
        lo = self.samples.min(axis=0) - GRID_MARGIN
        shape = np.ceil((self.samples.max(axis=0) + GRID_MARGIN - lo) / GRID_CELL).astype(int)
        axes = [lo[a] + (np.arange(shape[a]) + 0.5) * GRID_CELL for a in range(3)]
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        _, near = cKDTree(self.samples).query(centres, k=NEIGHBOURS)
        self.grid_lo, self.grid_shape = lo, shape
        self.grid = near.reshape(-1, NEIGHBOURS).astype(np.int64)  # cells in C order
        self.grid_strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
        # each cell's nearest samples and their normals in one block: one gather per point
        self.cell_surface = np.hstack([self.samples, self.normals])[self.grid]
        self.shape = Shape.from_mesh(mesh)
        rests = stable_poses(self.shape)
        # the part's own upright pose first, then the others steadiest first
        rests.sort(key=lambda p: (not np.allclose(p.rotation, np.eye(3), atol=1e-6),))
        self.rests = [p.rotation for p in rests] or [np.eye(3)]
        pts = np.concatenate(self.shape.pieces)
        self.extent = np.ptp(pts, axis=0)
        self.centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
        self.lowest = {k: float((pts @ R.T)[:, 2].min()) for k, R in enumerate(self.rests)}
        self.highest = {k: float((pts @ R.T)[:, 2].max()) for k, R in enumerate(self.rests)}
        step = max(1, len(self.samples) // 400)
        self.probe = np.arange(0, len(self.samples), step)  # samples used for visibility


def _model(mesh):
    k = _key(mesh)
    if k not in _CACHE:
        _CACHE[k] = _Model(mesh)
    return _CACHE[k]


def _rz(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _pose(R, t):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


# -- colour --------------------------------------------------------------------------------


def _labels(rgb):
    """Per-pixel part index into PARTS (-1: not a part), and the box (row slice, column
    slice) around each part's pixels, with room for the morphology."""
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV_FULL)
    ok = (hsv[..., 1] >= SAT_MIN * 255) & (hsv[..., 2] >= VAL_MIN * 255)
    labels = np.full(rgb.shape[:2], -1, dtype=np.int32)
    v, u = np.nonzero(ok)
    h = hsv[v, u, 0].astype(np.float32) * (360.0 / 256.0)
    hues = np.array([hue for _, hue in PARTS.values()], dtype=np.float32)
    d = np.abs((h[:, None] - hues + 180.0) % 360.0 - 180.0)
    best = np.argmin(d, axis=1)
    near = d[np.arange(len(h)), best] <= HUE_TOL
    v, u, best = v[near], u[near], best[near]
    labels[v, u] = best
    boxes = {}
    for k in np.unique(best):
        rows, cols = v[best == k], u[best == k]
        boxes[int(k)] = (
            slice(max(rows.min() - BOX_MARGIN, 0), rows.max() + BOX_MARGIN + 1),
            slice(max(cols.min() - BOX_MARGIN, 0), cols.max() + BOX_MARGIN + 1),
        )
    return labels, boxes


def _mask(labels, k):
    raw = (labels == k).astype(np.uint8)
    if raw.sum() < MIN_PIXELS:
        return None, int(raw.sum())
    opened = cv2.morphologyEx(raw, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    if opened.sum() < MIN_PIXELS:  # barely visible: keep what is not a one-pixel line
        opened = cv2.morphologyEx(raw, cv2.MORPH_OPEN, cv2.getStructuringElement(0, (2, 2)))
    if opened.sum() < MIN_PIXELS:
        return None, int(raw.sum())
    eroded = cv2.erode(opened, np.ones((3, 3), np.uint8))
    mask = eroded if eroded.sum() >= 4 * MIN_PIXELS else opened
    return mask.astype(bool), int(opened.sum())


def _points(mask, box, depth, camera, n_max):
    """World points of the mask's pixels (the mask covers `box` of the image)."""
    K = np.asarray(camera["K"], dtype=float)
    T = np.asarray(camera["T_world_camera"], dtype=float)
    v, u = np.nonzero(mask & (depth[box] > 0))
    v, u = v + box[0].start, u + box[1].start
    if len(u) > n_max:  # an even, deterministic subsample
        keep = np.linspace(0, len(u) - 1, n_max).round().astype(int)
        u, v = u[keep], v[keep]
    z = depth[v, u].astype(float)
    cam = np.stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z], axis=1)
    return cam @ T[:3, :3].T + T[:3, 3]


def _inliers(pts, size):
    """Drop points far from the bulk (mislabelled pixels elsewhere in the image)."""
    if len(pts) < 10:
        return pts
    med = np.median(pts, axis=0)
    keep = np.linalg.norm(pts - med, axis=1) <= 0.75 * size + 0.01
    return pts[keep] if keep.sum() >= 10 else pts


# -- fitting --------------------------------------------------------------------------------


def _nearest(model, Rs, ts, pts, eye, index=False):
    """For poses (Rs (b, 3, 3), ts (b, 3)) at once: the model sample matched to each point,
    facing the camera where one is near: weight and distance [m], each (b, n), and with
    `index` the sample's index too."""
    q = (pts[None] - ts[:, None]) @ Rs  # object frame
    cell = ((q - model.grid_lo) * (1.0 / GRID_CELL)).astype(np.int64)
    np.clip(cell, 0, model.grid_shape - 1, out=cell)
    cells = cell @ model.grid_strides
    near = model.cell_surface[cells]  # the cells' samples and normals, (b, n, k, 6)
    view = (eye - pts)[None] @ Rs  # towards the camera, object frame
    facing = np.einsum("bnkd,bnd->bnk", near[..., 3:], view) > 0
    diff = near[..., :3] - q[:, :, None, :]
    d2 = np.einsum("bnkd,bnkd->bnk", diff, diff) + ~facing  # turned away: only if nothing near
    b, n, k = d2.shape
    flat = np.arange(b * n) * k + d2.argmin(axis=2).ravel()  # the nearest of the k, per point
    ok = facing.ravel()[flat].reshape(b, n)
    dist = np.sqrt(np.maximum(d2.ravel()[flat].reshape(b, n) - ~ok, 0.0))
    w = np.where(ok, 1.0, 0.2)
    if not index:
        return w, dist
    return w, dist, model.grid[cells].ravel()[flat].reshape(b, n)


def _turned(yaws, R0):
    """The rotations Rz(yaw) @ R0, (b, 3, 3)."""
    c, s = np.cos(yaws), np.sin(yaws)
    Rz = np.zeros((len(c), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    return Rz @ R0


def _icp(model, k, starts, pts, eye, iterations):
    """Point-to-plane Gauss–Newton on (x, y, z, yaw) in resting pose k, from each start (b, 4)
    at once, each until its steps are negligible; the part never sinks into the table."""
    R0 = model.rests[k]
    floor = -model.lowest[k] - 0.002
    X = np.array(starts, dtype=float).reshape(-1, 4)
    X[:, 2] = np.maximum(X[:, 2], floor)
    active = np.arange(len(X))
    damping = np.diag([1e-3, 1e-3, 1e-2, 1e-4])
    for _ in range(iterations):
        Rs = _turned(X[active, 3], R0)
        Rt, t = Rs.transpose(0, 2, 1), X[active, None, :3]
        w, _, j = _nearest(model, Rs, X[active, :3], pts, eye, index=True)
        c, n = model.samples[j] @ Rt + t, model.normals[j] @ Rt
        r = np.einsum("bnd,bnd->bn", n, pts - c)
        w = w * np.minimum(1.0, TRUNCATE / np.maximum(np.abs(r), 1e-9))
        w = np.where(np.linalg.norm(pts - c, axis=2) > 3 * TRUNCATE, 0.0, w)
        arm = c - t
        turn = -(n[..., 1] * arm[..., 0] - n[..., 0] * arm[..., 1])
        J = np.concatenate([-n, turn[..., None]], axis=2)  # d r / d (x, y, z, yaw)
        Jw = (J * w[..., None]).transpose(0, 2, 1)
        A = Jw @ J + damping * np.maximum(w.sum(axis=1), 1.0)[:, None, None] * 1e-3
        step = np.linalg.solve(A, -(Jw @ r[..., None]))[..., 0]
        step[:, :3] = np.clip(step[:, :3], -0.02, 0.02)
        step[:, 3] = np.clip(step[:, 3], -0.3, 0.3)
        X[active] += step
        X[active, 2] = np.maximum(X[active, 2], floor)
        done = (np.abs(step[:, :3]).max(axis=1) < 2e-5) & (np.abs(step[:, 3]) < 1e-4)
        active = active[~done]
        if not len(active):
            break
    return X


def _scores(model, R0, X, pts, eye, view):
    """Lower is better, for the poses X (b, 4: x, y, z, yaw in resting pose R0) at once: mean
    truncated distance of the points to the facing model surface, plus the share of the
    model's camera-facing surface that would hide what the camera sees. (scores, fits)."""
    X = np.asarray(X, dtype=float)
    Rs = _turned(X[:, 3], R0)
    w, d = _nearest(model, Rs, X[:, :3], pts, eye)
    fit = np.mean(np.minimum(d, TRUNCATE) * np.where(w < 1, 1.5, 1.0), axis=1)
    Rt = Rs.transpose(0, 2, 1)
    s = model.samples[model.probe] @ Rt + X[:, None, :3]  # (b, p, 3) world
    n = model.normals[model.probe] @ Rt
    ray = eye - s
    cos = np.einsum("bpd,bpd->bp", n, ray) / np.linalg.norm(ray, axis=2)
    judged = cos > GRAZING  # faces seen at a grazing angle fall on their neighbours' pixels
    depth, K, R_cw, t_cw = view
    cam = s @ R_cw.T + t_cw
    z = cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.round(K[0, 0] * cam[..., 0] / z + K[0, 2])
        v = np.round(K[1, 1] * cam[..., 1] / z + K[1, 2])
    h, wd = depth.shape
    inside = judged & (z > 0) & (u >= 0) & (u < wd) & (v >= 0) & (v < h)
    seen = depth[np.where(inside, v, 0).astype(np.int64), np.where(inside, u, 0).astype(np.int64)]
    through = inside & (seen > 0) & (seen > z + SEEN_THROUGH)
    violation = through.sum(axis=1) / np.maximum(inside.sum(axis=1), 1)  # beyond: no evidence
    return fit + VIOLATION_WEIGHT * violation, fit


def _score(model, R0, x, pts, eye, view):
    """`_scores` of one pose: (score, fit)."""
    score, fit = _scores(model, R0, np.asarray(x, dtype=float)[None], pts, eye, view)
    return float(score[0]), float(fit[0])


def _visible_centre(model, R, t, view):
    """Mean (object frame) of the model samples the camera would see at pose (R, t): facing
    it, inside the image and in front of the part's own other surfaces (a z-buffer at a quarter
    resolution)."""
    depth, K, R_cw, t_cw = view
    s = model.samples[model.probe]
    w = s @ R.T + t
    eye = -R_cw.T @ t_cw
    cam = w @ R_cw.T + t_cw
    u = (K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2]) / 4
    v = (K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]) / 4
    front = np.einsum("ij,ij->i", model.normals[model.probe] @ R.T, eye - w) > 0
    front &= (u >= 0) & (v >= 0) & (u < depth.shape[1] / 4) & (v < depth.shape[0] / 4)
    s, cam, u, v = s[front], cam[front], u[front].astype(np.int64), v[front].astype(np.int64)
    if len(s) == 0:
        return np.zeros(3)
    key = (u - u.min()) * 100000 + (v - v.min())
    order = np.lexsort((cam[:, 2], key))
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    return s[order[first]].mean(axis=0)


class _Part:
    """One seen part: its points and its pose hypotheses, refined on demand, best first."""

    def __init__(self, name, model, pts, pixels, eye, view):
        self.name, self.model, self.pts, self.pixels = name, model, pts, pixels
        self.eye, self.view = eye, view
        xy = pts[:, :2] - pts[:, :2].mean(axis=0)
        _, evecs = np.linalg.eigh(xy.T @ xy)
        self.heading = float(np.arctan2(evecs[1, 1], evecs[0, 1]))
        self.coarse = pts[
            np.linspace(0, len(pts) - 1, min(len(pts), COARSE_POINTS)).round().astype(int)
        ]
        self.tries = []  # (coarse score, rest, heading, shift, x), per resting pose on demand
        self.rests_tried = 0
        self.wide = False
        self.refined = set()
        self.hyps = []  # (score, fit, R, t) refined, best first
        self._search(0)
        self.refine(2)
        if len(self.hyps) > 1 and self.hyps[1][0] < self.hyps[0][0] + 0.0003:
            self.refine(3)  # undecided: weigh one more
        if self.hyps[0][1] > BAD_FIT:  # fits badly: it may rest on another face
            for k in range(1, len(model.rests)):
                self._search(k)
            self.refine(2)

    def _search(self, k):
        """Coarse ICP from eight headings (and offsets along long parts) in resting pose k."""
        model, pts, R0 = self.model, self.pts, self.model.rests[k]
        centre = pts.mean(axis=0)
        top = float(np.percentile(pts[:, 2], 97))
        length = float(np.ptp((np.concatenate(model.shape.pieces) @ R0.T)[:, 0]))
        shifts = (0.0, -length / 4, length / 4) if length > 0.06 else (0.0,)
        starts, Rs = [], []
        for j in range(8):
            yaw = self.heading + j * np.pi / 4
            R = _rz(yaw) @ R0
            t = centre - R @ _visible_centre(model, R, centre - R @ model.centre, self.view)
            t[2] = top - model.highest[k]  # the top shows from above, even when cut off
            for n, shift in enumerate(shifts):  # partly hidden long parts: along their length
                t1 = t + shift * R[:, 0] * [1, 1, 0] / max(np.linalg.norm(R[:2, 0]), 1e-9)
                starts.append((j, n, np.array([t1[0], t1[1], t1[2], yaw])))
                Rs.append(R)
        X = np.array([x for _, _, x in starts])
        d = _nearest(model, np.array(Rs), X[:, :3], self.coarse, self.eye)[1]
        spread = np.mean(np.minimum(d, 3 * TRUNCATE), axis=1)
        ranked = sorted((float(e), j, n, x) for e, (j, n, x) in zip(spread, starts, strict=True))
        keep = [next(t for t in ranked if t[1] == j) for j in range(8)]  # every heading
        fitted = _icp(model, k, [x for *_, x in keep], self.coarse, self.eye, 4)  # from the
        scores = _scores(model, R0, fitted, self.coarse, self.eye, self.view)[0]  # nearest offset
        for (_, j, n, _), x, score in zip(keep, fitted, scores, strict=True):
            self.tries.append((float(score) + OTHER_POSE_PENALTY * (k > 0), k, j, n, x))
        self.tries.sort(key=lambda t: t[:4])
        self.rests_tried = k + 1

    def search_wide(self):
        """For a part in conflict with its neighbours: sixteen headings, and what it shows
        aligned with several points of its top in turn (a small patch of an occluded part can
        be any piece of it)."""
        if self.wide:
            return
        self.wide = True
        model, R0 = self.model, self.model.rests[0]
        up = model.samples[model.probe][(model.normals[model.probe] @ R0.T)[:, 2] > 0.5]
        if len(up) < WIDE_ANCHORS:
            up = model.samples[model.probe]
        anchors = [up[np.argmin(np.linalg.norm(up[:, :2] - model.centre[:2], axis=1))]]
        for _ in range(WIDE_ANCHORS - 1):  # farthest point sampling
            d = np.min([np.linalg.norm(up - a, axis=1) for a in anchors], axis=0)
            anchors.append(up[int(np.argmax(d))])
        centre = self.pts.mean(axis=0)
        keys, starts = [], []
        for j in range(16):
            yaw = self.heading + (j + 0.5) * np.pi / 8
            R = _rz(yaw) @ R0
            for n, a in enumerate(anchors):
                starts.append([*(centre - R @ a), yaw])
                keys.append((100 + j, n))
        fitted = _icp(model, 0, starts, self.coarse, self.eye, 4)
        scores = _scores(model, R0, fitted, self.coarse, self.eye, self.view)[0]
        for (j, n), x, score in zip(keys, fitted, scores, strict=True):
            self.tries.append((float(score), 0, j, n, x))
        self.tries.sort(key=lambda t: t[:4])

    def refine(self, n):
        """Refine coarse hypotheses until n distinct ones exist (or none are left)."""
        for _, k, j, m, x in self.tries:
            if len(self.hyps) >= n:
                break
            if (k, j, m) in self.refined:
                continue
            self.refined.add((k, j, m))
            self.add(k, _icp(self.model, k, [x], self.pts, self.eye, FINE_ITERATIONS)[0])

    def add(self, k, x):
        R0 = self.model.rests[k]
        score, fit = _score(self.model, R0, x, self.pts, self.eye, self.view)
        if score - fit > VIOLATION_SEARCH or fit > POOR_FIT:
            # hides what the camera sees, or explains it poorly: ICP only sees the points
            # near the model, which a face sliding along itself explains equally well
            x, score, fit = self._slide(R0, x, score, fit)
        score += OTHER_POSE_PENALTY * (k > 0)
        R = _rz(x[3]) @ R0
        for _, _, R1, t1 in self.hyps:
            if np.linalg.norm(t1 - x[:3]) < 0.004 and np.trace(R1.T @ R) > 1 + 2 * np.cos(0.08):
                return
        self.hyps.append((score, fit, R, x[:3].copy()))
        self.hyps.sort(key=lambda h: h[0])

    def _slide(self, R0, x, score, fit):
        """Pattern search on the full score (points and free space) around x: each axis in
        turn, one step up or else down where that scores better, then smaller steps."""
        steps = np.array([0.008, 0.008, 0.0, np.radians(4.0)])
        axes = [d for d in range(4) if steps[d] > 0]
        for _ in range(24):
            moved, pending = False, list(axes)
            while pending:  # the remaining axes' steps from the current x, scored at once
                trials = [x + sign * steps[d] * np.eye(4)[d] for d in pending for sign in (1, -1)]
                sc, ft = _scores(self.model, R0, trials, self.pts, self.eye, self.view)
                better = np.flatnonzero(sc < score - 1e-7)
                if not len(better):
                    break
                b = int(better[0])  # the first axis that improves moves; later ones restart
                x, score, fit, moved = trials[b], float(sc[b]), float(ft[b]), True
                pending = pending[b // 2 + 1 :]
            if not moved:
                steps = steps / 2
                if steps[0] < 0.0005:
                    break
        return x, score, fit

    def slide_under(self, h, coms, masses):
        """The hypothesis h moved along the part's length to where the joint centre of mass of
        its load is best centred, among the positions explaining the image as well as h."""
        model, R = self.model, h[2]
        u = R[:, 0] * [1.0, 1.0, 0.0]
        if np.linalg.norm(u) < 0.5:
            return h
        u /= np.linalg.norm(u)
        k = next(
            (
                k
                for k, R0 in enumerate(model.rests)
                if np.allclose(R0, _rz(-np.arctan2(R[1, 0], R[0, 0])) @ R, atol=1e-6)
            ),
            0,
        )
        length = float(np.ptp((np.concatenate(model.shape.pieces) @ model.rests[k].T)[:, 0]))
        yaw = float(np.arctan2(R[1, 0], R[0, 0]))
        load = np.average(np.array(coms)[:, :2], axis=0, weights=masses)
        offsets = np.arange(-length / 2, length / 2 + 1e-9, SLIDE_STEP)
        turns = np.radians([0.0, -2.0, 2.0, -4.0, 4.0])  # the far end swings
        X = np.array([[*(h[3] + d * u), yaw + turn] for d in offsets for turn in turns])
        sc, ft = _scores(model, model.rests[k], X, self.pts, self.eye, self.view)
        rows = []
        for a, d in enumerate(offsets):  # the best turn at each offset (the first of equals)
            b = a * len(turns) + int(np.argmin(sc[a * len(turns) : (a + 1) * len(turns)]))
            rows.append(((float(sc[b]), float(ft[b])), d, X[b]))
        best = min(r[0][0] for r in rows)
        if best > h[0] + TIE:
            return h
        centre = R @ model.shape.centre_of_mass
        fits = [r for r in rows if r[0][0] <= best + TIE]
        (score, fit), _, x = min(
            fits, key=lambda r: (abs((r[2][:2] + centre[:2] - load) @ u[:2]), r[1])
        )
        if np.linalg.norm(x[:3] - h[3]) < 1e-9 and x[3] == yaw:
            return h
        return (score, fit, _rz(x[3]) @ model.rests[k], x[:3])

    def near(self, anchors):
        """Hypotheses where well-seen neighbours suggest: stacked under or on one, turned like
        it (a beam under a roof shows only its ends)."""
        for T in anchors:
            if np.linalg.norm(T[:2, 3] - self.pts[:, :2].mean(axis=0)) > 0.15:
                continue
            yaw0 = float(np.arctan2(T[1, 0], T[0, 0]))
            z = self.hyps[0][3][2]
            starts = [[T[0, 3], T[1, 3], z, yaw0 + k * np.pi / 2] for k in range(4)]
            for x in _icp(self.model, 0, starts, self.pts, self.eye, FINE_ITERATIONS):
                self.add(0, x)


# -- physics -------------------------------------------------------------------------------


def _records(poses):
    return [{"id": i, "mesh": PARTS[i][0], "pose": poses[i]} for i in sorted(poses)]


def _lowest(shape, T):
    pts = np.concatenate(shape.pieces)
    return float((pts @ T[:3, :3].T + T[:3, 3])[:, 2].min())


def _settle(poses, shapes, order, moves=None, missing_heights=()):
    """Drop (or lift) each part, lowest first, onto the table or the parts under it; `moves`
    collects each part's vertical shift [m] and what it landed on. A part that floats by the
    height of an unseen part stays where it is seen: the unseen part holds it up."""
    placed = {}
    for i in order:
        T = poses[i].copy()
        drop, on = _lowest(shapes[i], T), "table"
        for j, U in placed.items():
            gap, axis = separation(shapes[i], T, shapes[j], U, cutoff=SETTLE_RANGE)
            if axis[2] >= 0.7 and -SETTLE_RANGE <= gap < drop and _lands(shapes, i, T, j, U, gap):
                drop, on = gap, j
        held = drop > SETTLE_TOL and any(abs(drop - h) < 0.006 for h in missing_heights)
        if (abs(drop) <= SETTLE_RANGE or drop < 0) and not held:
            T[2, 3] -= drop
        elif moves is not None:
            on = None  # floating
        placed[i] = T
        if moves is not None:
            moves[i] = (-drop, on)
    return placed


def _lands(shapes, i, T, j, U, gap):
    """Whether part i, moved down by `gap`, rests on part j's top (a part beside j, its bottom
    edge diagonally above j's top edge, would slide down j's side)."""
    D = T.copy()
    D[2, 3] -= gap
    after, axis = separation(shapes[i], D, shapes[j], U, cutoff=0.001)
    return after > -0.001 and axis[2] >= 0.7


def _push_apart(poses, shapes, pixels):
    """Side-by-side overlaps (noise) resolved by moving the less visible part sideways."""
    ids = sorted(poses)
    for _ in range(3):
        moved = False
        for a in ids:
            for b in ids:
                if a >= b:
                    continue
                gap, axis = separation(shapes[a], poses[a], shapes[b], poses[b], cutoff=0.0)
                if gap >= -0.0005 or abs(axis[2]) >= 0.7:
                    continue
                weak, sign = (a, 1.0) if pixels.get(a, 0) < pixels.get(b, 0) else (b, -1.0)
                shift = sign * axis * (-gap + 0.0005)
                shift[2] = 0.0
                poses[weak] = poses[weak].copy()
                poses[weak][:3, 3] += shift
                moved = True
        if not moved:
            break
    return poses


def _hidden_supporters(poses, shapes, models, missing, pixels):
    """Put unseen parts under parts that would otherwise float or tip over: an unseen part of
    the right height, on the table or on a seen part's flat top (pillars on the beam)."""
    missing = list(missing)
    for _ in range(len(missing)):
        if not missing:
            break
        recs = _records(poses)
        bad = unstable_objects(recs, shapes, contact_tol=0.003)
        if not bad:
            break
        sup = supports(recs, shapes, contact_tol=0.003)
        placed = False
        for i in sorted(bad, key=lambda k: (_lowest(shapes[k], poses[k]), k)):
            T = poses[i]
            bottom = _lowest(shapes[i], T)
            com = T[:3, :3] @ shapes[i].centre_of_mass + T[:3, 3]
            under = [j for j in sup.get(i, []) if j != "table"]
            if len(under) == 1:  # one visible supporter: the hidden one mirrors it
                U = poses[under[0]]
                xy = 2 * com[:2] - U[:2, 3]
                yaw = float(np.arctan2(U[1, 0], U[0, 0]))
            else:
                xy, yaw = com[:2], float(np.arctan2(T[1, 0], T[0, 0]))
            for m in sorted(missing):
                model = models[m]
                base = bottom - (model.highest[0] - model.lowest[0])  # where m would stand
                if base < -0.006:
                    continue
                z = base - model.lowest[0] if base > 0.006 else -model.lowest[0]
                T_m = _pose(_rz(yaw) @ model.rests[0], [xy[0], xy[1], z])
                if base > 0.006 and not _stands_on_a_part({**poses, m: T_m}, shapes, m):
                    continue
                poses[m] = T_m
                pixels[m] = 0
                missing.remove(m)
                placed = True
                break
            if placed:
                break
        if not placed:
            break
    return poses


def _stands_on_a_part(poses, shapes, m):
    """Whether part `m` rests, stably and inside nothing, on a part (not the table)."""
    recs = _records(poses)
    on = [j for j in supports(recs, shapes, contact_tol=0.003).get(m, []) if j != "table"]
    if not on or m in unstable_objects(recs, shapes, contact_tol=0.003):
        return False
    return not any(m in (a, b) for a, b, _ in collisions(recs, shapes, tolerance=0.002))


def _surfaces(poses, shapes):
    """Heights [m] a part may stand at: the table and every part's highest point."""
    return [0.0] + [
        float((np.concatenate(shapes[i].pieces) @ T[:3, :3].T + T[:3, 3])[:, 2].max())
        for i, T in poses.items()
    ]


def _out_of_sight(poses, shapes, models, missing, pixels, camera, meshes):
    """Unseen parts that hold nothing up, each put upright on the table behind a seen part
    (most visible first), where a drawing of the scene shows none of it and it touches
    nothing; a part with no such spot is left out."""
    eye = np.asarray(camera["T_world_camera"], float)[:3, 3]
    small = {
        "width": int(camera["width"]) // SIGHT_SCALE,
        "height": int(camera["height"]) // SIGHT_SCALE,
        "K": np.diag([1 / SIGHT_SCALE, 1 / SIGHT_SCALE, 1.0]) @ np.asarray(camera["K"], float),
        "T_world_camera": camera["T_world_camera"],
    }
    poses = dict(poses)
    for m in missing:
        model = models[m]
        placed = False
        for j in sorted(pixels, key=lambda k: (-pixels[k], k)):
            away = poses[j][:2, 3] - eye[:2]
            away /= max(float(np.linalg.norm(away)), 1e-9)
            R = _rz(float(np.arctan2(away[1], away[0]))) @ model.rests[0]
            for d in BEHIND:
                xy = poses[j][:2, 3] + d * away
                trial = {**poses, m: _pose(R, [xy[0], xy[1], -model.lowest[0]])}
                recs = _records(trial)
                if any(m in (a, b) for a, b, _ in collisions(recs, shapes, tolerance=0.001)):
                    continue
                seen = render_scene(recs, meshes, small)["mask"]
                if not (seen == [r["id"] for r in recs].index(m)).any():
                    poses, placed = trial, True
                    break
            if placed:
                break
    return poses


def _conflicts(poses, shapes, pixels, missing_heights, moves):
    """Parts whose pose cannot be right: the less visible of two interpenetrating parts, of a
    part and what it had to be moved far onto, and a part floating where no unseen part could
    hold it up."""
    recs = _records(poses)
    out = set()
    for i, (dz, on) in moves.items():
        if abs(dz) > SETTLE_TOL and on is not None:
            out.add(i if on == "table" else min((i, on), key=lambda k: (pixels.get(k, 0), k)))
    for a, b, _ in collisions(recs, shapes, tolerance=CONFLICT_DEPTH):
        if b != "table":
            out.add(min((a, b), key=lambda k: (pixels.get(k, 0), k)))
    sup = supports(recs, shapes, contact_tol=0.003)
    surfaces = _surfaces(poses, shapes)
    for i, T in poses.items():
        bottom = _lowest(shapes[i], T)
        if not sup[i] and not any(
            abs(s + h - bottom) < 0.006 for h in missing_heights for s in surfaces
        ):
            out.add(i)
    return out


def _choose(parts, shapes, missing_heights):
    """One hypothesis per part, physically consistent where the image allows."""
    pixels = {i: p.pixels for i, p in parts.items()}
    anchors = [_pose(p.hyps[0][2], p.hyps[0][3]) for p in parts.values()]
    for i in sorted(parts):
        if parts[i].hyps[0][0] > CONTEXT_SCORE:
            parts[i].near([T for T in anchors if not np.allclose(T[:3, 3], parts[i].hyps[0][3])])
    choice = {i: p.hyps[0] for i, p in parts.items()}  # (score, fit, R, t)

    def posed(ch):
        poses = {i: _pose(h[2], h[3]) for i, h in ch.items()}
        moves = {}
        order = sorted(poses, key=lambda i: (_lowest(shapes[i], poses[i]), i))
        poses = _settle(poses, shapes, order, moves, missing_heights)
        return poses, _conflicts(poses, shapes, pixels, missing_heights, moves)

    poses, conflicts = posed(choice)
    tried = set()
    for _ in range(2 * len(parts)):
        bad = sorted(conflicts - tried)
        if not bad:
            break
        i = min(bad, key=lambda k: (pixels[k], k))
        tried.add(i)
        part = parts[i]
        part.search_wide()
        part.refine(len(part.hyps) + ALTERNATIVES)
        if part.rests_tried < len(part.model.rests):
            for k in range(part.rests_tried, len(part.model.rests)):
                part._search(k)
            part.refine(len(part.hyps) + 2)
        for h in list(part.hyps):
            if h is choice[i] or h[0] > choice[i][0] + ALTERNATIVE_MARGIN:
                continue
            trial, found = posed({**choice, i: h})
            if i not in found and len(found) < len(conflicts):
                choice[i], poses, conflicts = h, trial, found
                break
    # a part carrying others whose position along its length the image cannot settle (a beam
    # seen end-on under a cylinder shows a patch that fits anywhere along it) is put where its
    # load is centred on it, among the positions that explain the image as well as the best
    sup = supports(_records(poses), shapes, contact_tol=0.003)
    for i in sorted(parts):
        loads = sorted(j for j in poses if i in sup[j])
        if not loads:
            continue
        h = parts[i].slide_under(
            choice[i],
            [poses[j][:3, :3] @ shapes[j].centre_of_mass + poses[j][:3, 3] for j in loads],
            [shapes[j].volume for j in loads],
        )
        if h is not choice[i]:
            trial, found = posed({**choice, i: h})
            if len(found) <= len(conflicts):
                choice[i], poses, conflicts = h, trial, found
    return poses


def _refined(observation, meshes, camera, poses, parts, labels):
    """Step 5: the seen parts' poses refined by render-and-compare where that explains the
    image better (see the module docstring)."""
    ids = [i for i in PARTS if i in poses]
    records = [{"id": i, "mesh": PARTS[i][0], "pose": poses[i]} for i in ids]
    segments = {i: labels == k for k, i in enumerate(PARTS) if i in parts}

    def fitted(recs, segs, **kw):
        return refine_poses(observation, meshes, recs, camera=camera, segments=segs, **kw)

    now = fitted(records, segments, hypotheses="given", iterations=1, max_shift=1e-4)
    fits = fitted(records, segments)
    out, cost = dict(poses), {i: f.cost for i, f in zip(ids, now, strict=True)}
    for i, fit in zip(ids, fits, strict=True):
        if fit.pixels and _better(fit, cost[i]):
            out[i], cost[i] = _kept_heading(fit, poses[i]), fit.cost
    for k, i in enumerate(ids):
        if not fits[k].pixels or cost[i] <= TURN_EVIDENCE:
            continue
        start = poses[i].copy()
        start[:2, 3] = parts[i].pts[:, :2].mean(axis=0)
        again = [{**r, "pose": start if r["id"] == i else out[r["id"]]} for r in records]
        other = fitted(again, {i: segments[i]}, max_shift=RESEARCH_SHIFT)[k]
        if other.cost < cost[i] / 2:
            out[i], cost[i] = _kept_heading(other, poses[i]), other.cost
    return out


def _mirrored(observation, meshes, camera, poses, shapes, parts, labels):
    """A part carried on two supporters (a beam or the arch on two pillars) rests centred on
    them. Where one supporter shows only a sliver (fewer than WEAK_PIXELS) and the other is
    well seen, the sliver's fit can slide along the view ray or along the load; the weak
    supporter is tried at the mirror of the other through the load's centre of mass, with its
    own heading and with the other's, refined there by at most MIRROR_MIN, and moved there
    when that explains its segment as well
    (the refiner's cost, within MIRROR_SLACK) and touches nothing."""
    sup = supports(_records(poses), shapes, contact_tol=0.003)
    pixels = {i: p.pixels for i, p in parts.items()}
    out = dict(poses)
    for load in sorted(poses):
        under = sorted(j for j in sup.get(load, []) if j != "table")
        if len(under) != 2 or any(j not in parts for j in under):
            continue
        weak, strong = sorted(under, key=lambda j: (pixels[j], j))
        if pixels[weak] >= WEAK_PIXELS or pixels[strong] < 2 * pixels[weak]:
            continue
        if abs(_lowest(shapes[weak], out[weak]) - _lowest(shapes[strong], out[strong])) > 0.003:
            continue
        T = out[load]
        com = T[:3, :3] @ shapes[load].centre_of_mass + T[:3, 3]
        M = out[weak].copy()
        M[:2, 3] = 2 * com[:2] - out[strong][:2, 3]
        if np.linalg.norm(M[:2, 3] - out[weak][:2, 3]) < MIRROR_MIN:
            continue
        ids = [i for i in PARTS if i in out]
        segment = {weak: labels == list(PARTS).index(weak)}
        # at the mirror, the weak supporter keeps its own heading or takes the seen one's
        S = M.copy()
        S[:3, :3] = out[strong][:3, :3]
        now, *mirrors = [
            refine_poses(
                observation,
                meshes,
                [
                    {"id": i, "mesh": PARTS[i][0], "pose": pose if i == weak else out[i]}
                    for i in ids
                ],
                camera=camera,
                segments=segment,
                hypotheses="given",
                **kw,
            )[ids.index(weak)]
            for pose, kw in (
                (out[weak], {"iterations": 1, "max_shift": 1e-4}),
                (M, {"max_shift": MIRROR_MIN}),
                (S, {"max_shift": MIRROR_MIN}),
            )
        ]
        best = min(mirrors, key=lambda f: f.cost)
        if best.cost > now.cost + MIRROR_SLACK:
            continue
        M[:3, :3], M[:2, 3] = best.pose[:3, :3], best.pose[:2, 3]
        trial = {**out, weak: M}
        hits = collisions(_records(trial), shapes, tolerance=CONFLICT_DEPTH)
        if not any(weak in (a, b) and b != "table" for a, b, _ in hits):
            out = trial
    return out


def _kept_heading(fit, T):
    """The refined pose; for a sliver (fewer than FEW_PIXELS) turned by less than
    SMALL_TURN, with the heading of `T`: a few pixels show where a part is, and which of its
    faces show, but not a small turn (the calibration error moves them as much)."""
    out = fit.pose.copy()
    turn = np.arccos(np.clip((np.trace(T[:3, :3].T @ out[:3, :3]) - 1) / 2, -1.0, 1.0))
    if fit.pixels < FEW_PIXELS and turn < SMALL_TURN:
        out[:3, :3] = T[:3, :3]
    return out


def _better(fit, cost):
    """Whether a refined fit explains its segment better than the pose it started from
    (cost `cost`): a turn of it only when the start explains the segment badly and the turn
    at least twice as well, or when the part shows more than a sliver and the turn explains
    it TURN_RATIO times better (a block half hidden behind others, fitted across)."""
    if fit.hypothesis == "given":
        return fit.cost < cost
    if fit.pixels >= FEW_PIXELS and fit.cost * TURN_RATIO < cost:
        return True
    return cost > TURN_EVIDENCE and fit.cost < cost / 2


def perceive(observation, meshes, camera):
    rgb = np.asarray(observation["rgb"], dtype=np.uint8)
    depth = np.asarray(observation["depth"], dtype=np.float32)
    camera = level_camera_on_table(depth, camera)  # the table shows the calibration's tilt
    K = np.asarray(camera["K"], dtype=float)
    T_wc = np.asarray(camera["T_world_camera"], dtype=float)
    eye = T_wc[:3, 3]
    # the nearest depth around each pixel: a surface counts as seen through only where all
    # of its neighbourhood is farther (silhouette pixels are not evidence)
    near = cv2.erode(np.where(depth > 0, depth, np.float32(1e3)), np.ones((3, 3), np.uint8))
    view = (np.where(near < 1e3, near, 0.0), K, T_wc[:3, :3].T, -T_wc[:3, :3].T @ T_wc[:3, 3])
    labels, boxes = _labels(rgb)
    ids = [i for i in PARTS if PARTS[i][0] in meshes]
    models = {i: _model(meshes[PARTS[i][0]]) for i in ids}
    shapes = {i: models[i].shape for i in ids}  # by id, and by mesh key for the toolbox
    shapes.update({PARTS[i][0]: models[i].shape for i in ids})
    parts = {}
    for k, i in enumerate(PARTS):
        if i not in models or k not in boxes:
            continue
        mask, count = _mask(labels[boxes[k]], k)
        if mask is None:
            continue
        pts = _points(mask, boxes[k], depth, camera, FINE_POINTS)
        pts = _inliers(pts, float(models[i].extent.max()))
        if len(pts) >= 10:
            parts[i] = _Part(i, models[i], pts, count, eye, view)
    missing = [i for i in ids if i not in parts]
    heights = [models[m].highest[0] - models[m].lowest[0] for m in missing]
    poses = _choose(parts, shapes, heights)
    poses = _push_apart(poses, shapes, {i: p.pixels for i, p in parts.items()})
    poses = _refined(observation, meshes, camera, poses, parts, labels)
    # the refiner judges the image only: settle its poses again, and part what it pushed in
    order = sorted(poses, key=lambda i: (_lowest(shapes[i], poses[i]), i))
    poses = _push_apart(
        _settle(poses, shapes, order, missing_heights=heights),
        shapes,
        {i: p.pixels for i, p in parts.items()},
    )
    poses = _mirrored(observation, meshes, camera, poses, shapes, parts, labels)
    if missing:
        pixels = {i: p.pixels for i, p in parts.items()}
        poses = _hidden_supporters(poses, shapes, models, missing, pixels)
        left = [m for m in missing if m not in poses]
        poses = _out_of_sight(poses, shapes, models, left, pixels, camera, meshes)
        order = sorted(poses, key=lambda i: (_lowest(shapes[i], poses[i]), i))
        poses = _settle(poses, shapes, order)
    return [{"id": i, "mesh": PARTS[i][0], "pose": poses[i]} for i in PARTS if i in poses]
