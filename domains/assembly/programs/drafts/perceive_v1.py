# A realistic failing draft, kept to show what the checks reject (not a reference program).
# perceive v1 (an earlier version of the reference perceive) fits every part on its own: its
# eight headings and three offsets along its length all start from what it shows. A beam
# under a roof shows only its two ends and a sliver of one side; from those ICP settles on a
# beam lying across the structure, and nothing makes it look where the roof above it points.
# Where a part is hidden it asks the toolbox's physics about records whose mesh ('pillar') its
# shapes are not keyed by, and raises. In the reference transcript it fails `schema.output`
# (that error, on a composed scene), `property.accuracy` and `domain.assembly.physically_valid`
# (a roof whose centre of mass lies 45 mm outside its support); `rivet check assembly perceive
# domains/assembly/programs/drafts/perceive_v1.py --deps domains/assembly/programs` shows its
# failures on fresh cases.
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
   see: an unseen part of the right height is put under it (mirroring the visible one for a
   beam or an arch on two pillars). A part that is not seen and not needed to hold anything up
   is left out: it is reported missing rather than invented.
"""

import hashlib

import cv2
import numpy as np
import trimesh
from scipy.spatial import cKDTree

from toolbox import Shape, separation, stable_poses, supports, unstable_objects

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
COARSE_POINTS = 120
FINE_POINTS = 400
SAMPLE_EDGE = 0.004  # model surface sampling [m]
TRUNCATE = 0.006  # residuals beyond this count as outliers [m]
SEEN_THROUGH = 0.008  # model surface this far in front of what the camera sees [m]
VIOLATION_WEIGHT = 0.02  # [m] per unit fraction of model surface seen through
BAD_FIT = 0.004  # mean residual [m] above which other resting poses are tried
OTHER_POSE_PENALTY = 0.0015  # [m] prior for the part's own upright pose
SETTLE_RANGE = 0.03  # a part may drop or rise this much onto its support [m]
GRID_CELL = 0.0025  # [m]
GRID_MARGIN = 0.025  # [m]
NEIGHBOURS = 6

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
    """Per-pixel part index into PARTS (-1: not a part)."""
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV_FULL)
    ok = (hsv[..., 1] >= SAT_MIN * 255) & (hsv[..., 2] >= VAL_MIN * 255)
    labels = np.full(rgb.shape[:2], -1, dtype=np.int32)
    v, u = np.nonzero(ok)
    h = hsv[v, u, 0].astype(np.float32) * (360.0 / 256.0)
    hues = np.array([hue for _, hue in PARTS.values()], dtype=np.float32)
    d = np.abs((h[:, None] - hues + 180.0) % 360.0 - 180.0)
    best = np.argmin(d, axis=1)
    near = d[np.arange(len(h)), best] <= HUE_TOL
    labels[v[near], u[near]] = best[near]
    return labels


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


def _points(mask, depth, camera, n_max):
    K = np.asarray(camera["K"], dtype=float)
    T = np.asarray(camera["T_world_camera"], dtype=float)
    v, u = np.nonzero(mask & (depth > 0))
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


def _match(model, R, t, pts, eye):
    """Model samples (world) and normals matched to the points, facing the camera; weights and
    distances [m]."""
    q = (pts - t) @ R  # object frame
    cell = ((q - model.grid_lo) * (1.0 / GRID_CELL)).astype(np.int64)
    np.clip(cell, 0, model.grid_shape - 1, out=cell)
    idx = model.grid[
        (cell[:, 0] * model.grid_shape[1] + cell[:, 1]) * model.grid_shape[2] + cell[:, 2]
    ]
    view = (eye - pts) @ R  # towards the camera, object frame
    nrm = model.normals[idx]  # (n, k, 3)
    facing = (
        nrm[..., 0] * view[:, :1] + nrm[..., 1] * view[:, 1:2] + nrm[..., 2] * view[:, 2:]
    ) > 0
    diff = model.samples[idx] - q[:, None, :]
    d2 = (diff * diff).sum(axis=2) + ~facing  # a sample turned away only when no other is near
    first = d2.argmin(axis=1)
    rows = np.arange(len(pts))
    j = idx[rows, first]
    ok = facing[rows, first]
    w = np.where(ok, 1.0, 0.2)
    dist = np.sqrt(np.maximum(d2[rows, first] - ~ok, 0.0))
    return model.samples[j] @ R.T + t, model.normals[j] @ R.T, w, dist


def _icp(model, R0, params, pts, eye, iterations):
    """Point-to-plane Gauss–Newton on (x, y, z, yaw) with the resting orientation R0."""
    x = np.array(params, dtype=float)
    for _ in range(iterations):
        R = _rz(x[3]) @ R0
        c, n, w, _ = _match(model, R, x[:3], pts, eye)
        r = np.einsum("ij,ij->i", n, pts - c)
        w = w * np.minimum(1.0, TRUNCATE / np.maximum(np.abs(r), 1e-9))
        w = np.where(np.linalg.norm(pts - c, axis=1) > 3 * TRUNCATE, 0.0, w)
        arm = c - x[:3]
        J = np.c_[-n, -(n[:, 1] * arm[:, 0] - n[:, 0] * arm[:, 1])]  # d r / d (x, y, z, yaw)
        A = (J * w[:, None]).T @ J + np.diag([1e-3, 1e-3, 1e-2, 1e-4]) * max(w.sum(), 1.0) * 1e-3
        b = -(J * w[:, None]).T @ r
        step = np.linalg.solve(A, b)
        step[:3] = np.clip(step[:3], -0.02, 0.02)
        step[3] = np.clip(step[3], -0.3, 0.3)
        x += step
        if np.abs(step[:3]).max() < 2e-5 and abs(step[3]) < 1e-4:
            break
    return x


def _score(model, R0, x, pts, eye, view):
    """Lower is better: mean truncated distance of the points to the facing model surface, plus
    the share of the model's camera-facing surface that would hide what the camera sees."""
    R = _rz(x[3]) @ R0
    _, _, w, d = _match(model, R, x[:3], pts, eye)
    fit = float(np.mean(np.minimum(d, TRUNCATE) * np.where(w < 1, 1.5, 1.0)))
    s = model.samples[model.probe] @ R.T + x[:3]
    n = model.normals[model.probe] @ R.T
    s = s[np.einsum("ij,ij->i", n, eye - s) > 0]
    depth, K, R_cw, t_cw = view
    cam = s @ R_cw.T + t_cw
    z = cam[:, 2]
    u = np.round(K[0, 0] * cam[:, 0] / z + K[0, 2]).astype(int)
    v = np.round(K[1, 1] * cam[:, 1] / z + K[1, 2]).astype(int)
    h, wd = depth.shape
    inside = (z > 0) & (u >= 0) & (u < wd) & (v >= 0) & (v < h)
    seen = depth[np.clip(v, 0, h - 1), np.clip(u, 0, wd - 1)]
    valid = inside & (seen > 0)
    through = valid & (seen > z + SEEN_THROUGH)
    outside = (~inside).sum()
    violation = (through.sum() + outside) / max(len(s), 1)
    return fit + VIOLATION_WEIGHT * violation, fit


