# Written by people (the RIVET team), not by a model: the hand-written reference `perceive`
# for the tangram domain, the level a model's program should reach. It uses numpy, scipy, cv2.
"""perceive(observation, meshes, camera) -> records: the seven pieces' planar poses from RGB-D.

Identity. Every piece has its own colour, so a piece's id is the colour it shows: the two
large (red `large_1`, blue `large_2`) and the two small (green `small_1`, orange `small_2`)
triangles have the same shape but are never confused, and the same id names the same physical
piece in the start and in the goal image. The task gives each coloured piece its own place and
the scorer compares ids, so the planner must not swap identical shapes: it never does, because
ids are stable and colour-bound.

Pose. The pieces lie flat (z = 0, turned only about the vertical), so each is (x, y, yaw):
1. Colour: pixels are labelled by the nearest catalogue hue (saturated pixels only: the table
   and shadows are grey); a 3×3 opening removes the one-pixel lines where two colours blend at
   a shared edge.
2. Heights, without trusting depth for x, y: each pixel's ray is cut with the plane of the
   pieces' top faces (z = 15 mm) and the plane of the knob tops (z = 35 mm); a labelled pixel
   whose measured depth agrees with the top-face plane (±3.5 mm, the sensor noise is ≈1–1.5 mm)
   is top face, one that agrees with the knob plane is knob top. The ray intersection gives
   x, y far more precisely than the noisy depth would.
3. Fit (x, y, yaw) of the known outline (the mesh's bottom face), robust least squares on
   three residuals: every top-face point must lie inside the outline; every point of the
   outline must project onto an image pixel that is either this piece's top face or hidden by
   something nearer (its own knob, a neighbour's knob: occlusion is excused, the table or a
   neighbour seen there is not); the knob-top points must lie inside the knob, which sits on
   the centroid. The starts are the knob centre and a coarse sweep of yaw over the piece's
   symmetry period (triangles 360°, parallelogram 180°, square 90°); the fit is sub-degree
   because the outline's long edges are hundreds of pixels.
4. Apart. A piece mostly hidden behind its neighbours' knobs shows too little of its outline
   to fix its turn, and its fit may put it inside a neighbour. Pieces lie side by side, never
   in each other: where two fitted pieces overlap by more than 1.5 mm, the one the image shows
   less of is fitted again from every start of the sweep with a fourth residual, how deep its
   samples lie inside the other pieces, and that fit is kept when it keeps them apart.
The parallelogram is never mirrored: a mirrored parallelogram does not fit its outline.
"""

import cv2
import numpy as np
from scipy.optimize import least_squares

from toolbox.vision import level_camera_on_table

OBJECTS = {  # id → mesh key, in catalogue order
    "large_1": "large_triangle",
    "large_2": "large_triangle",
    "medium": "medium_triangle",
    "small_1": "small_triangle",
    "small_2": "small_triangle",
    "square": "square",
    "parallelogram": "parallelogram",
}
COLOURS = {  # catalogue colours, RGB 0–1
    "large_1": (0.85, 0.14, 0.14),
    "large_2": (0.14, 0.33, 0.85),
    "medium": (0.96, 0.80, 0.08),
    "small_1": (0.14, 0.64, 0.24),
    "small_2": (0.98, 0.50, 0.05),
    "square": (0.56, 0.24, 0.76),
    "parallelogram": (0.08, 0.76, 0.80),
}
SYMMETRY = {  # rotational symmetry order about z per mesh key
    "large_triangle": 1,
    "medium_triangle": 1,
    "small_triangle": 1,
    "square": 4,
    "parallelogram": 2,
}
TOP = 0.015  # top face height [m]
KNOB_TOP = 0.035  # knob top height [m]
KNOB_HALF = 0.008  # half side of the square knob [m]
HUE_TOL = 14.0  # [deg]; red–orange are 28° apart, orange–yellow 22°
SAT_MIN = 0.35
VAL_MIN = 0.12
HEIGHT_TOL = 0.0035  # depth agreement with a plane [m]
SIDE_TOL = 0.0005  # depth beyond the top-face plane still read as top face [m]
INSIDE_SLACK = 0.0005  # top-face points may lie this far outside the outline [m]
NEARER = 0.004  # a pixel this much nearer than the top-face plane hides it [m]
MIN_PIXELS = 40
MAX_POINTS = 400  # top-face points per piece, for speed
EDGE_STEP = 0.002  # spacing of outline samples [m]
INTERIOR_STEP = 0.008  # spacing of interior samples [m]
YAW_STEP = np.radians(10.0)
GOOD_FIT = 0.0005**2  # mean squared residual of a clean fit [m²]
MARGIN = 30  # crop margin around a piece's pixels [px]
OVERLAP_TOL = 0.0015  # two fitted pieces overlapping deeper than this are refitted apart [m]
OVERLAP_SLACK = 0.0005  # the overlap a refit tolerates [m]