def _visible_centre(model, R, t, view):
    """Mean (object frame) of the model samples the camera would see at pose (R, t): facing
    it and in front of the part's own other surfaces (a z-buffer at a quarter resolution)."""
    _, K, R_cw, t_cw = view
    s = model.samples[model.probe]
    w = s @ R.T + t
    eye = -R_cw.T @ t_cw
    front = np.einsum("ij,ij->i", model.normals[model.probe] @ R.T, eye - w) > 0
    s, w = s[front], w[front]
    if len(s) == 0:
        return np.zeros(3)
    cam = w @ R_cw.T + t_cw
    u = (K[0, 0] * cam[:, 0] / cam[:, 2] / 4).astype(np.int64)
    v = (K[1, 1] * cam[:, 1] / cam[:, 2] / 4).astype(np.int64)
    key = (u - u.min()) * 100000 + (v - v.min())
    order = np.lexsort((cam[:, 2], key))
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    return s[order[first]].mean(axis=0)


def _fit(model, pts, eye, view):
    """Best (R, t, score, fit) of the part over its resting poses and starting headings."""
    xy = pts[:, :2] - pts[:, :2].mean(axis=0)
    _, evecs = np.linalg.eigh(xy.T @ xy)
    heading = float(np.arctan2(evecs[1, 1], evecs[0, 1]))
    centre = pts.mean(axis=0)
    coarse = pts[np.linspace(0, len(pts) - 1, min(len(pts), COARSE_POINTS)).round().astype(int)]
    best = None
    for k, R0 in enumerate(model.rests):
        if k > 0 and best is not None and best[3] < BAD_FIT:
            break
        tries = []
        length = float(np.ptp((np.concatenate(model.shape.pieces) @ R0.T)[:, 0]))
        shifts = (0.0, -length / 4, length / 4) if length > 0.06 else (0.0,)
        for j in range(8):
            yaw = heading + j * np.pi / 4
            R = _rz(yaw) @ R0
            t = centre - R @ _visible_centre(model, R, centre - R @ model.centre, view)
            for n, shift in enumerate(shifts):  # partly hidden long parts: along their length
                t1 = t + shift * R[:, 0] * [1, 1, 0] / max(np.linalg.norm(R[:2, 0]), 1e-9)
                x = _icp(model, R0, [t1[0], t1[1], t1[2], yaw], coarse, eye, 4)
                tries.append((_score(model, R0, x, coarse, eye, view)[0], j, n, x))
        tries.sort(key=lambda t: t[:3])
        for n, (first, _, _, x) in enumerate(tries[:2]):
            if n > 0 and first > 1.3 * tries[0][0]:
                break
            x = _icp(model, R0, x, pts, eye, 12)
            score, fit = _score(model, R0, x, pts, eye, view)
            score += OTHER_POSE_PENALTY * (k > 0)
            if best is None or score < best[2] - 1e-12:
                best = (_rz(x[3]) @ R0, x[:3].copy(), score, fit)
    return best