def _hue(rgb):
    r, g, b = (float(c) for c in rgb)
    return float(cv2.cvtColor(np.float32([[[r, g, b]]]), cv2.COLOR_RGB2HSV)[0, 0, 0])


HUES = {i: _hue(c) for i, c in COLOURS.items()}


def _labels(rgb):
    """Per-pixel index into OBJECTS (-1: not a piece)."""
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV_FULL)  # uint8: hue in 256ths of a turn
    byte = (np.arange(256) + 0.5) * (360.0 / 256.0)
    hues = np.array([HUES[i] for i in OBJECTS])
    d = np.abs((byte[:, None] - hues + 180.0) % 360.0 - 180.0)  # (256, 7)
    lut = np.where(d.min(axis=1) <= HUE_TOL, np.argmin(d, axis=1), -1).astype(np.int32)
    ok = (hsv[..., 1] >= SAT_MIN * 255) & (hsv[..., 2] >= VAL_MIN * 255)
    return np.where(ok, lut[hsv[..., 0]], -1)


def _outline(mesh):
    """Counter-clockwise bottom outline (M, 2) [m] of a flat piece in its own frame."""
    v = np.asarray(mesh.vertices, dtype=float)
    pts = v[v[:, 2] < v[:, 2].min() + 1e-6][:, :2]
    hull = cv2.convexHull(pts.astype(np.float32)).reshape(-1, 2).astype(float)
    # snap back to the exact vertices (convexHull works in float32)
    idx = [int(np.argmin(np.linalg.norm(pts - p, axis=1))) for p in hull]
    poly = pts[idx]
    area = np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    return poly if area > 0 else poly[::-1]


class _Shape:
    """A piece outline with its edge normals and sample points (own frame)."""

    def __init__(self, poly):
        self.poly = poly
        e = np.roll(poly, -1, axis=0) - poly
        n = np.stack([e[:, 1], -e[:, 0]], axis=1)
        self.normals = n / np.linalg.norm(n, axis=1, keepdims=True)  # outward (CCW polygon)
        self.offsets = np.sum(self.normals * poly, axis=1)
        samples = []
        for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
            k = max(int(np.linalg.norm(b - a) / EDGE_STEP), 2)
            t = (np.arange(k) + 0.5) / k
            samples.append(a + t[:, None] * (b - a))
        edge = np.concatenate(samples)
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        gx, gy = np.meshgrid(
            np.arange(lo[0], hi[0], INTERIOR_STEP), np.arange(lo[1], hi[1], INTERIOR_STEP)
        )
        grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
        grid = grid[self.outside(grid) < -INTERIOR_STEP / 2]
        self.samples = np.concatenate([edge, grid])

    def outside(self, p):
        """Signed distance-like value (N,) [m]: > 0 outside the convex outline."""
        return np.max(p @ self.normals.T - self.offsets, axis=1)


class _View:
    """The camera's rays, and the depth at which each pixel's ray meets a horizontal plane."""

    def __init__(self, camera, depth):
        self.K = np.asarray(camera["K"], dtype=float)
        T = np.asarray(camera["T_world_camera"], dtype=float)
        self.R, self.o = T[:3, :3], T[:3, 3]
        self.R_cw, self.t_cw = self.R.T, -self.R.T @ self.o
        self.depth = depth
        self.h, self.w = depth.shape

    def rays(self, u, v):
        """World directions (N, 3) with unit depth along the optical axis."""
        x = (u - self.K[0, 2]) / self.K[0, 0]
        y = (v - self.K[1, 2]) / self.K[1, 1]
        return np.stack([x, y, np.ones_like(x)], axis=-1) @ self.R.T

    def plane_depth(self, u, v, z):
        """Depth (N,) at which the rays of pixels (u, v) reach the plane at height z [m]."""
        d = self.rays(u, v)
        with np.errstate(divide="ignore", invalid="ignore"):
            return (z - self.o[2]) / d[..., 2]

    def to_plane(self, u, v, z):
        """World x, y (N, 2) where the rays of pixels (u, v) meet the plane at height z."""
        d = self.rays(u, v)
        s = (z - self.o[2]) / d[:, 2]
        return self.o[:2] + s[:, None] * d[:, :2]

    def project_plane(self, xy, z):
        """Pixels (N, 2), depths (N,) and d(u, v)/d(x, y) (N, 2, 2) of points (N, 2) at height z."""
        pc = xy @ self.R_cw[:, :2].T + (self.R_cw[:, 2] * z + self.t_cw)
        d = pc[:, 2]
        f, cx, cy = self.K[0, 0], self.K[0, 2], self.K[1, 2]
        uv = np.stack([f * pc[:, 0] / d + cx, f * pc[:, 1] / d + cy], axis=1)
        dpc = np.zeros((len(xy), 2, 3))  # d(u, v) / d(camera point)
        dpc[:, 0, 0] = f / d
        dpc[:, 0, 2] = -f * pc[:, 0] / d**2
        dpc[:, 1, 1] = f / d
        dpc[:, 1, 2] = -f * pc[:, 1] / d**2
        return uv, d, dpc @ self.R_cw[:, :2]