# -- physics -------------------------------------------------------------------------------


def _records(poses):
    return [{"id": i, "mesh": PARTS[i][0], "pose": poses[i]} for i in sorted(poses)]


def _lowest(shape, T):
    pts = np.concatenate(shape.pieces)
    return float((pts @ T[:3, :3].T + T[:3, 3])[:, 2].min())


def _settle(poses, shapes, order):
    """Drop (or lift) each part, lowest first, onto the table or the parts under it."""
    placed = {}
    for i in order:
        T = poses[i].copy()
        drop = _lowest(shapes[i], T)
        for j, U in placed.items():
            gap, axis = separation(shapes[i], T, shapes[j], U, cutoff=SETTLE_RANGE)
            if axis[2] >= 0.7 and -SETTLE_RANGE <= gap < drop:
                drop = gap
        if abs(drop) <= SETTLE_RANGE or drop < 0:
            T[2, 3] -= drop
        placed[i] = T
    return placed


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
    """Put unseen parts under parts that would otherwise float or tip over."""
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
            for m in sorted(missing, key=lambda k: (k not in [c for c in missing], k)):
                model = models[m]
                height = model.highest[0] - model.lowest[0]
                if abs(height - bottom) > 0.006:
                    continue
                poses[m] = _pose(_rz(yaw) @ model.rests[0], [xy[0], xy[1], -model.lowest[0]])
                pixels[m] = 0
                missing.remove(m)
                placed = True
                break
            if placed:
                break
        if not placed:
            break
    return poses


def perceive(observation, meshes, camera):
    rgb = np.asarray(observation["rgb"], dtype=np.uint8)
    depth = np.asarray(observation["depth"], dtype=np.float32)
    K = np.asarray(camera["K"], dtype=float)
    T_wc = np.asarray(camera["T_world_camera"], dtype=float)
    eye = T_wc[:3, 3]
    view = (depth, K, T_wc[:3, :3].T, -T_wc[:3, :3].T @ T_wc[:3, 3])
    labels = _labels(rgb)
    ids = [i for i in PARTS if PARTS[i][0] in meshes]
    models = {i: _model(meshes[PARTS[i][0]]) for i in ids}
    shapes = {i: models[i].shape for i in ids}
    poses, pixels, fits = {}, {}, {}
    for k, i in enumerate(PARTS):
        if i not in models:
            continue
        mask, count = _mask(labels, k)
        if mask is None:
            continue
        pts = _inliers(_points(mask, depth, camera, FINE_POINTS), float(models[i].extent.max()))
        if len(pts) < 10:
            continue
        R, t, _, fit = _fit(models[i], pts, eye, view)
        poses[i], pixels[i], fits[i] = _pose(R, t), count, fit
    order = sorted(poses, key=lambda i: (_lowest(shapes[i], poses[i]), i))
    poses = _settle(poses, shapes, order)
    poses = _push_apart(poses, shapes, pixels)
    missing = [i for i in ids if i not in poses]
    if missing:
        poses = _hidden_supporters(poses, shapes, models, missing, pixels)
        order = sorted(poses, key=lambda i: (_lowest(shapes[i], poses[i]), i))
        poses = _settle(poses, shapes, order)
    return [{"id": i, "mesh": PARTS[i][0], "pose": poses[i]} for i in PARTS if i in poses]