def _bilinear(img, grad, uv, inside):
    """Bilinear samples (N,) of img and (N, 2) of grad at pixels uv inside the image."""
    val = np.zeros(len(uv))
    g = np.zeros((len(uv), 2))
    if not inside.any():
        return val, g
    u, v = uv[inside, 0], uv[inside, 1]
    u0, v0 = np.floor(u).astype(int), np.floor(v).astype(int)
    fu, fv = u - u0, v - v0
    w = [(1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv]
    idx = [(v0, u0), (v0, u0 + 1), (v0 + 1, u0), (v0 + 1, u0 + 1)]
    val[inside] = sum(wk * img[i] for wk, i in zip(w, idx, strict=True))
    g[inside] = sum(wk[:, None] * grad[i] for wk, i in zip(w, idx, strict=True))
    return val, g


class _Piece:
    """The evidence of one piece in one image, and the fit's residuals."""

    def __init__(self, view, shape, mask, knob_mask):
        self.view, self.shape = view, shape
        rows, cols = np.nonzero(mask)
        v0, v1 = max(rows.min() - MARGIN, 0), min(rows.max() + MARGIN + 1, view.h)
        u0, u1 = max(cols.min() - MARGIN, 0), min(cols.max() + MARGIN + 1, view.w)
        self.origin = np.array([u0, v0], dtype=float)
        vv, uu = np.mgrid[v0:v1, u0:u1]
        uu, vv = uu.astype(float), vv.astype(float)
        d = view.depth[v0:v1, u0:u1]
        top_d = view.plane_depth(uu, vv, TOP)
        knob_d = view.plane_depth(uu, vv, KNOB_TOP)
        own = mask[v0:v1, u0:u1]
        valid = d > 0
        # side faces lie behind a face's plane along the ray: a narrow window on that side
        top = own & valid & (d - top_d <= SIDE_TOL) & (top_d - d <= HEIGHT_TOL)
        knob = (
            knob_mask[v0:v1, u0:u1] & valid & (d - knob_d <= SIDE_TOL) & (knob_d - d <= HEIGHT_TOL)
        )
        # where this piece's top face may be: seen, hidden by something nearer, or unknown
        allowed = top | (valid & (d < top_d - NEARER)) | (own & ~valid)
        self.dt = cv2.distanceTransform((~allowed).astype(np.uint8), cv2.DIST_L2, 5)
        gy, gx = np.gradient(self.dt)
        self.grad = np.stack([gx, gy], axis=-1)  # (h, w, 2): d dt / d (u, v)
        self.metres_per_px = float(np.median(top_d)) / view.K[0, 0]
        tv, tu = np.nonzero(top)
        if len(tu) > MAX_POINTS:  # an even, deterministic subsample
            keep = np.linspace(0, len(tu) - 1, MAX_POINTS).round().astype(int)
            tu, tv = tu[keep], tv[keep]
        self.top = view.to_plane(tu + u0, tv + v0, TOP) if len(tu) else np.zeros((0, 2))
        kv, ku = np.nonzero(knob)
        self.knob = view.to_plane(ku + u0, kv + v0, KNOB_TOP) if len(ku) else np.zeros((0, 2))
        self.n_top = int(top.sum())
        self._last = None

    def residuals(self, p, jac=False):
        """Residuals [m] (and their Jacobian (n, 3) in x, y, yaw when `jac`)."""
        x, y, yaw = p
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s], [s, c]])
        dR = np.array([[-s, -c], [c, -s]])  # d R / d yaw
        t = np.array([x, y])
        # 1. top-face points inside the outline (piece frame: Rᵀ (q − t))
        d_top = self.top - t
        local = d_top @ R
        val = local @ self.shape.normals.T - self.shape.offsets
        k = np.argmax(val, axis=1)
        r_in = np.maximum(val[np.arange(len(k)), k] - INSIDE_SLACK, 0.0)
        # 2. outline samples on pixels that are this top face or hidden
        world = self.shape.samples @ R.T + t
        uv, _, duv = self.view.project_plane(world, TOP)
        uv = uv - self.origin
        h, w = self.dt.shape
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] < h - 1)
        val, grad = _bilinear(self.dt, self.grad, uv, inside)
        over = inside & (val > 0.5)
        cover = np.where(over, (val - 0.5) * self.metres_per_px, 0.0)
        # 3. knob-top points inside the knob, which sits on the centroid
        d_knob = self.knob - t
        lk = d_knob @ R
        a = np.argmax(np.abs(lk), axis=1)
        la = lk[np.arange(len(a)), a]
        r_knob = np.maximum(np.abs(la) - KNOB_HALF - INSIDE_SLACK, 0.0)
        r = np.concatenate([r_in, cover, r_knob])
        if not jac:
            return r
        J = np.zeros((len(r), 3))
        n_world = self.shape.normals[k] @ R.T  # (n, 2): d/dq of n·Rᵀ(q − t)
        on = r_in > 0
        J[: len(k)][on, :2] = -n_world[on]
        J[: len(k)][on, 2] = np.sum(self.shape.normals[k][on] * (d_top[on] @ dR), axis=1)
        # d cover / d (x, y, yaw) = m/px · ∇dt · d uv / d world · d world / d p
        g = np.einsum("ni,nij->nj", grad, duv) * self.metres_per_px  # (n, 2) per world x, y
        dw_dyaw = self.shape.samples @ dR.T
        o = len(k)
        J[o : o + len(uv)][over, :2] = g[over]
        J[o : o + len(uv)][over, 2] = np.sum(g[over] * dw_dyaw[over], axis=1)
        o += len(uv)
        onk = r_knob > 0
        sign = np.sign(la)[onk]
        rows = R.T[a[onk]]  # d local_a / d q
        drows = dR.T[a[onk]]
        J[o:][onk, :2] = -sign[:, None] * rows
        J[o:][onk, 2] = sign * np.sum(drows * d_knob[onk], axis=1)
        return r, J

    def cost(self, p):
        r = self.residuals(p)
        return float(np.mean(np.minimum(r, 0.01) ** 2))

    def _both(self, p):
        key = tuple(np.round(p, 12))
        if self._last is None or self._last[0] != key:
            self._last = (key, *self.residuals(p, jac=True))
        return self._last[1:]

    def fit(self, period):
        # the knob top marks the centroid; without it, the top face's mean is a start
        centre = np.median(self.knob, axis=0) if len(self.knob) >= 10 else self.top.mean(axis=0)
        yaws = np.arange(0.0, period - 1e-9, YAW_STEP)
        full = (self.top, self.knob, self.shape.samples)
        # the sweep on a sparse subset of the evidence
        self.top, self.knob = full[0][::4], full[1][::4]
        self.shape = _Sparse(self.shape, 3)
        costs = [self.cost((centre[0], centre[1], a)) for a in yaws]
        self.top, self.knob, self.shape = full[0], full[1], self.shape.dense
        best, best_cost = None, np.inf
        for k in np.argsort(costs, kind="stable")[:3]:
            self._last = None
            r = least_squares(
                lambda q: self._both(q)[0],
                jac=lambda q: self._both(q)[1],
                x0=[centre[0], centre[1], yaws[k]],
                loss="soft_l1",
                f_scale=0.001,
                x_scale=[0.005, 0.005, 0.1],
                max_nfev=40,
            )
            c = self.cost(r.x)
            if c < best_cost - 1e-12:
                best, best_cost = r.x, c
            if best_cost < GOOD_FIT:  # a clean fit: the other starts cannot do better
                break
        x, y, yaw = best
        return float(x), float(y), float(yaw % period)

    def refit_apart(self, period, others):
        """The fit again from every start of the yaw sweep, now also keeping the piece out of
        `others` (fitted pieces (Shape, x, y, yaw)): pieces lie side by side, never in each
        other. Returns (x, y, yaw) and its cost with the overlap."""
        centre = np.median(self.knob, axis=0) if len(self.knob) >= 10 else self.top.mean(axis=0)

        def fun(q):
            return np.concatenate([self.residuals(q), _overlap(self.shape, q, others)])

        def cost(q):
            return float(np.mean(np.minimum(fun(q), 0.01) ** 2))

        yaws = np.arange(0.0, period - 1e-9, YAW_STEP)
        costs = [cost((centre[0], centre[1], a)) for a in yaws]
        best, best_cost = None, np.inf
        for k in np.argsort(costs, kind="stable")[:4]:
            r = least_squares(
                fun,
                x0=[centre[0], centre[1], yaws[k]],
                loss="soft_l1",
                f_scale=0.001,
                x_scale=[0.005, 0.005, 0.1],
                max_nfev=40,
            )
            c = cost(r.x)
            if c < best_cost - 1e-12:
                best, best_cost = r.x, c
        x, y, yaw = best
        return (float(x), float(y), float(yaw % period)), best_cost


def _overlap(shape, p, others):
    """How deep [m] the samples of `shape` at pose p (x, y, yaw) lie inside each of `others`
    (Shape, x, y, yaw), less OVERLAP_SLACK, per sample and other piece."""
    world = _place(shape.samples, p)
    out = []
    for other, *q in others:
        c, s = np.cos(q[2]), np.sin(q[2])
        local = (world - q[:2]) @ np.array([[c, -s], [s, c]])
        out.append(np.maximum(-other.outside(local) - OVERLAP_SLACK, 0.0))
    return np.concatenate(out) if out else np.zeros(0)


def _place(points, p):
    c, s = np.cos(p[2]), np.sin(p[2])
    return points @ np.array([[c, -s], [s, c]]).T + np.asarray(p[:2])


class _Sparse:
    """Every k-th sample of a shape (for the coarse yaw sweep)."""

    def __init__(self, shape, k):
        self.dense = shape
        self.normals, self.offsets = shape.normals, shape.offsets
        self.samples = shape.samples[::k]


def perceive(observation, meshes, camera):
    rgb = np.asarray(observation["rgb"], dtype=np.uint8)
    depth = np.asarray(observation["depth"], dtype=np.float32).astype(float)
    camera = level_camera_on_table(depth, camera)  # the table shows the calibration's tilt
    view = _View(camera, depth)
    labels = _labels(rgb)
    kernel = np.ones((3, 3), np.uint8)
    records, fits = [], {}
    for k, (oid, key) in enumerate(OBJECTS.items()):
        if key not in meshes:
            continue
        rows, cols = np.nonzero(labels == k)
        if len(rows) < MIN_PIXELS:
            continue
        v0, u0 = max(rows.min() - 2, 0), max(cols.min() - 2, 0)
        v1, u1 = min(rows.max() + 3, labels.shape[0]), min(cols.max() + 3, labels.shape[1])
        raw = np.zeros((v1 - v0, u1 - u0), np.uint8)
        raw[rows - v0, cols - u0] = 1
        crop = cv2.morphologyEx(raw, cv2.MORPH_OPEN, kernel)
        n, comp, stats, _ = cv2.connectedComponentsWithStats(crop, connectivity=8)
        big = [j for j in range(1, n) if stats[j, cv2.CC_STAT_AREA] >= MIN_PIXELS]
        if not big:
            continue
        mask = np.zeros(labels.shape, bool)
        mask[v0:v1, u0:u1] = np.isin(comp, big)
        piece = _Piece(view, _Shape(_outline(meshes[key])), mask, mask)
        if piece.n_top < MIN_PIXELS:
            continue
        period = 2 * np.pi / SYMMETRY.get(key, 1)
        fits[oid] = (piece, key, period, piece.fit(period))
    _apart(fits)
    for oid, (_, key, _, (x, y, yaw)) in fits.items():
        c, s = np.cos(yaw), np.sin(yaw)
        pose = np.array(
            [[c, -s, 0.0, x], [s, c, 0.0, y], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
        )
        records.append({"id": oid, "mesh": key, "pose": pose})
    return records


def _apart(fits):
    """Pieces fitted one by one may overlap where one is mostly hidden (its outline then fits
    several turns): fit again, kept out of the others, the piece of an overlapping pair the
    image shows less of, and keep that fit when the pair no longer overlaps."""
    for _ in range(len(fits)):
        clash = _worst_clash(fits)
        if clash is None:
            return
        a, b = clash
        weak = a if fits[a][0].n_top <= fits[b][0].n_top else b
        piece, key, period, _ = fits[weak]
        others = [(f[0].shape, *f[3]) for o, f in fits.items() if o != weak]
        new, _ = piece.refit_apart(period, others)
        if np.max(_overlap(piece.shape, new, others), initial=0.0) > OVERLAP_TOL:
            return  # no fit keeps it apart: leave the pieces as the image alone put them
        fits[weak] = (piece, key, period, new)


def _worst_clash(fits):
    """The pair of fitted pieces that overlap deepest beyond OVERLAP_TOL, or None."""
    worst, pair = OVERLAP_TOL, None
    ids = list(fits)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            A, B = fits[a], fits[b]
            depth = max(
                np.max(_overlap(A[0].shape, A[3], [(B[0].shape, *B[3])]), initial=0.0),
                np.max(_overlap(B[0].shape, B[3], [(A[0].shape, *A[3])]), initial=0.0),
            )
            if depth > worst:
                worst, pair = depth, (a, b)
    return pair
