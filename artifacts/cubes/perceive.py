# Written by people (the RIVET team), not by a model: the hand-written reference `perceive`
# for the cubes domain, the level a model's program should reach. It uses numpy, scipy and cv2.
"""perceive(observation, meshes, camera) -> records: the six cubes' poses from one RGB-D image.

1. Colour: each cube has its own hue; pixels are labelled by the nearest catalogue hue
   (saturated pixels only: the table and the shadows are grey), eroded by one pixel so that
   mixed colours and depth edges at silhouettes are left out.
2. Geometry: the labelled pixels' depths are back-projected to world points with the given
   camera (OpenCV convention: x right, y down, z forward; depth along the optical axis).
3. Pose: an upright cube (x, y, z, yaw) is fitted to those points by robust least squares on
   the box's signed distance, from a few starting yaws; cubes are upright in this domain, so
   only the yaw is estimated, and the height is snapped to the stacking levels when close.
   A barely seen cube is slid to where it explains its points without covering what the
   image shows behind it (a farther surface, or another cube's colour), at its own yaw or a
   well-seen neighbour's (a sliver of a top face pins the yaw down little). How much of a
   cube the image shows is counted in faces seen square-on at its distance, so that these
   rules hold for any camera; a fit whose centre lies under the table is colour blends along
   other cubes' edges, not a cube.
4. Hidden cubes: a cube the camera does not show that holds up a cube it does goes under that
   cube (a tower's lower cubes, a pyramid's base); one that holds nothing up still is one of
   the six: it goes where the image allows it, on the table clear of the others and hidden
   from the camera, as close to the cubes that hide it as can be, in line with one of them
   at the rows' 6 mm gap when that is hardly farther.
The noise of a stereo sensor (≈1–2 mm, dropouts at edges) averages out over the hundreds of
points of each face.
"""

import cv2
import numpy as np
from scipy.optimize import least_squares

from toolbox.robot import PLACEMENT
from toolbox.vision import level_camera_on_table

HUES = {  # catalogue colour → hue [deg] as rendered
    "red": 0.0,
    "green": 127.0,
    "blue": 226.0,
    "yellow": 51.0,
    "purple": 278.0,
    "cyan": 186.0,
}
HUE_TOL = 20.0  # [deg]
SAT_MIN = 0.35
VAL_MIN = 0.10
MIN_PIXELS = 10
# How much of a cube the image shows is counted in faces: its pixels over the pixels of one
# face seen square-on at the cube's distance, (f · side / distance)², so that the thresholds
# hold for any camera (a 960×540 camera 0.9 m away shows a cube a fifth of the pixels the
# front view, 1280×720 at 0.6 m, does). A cube seen by fewer than WEAK_FACES is placed by
# physics when needed; by fewer than REFINE_FACES it is placed using free space as well (a
# pyramid's supporters half hidden behind a tower show ~0.5–0.6 of a face and slide along the
# faces they show; a cube beside or behind a tower, one side and part of its top seen,
# 0.7–1.2, and slides 12–21 mm), and a cube seen by at least FIRM_FACES (not cut by the
# border) holds its place against the others' refinement (cubes near the middle of the view
# show up to ~3 faces, half of them fewer than 1.4). Chosen on our own drawn scenes of a cube
# behind a tower (`python -m benchmarks.occlusion_bench`, seeds 100–219), as 1500, 4500 and
# 2500 pixels of the front view (a face there: 3530 pixels)
WEAK_FACES = 0.425
REFINE_FACES = 1.275
FIRM_FACES = 0.71
BELOW_TABLE = 0.005  # a fit whose centre lies this far below a cube on the table is none [m]
EXPLAINED = 0.003  # a point this close to another cube's surface belongs to that cube [m]
MAX_POINTS = 500  # per cube, for speed
# a cube nothing shows goes to a spot on the table hidden from the camera: candidate centres
# on a grid beside each placed cube (in its frame, up to three cube sides away) [m]
UNSEEN_STEPS = np.arange(-0.12, 0.12001, 0.005)
# every other cube's footprint grown by this on each side must not overlap it (by more than
# `_overlap`'s 3 mm): the spot keeps at least 1 mm from the others [m]
UNSEEN_CLEARANCE = 0.002
UNSEEN_MARGIN = 0.005  # a face sample this much behind the observed surface is hidden [m]
UNSEEN_SHOWN = 0.05  # a spot whose faces show this little (noise, dropouts) counts as hidden
ROW_GAP = 0.006  # the task text: "cubes in a row or a pyramid's base stand 6 mm apart" [m]
# a pixel showing another cube's colour is that cube's surface: a candidate face in front of
# it, or level with it within this (depth noise), would hide it [m]
LABEL_MARGIN = 0.003
NEIGHBOUR_REACH = 0.12  # a well-seen cube this near a barely seen one lends it its yaw [m]


def _labels(rgb):
    """Per-pixel cube index into HUES (-1: not a cube)."""
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV_FULL)  # uint8: hue in 256ths of a turn
    ok = (hsv[..., 1] >= SAT_MIN * 255) & (hsv[..., 2] >= VAL_MIN * 255)
    labels = np.full(rgb.shape[:2], -1, dtype=np.int32)
    v, u = np.nonzero(ok)
    h = hsv[v, u, 0].astype(np.float32) * (360.0 / 256.0)
    hues = np.array(list(HUES.values()), dtype=np.float32)
    d = np.abs((h[:, None] - hues + 180.0) % 360.0 - 180.0)  # (n, 6)
    best = np.argmin(d, axis=1)
    near = d[np.arange(len(h)), best] <= HUE_TOL
    labels[v[near], u[near]] = best[near]
    return labels


def _points(mask, depth, camera):
    K = np.asarray(camera["K"], dtype=float)
    T = np.asarray(camera["T_world_camera"], dtype=float)
    v, u = np.nonzero(mask & (depth > 0))
    if len(u) > MAX_POINTS:  # an even, deterministic subsample
        keep = np.linspace(0, len(u) - 1, MAX_POINTS).round().astype(int)
        u, v = u[keep], v[keep]
    z = depth[v, u].astype(float)
    x = (u - K[0, 2]) * z / K[0, 0]
    y = (v - K[1, 2]) * z / K[1, 1]
    cam = np.stack([x, y, z], axis=1)
    return cam @ T[:3, :3].T + T[:3, 3]


def _local(params, pts):
    x, y, z, yaw = params
    c, s = np.cos(yaw), np.sin(yaw)
    d = pts - (x, y, z)
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)


def _residuals(params, pts, half):
    q = np.abs(_local(params, pts)) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    inside = np.minimum(q.max(axis=1), 0.0)
    return outside + inside  # signed distance to the box surface [m]


def _jacobian(params, pts, half):
    """d residual / d (x, y, z, yaw), (n, 4): the distance gradient moved into the world."""
    x, y, z, yaw = params
    c, s = np.cos(yaw), np.sin(yaw)
    d = pts - (x, y, z)
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
    q = np.abs(local) - half
    pos = np.maximum(q, 0.0)
    norm = np.linalg.norm(pos, axis=1)
    grad = np.sign(local) * pos / np.maximum(norm, 1e-12)[:, None]  # outside the box
    inside = norm <= 1e-12
    k = np.argmax(q, axis=1)
    face = np.zeros_like(local)
    face[np.arange(len(pts)), k] = np.sign(local[np.arange(len(pts)), k])
    grad[inside] = face[inside]
    A = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    dA = np.array([[-s, c, 0.0], [-c, -s, 0.0], [0.0, 0.0, 0.0]])
    jac = np.empty((len(pts), 4))
    jac[:, :3] = -(grad @ A)
    jac[:, 3] = np.sum(grad * (d @ dA.T), axis=1)
    return jac


def _hidden_faces(params, pts, eye):
    """Fraction of points that would lie on a face turned away from the camera."""
    local = _local(params, pts)
    axis = np.argmax(np.abs(local), axis=1)
    normal = np.zeros_like(local)
    normal[np.arange(len(pts)), axis] = np.sign(local[np.arange(len(pts)), axis])
    c, s = np.cos(params[3]), np.sin(params[3])
    world = np.stack(
        [c * normal[:, 0] - s * normal[:, 1], s * normal[:, 0] + c * normal[:, 1], normal[:, 2]],
        axis=1,
    )
    return float(np.mean(np.sum(world * (eye - pts), axis=1) < 0))


def _fit(pts, half, eye):
    """Upright cube (x, y, z, yaw) explaining the points, its visible faces towards `eye`."""
    top_z = float(np.percentile(pts[:, 2], 98))
    top = pts[pts[:, 2] >= top_z - 0.006]
    yaw0 = 0.0
    if len(top) >= 30:
        (_, _), (_, _), angle = cv2.minAreaRect((top[:, :2] * 1000).astype(np.float32))
        yaw0 = np.radians(angle)
    away = pts[:, :2].mean(axis=0) - eye[:2]
    away /= max(np.linalg.norm(away), 1e-9)
    starts = [pts[:, :2].mean(axis=0) + away * half * 0.7]
    if len(top) >= 30:
        starts.append(top[:, :2].mean(axis=0))
    best, best_score = None, np.inf
    for xy0 in starts:
        for dyaw in (0.0, np.pi / 4):
            r = least_squares(
                _residuals,
                x0=[xy0[0], xy0[1], top_z - half, yaw0 + dyaw],
                args=(pts, half),
                jac=_jacobian,
                loss="soft_l1",
                f_scale=0.002,
                x_scale=[0.01, 0.01, 0.01, 0.3],
                max_nfev=40,
            )
            score = r.cost / len(pts) + 1e-4 * _hidden_faces(r.x, pts, eye)
            if score < best_score:
                best, best_score = r.x, score
    x, y, z, yaw = best
    return np.array([x, y, z, (yaw + np.pi / 4) % (np.pi / 2) - np.pi / 4]), top_z


def _face_samples(half, n=6):
    """Points (k, 3) and outward normals (k, 3) on the top and the four sides of a cube."""
    t = (np.arange(n) + 0.5) / n * 2 * half - half
    a, b = np.meshgrid(t, t)
    a, b = a.ravel(), b.ravel()
    pts, normals = [], []
    for axis, sign in ((2, 1.0), (0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)):
        p = np.zeros((len(a), 3))
        others = [i for i in range(3) if i != axis]
        p[:, axis] = sign * half
        p[:, others[0]], p[:, others[1]] = a, b
        nrm = np.zeros(3)
        nrm[axis] = sign
        pts.append(p)
        normals.append(np.tile(nrm, (len(a), 1)))
    return np.concatenate(pts), np.concatenate(normals)


def _free_space(p, pts, half, depth, labels, k, camera, firm, others):
    """Slide a barely seen cube to where it explains its points without hiding what the camera
    sees behind it (its visible faces must not lie in front of farther observed surfaces, nor
    cover pixels that show another cube's colour at their depth or beyond: a cube half hidden
    behind another slides toward its neighbours behind it unless their faces pin it).

    Each candidate place rests on the table or on the `others` under it, so a sliver of a
    cube on top of a stack is put on the stack, not in it; it may not overlap a well-seen
    cube (`firm`) at its own level. A sliver pins the yaw down little: the turns of the
    well-seen cubes next to it compete with its own fit (cubes in a row share one).
    """

    def turn(a, b):  # a cube's yaw a - b, wrapped to a quarter turn
        return (a - b + np.pi / 4) % (np.pi / 2) - np.pi / 4

    yaws = [p[3]]
    for q in firm:
        near = np.linalg.norm(q[:2] - p[:2]) < NEIGHBOUR_REACH
        if near and all(abs(turn(q[3], y)) > 0.05 for y in yaws):
            yaws.append(p[3] + turn(q[3], p[3]))
    tried = [_slide([*p[:3], y], pts, half, depth, labels, k, camera, firm, others) for y in yaws]
    return min(tried, key=lambda scored: scored[0])[1]


def _slide(p, pts, half, depth, labels, k, camera, firm, others):
    """(score, place) of `_free_space` at the yaw p[3]: the best spot near p."""
    K = np.asarray(camera["K"], dtype=float)
    T = np.asarray(camera["T_world_camera"], dtype=float)
    R_cw, t_cw = T[:3, :3].T, -T[:3, :3].T @ T[:3, 3]
    samples, normals = _face_samples(half, n=10)
    c, s = np.cos(p[3]), np.sin(p[3])
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    local_pts, world_n = samples @ Rz.T, normals @ Rz.T
    offsets = np.arange(-0.035, 0.03501, 0.0025)
    grid = np.array([(p[0] + dx, p[1] + dy) for dx in offsets for dy in offsets])  # (g, 2)
    # at least the level its points show: what holds it up may be hidden
    levels = np.full(len(grid), half + 2 * half * max(0, round((p[2] - half) / (2 * half))))
    top = float(np.percentile(pts[:, 2], 98))
    spots = np.c_[grid, levels, np.full(len(grid), p[3])]  # (g, 4)
    for q in sorted(others, key=lambda q: q[2]):
        if q[2] + half > top - 0.005:
            continue  # not below what is seen of this cube: it cannot hold it up
        on_it = _overlaps(spots, q, half)
        levels[on_it] = np.maximum(levels[on_it], q[2] + 2 * half)
    centres = np.c_[grid, levels]  # (g, 3)
    world = centres[:, None, :] + local_pts[None]  # (g, k, 3)
    eye = T[:3, 3]
    visible = np.einsum("gkj,kj->gk", eye - world, world_n) > 0
    cam = world @ R_cw.T + t_cw
    z = cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.round(K[0, 0] * cam[..., 0] / z + K[0, 2]).astype(int)
        v = np.round(K[1, 1] * cam[..., 1] / z + K[1, 2]).astype(int)
    h, w = depth.shape
    inside = visible & (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    uc, vc = np.clip(u, 0, w - 1), np.clip(v, 0, h - 1)
    observed = depth[vc, uc]
    shown = labels[vc, uc]
    beyond = observed > z + 0.008  # a farther surface shows where the face would be
    other_cube = (shown >= 0) & (observed > z - LABEL_MARGIN)  # another cube shows there
    seen_through = inside & (observed > 0) & (shown != k) & (beyond | other_cube)
    violation = seen_through.sum(axis=1) / np.maximum(inside.sum(axis=1), 1)
    # the points' distances to the cube at each candidate (`_residuals`, all at once)
    d = pts[None, :, :] - centres[:, None, :]  # (g, n, 3)
    local = np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1], d[..., 2]], -1)
    q = np.abs(local) - half
    r = np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)
    cost = np.mean(np.minimum(np.abs(r), 0.005), axis=1)
    for f in firm:
        cost[(np.abs(f[2] - levels) < half) & _overlaps(spots, f, half)] += 0.01
    score = cost + 0.004 * violation
    best = int(np.argmin(score))
    return float(score[best]), np.array([grid[best][0], grid[best][1], levels[best], p[3]])


def _overlap(a, b, half):
    """Whether the footprints of two upright cubes (x, y, z, yaw) overlap by more than 3 mm."""
    for p in (a, b):
        for yaw in (p[3], p[3] + np.pi / 2):
            axis = np.array([np.cos(yaw), np.sin(yaw)])
            ca, cb = a[:2] @ axis, b[:2] @ axis
            ra = half * (abs(np.cos(a[3] - yaw)) + abs(np.sin(a[3] - yaw)))
            rb = half * (abs(np.cos(b[3] - yaw)) + abs(np.sin(b[3] - yaw)))
            if abs(ca - cb) > ra + rb - 0.003:
                return False
    return True


def _settle(fits, missing, half):
    """Rest every cube on the table or on the cubes under it, lowest first.

    A cube seen a level or more above whatever is under it stands on a cube hidden from the
    camera: one of the `missing` ids is put there.
    """
    placed = {}
    for name, (p, _top, _) in sorted(fits.items(), key=lambda kv: (kv[1][1], kv[0])):
        p = p.copy()
        below = [q for q in placed.values() if _overlap(p, q, half)]
        base = max((q[2] + 2 * half for q in below), default=half)
        while p[2] - base > 1.5 * half and missing:
            hidden = np.array([p[0], p[1], base, p[3]])
            placed[missing.pop(0)] = hidden
            base += 2 * half
        p[2] = base
        placed[name] = p
    return placed


def _over(p, q, half):
    """Whether the centre of cube p lies over the footprint of cube q."""
    c, s = np.cos(q[3]), np.sin(q[3])
    d = p[:2] - q[:2]
    return abs(c * d[0] + s * d[1]) <= half and abs(-s * d[0] + c * d[1]) <= half


def _column_fits(p, q, pts, half):
    """Whether a barely seen cube's points lie on it centred under the cube p above it as well
    as on its own fit q (within 2 mm, or within 3 mm of its surface at all)."""
    aligned = np.array([p[0], p[1], q[2], p[3]])
    fitted = float(np.median(np.abs(_residuals(q, pts, half))))
    there = float(np.median(np.abs(_residuals(aligned, pts, half))))
    return there <= max(0.003, fitted + 0.002)


def _repair(fits, placed, half, missing, clouds):
    """Put barely seen or unseen cubes where the cubes above them need them.

    In a pyramid an upper cube rests centred between two cubes. When it would rest on a
    single cube, off-centre, the second supporter is hidden: an unseen cube (or the barely
    seen one nearest) goes to the mirror image of the first about the upper cube's centre.
    When a barely seen cube is one of two supporters, it is centred the same way. A barely
    seen cube that is the only support of the cube above it (a column) is centred under it
    when what shows of it agrees: a sliver of a face pins down little, the cube above it more.
    """
    weak = {n for n, (_, _, faces) in fits.items() if faces < WEAK_FACES}
    weak |= set(placed) - set(fits)
    unseen = [n for n in missing if n not in placed]
    for _ in range(len(placed) + len(unseen)):
        changed = False
        for name in sorted(placed, key=lambda n: (placed[n][2], n)):
            p = placed[name]
            if p[2] < 2 * half:
                continue
            under = [
                n
                for n, q in placed.items()
                if n != name and abs(p[2] - q[2] - 2 * half) < 1e-6 and _overlap(p, q, half)
            ]
            if len(under) == 2 and sum(n in weak for n in under) == 1:
                b, a = sorted(under, key=lambda n: n not in weak)  # b: the weak one
                spot = np.array(
                    [2 * p[0] - placed[a][0], 2 * p[1] - placed[a][1], placed[b][2], placed[a][3]]
                )
                if 1e-4 < np.linalg.norm(spot[:2] - placed[b][:2]) < 0.015:
                    placed[b] = spot
                    changed = True
                continue
            if len(under) != 1:
                continue
            a = placed[under[0]]
            if _over(p, a, half):
                b = under[0]
                moved = np.hypot(*(p[:2] - a[:2])) > 1e-4 or abs(p[3] - a[3]) > 1e-4
                if b in weak and b in clouds and moved and _column_fits(p, a, clouds[b][0], half):
                    placed[b] = np.array([p[0], p[1], a[2], p[3]])
                    changed = True
                    break
                continue
            spot = np.array([2 * p[0] - a[0], 2 * p[1] - a[1], a[2], a[3]])
            options = [n for n in weak if n not in (name, under[0])]
            if not unseen and under[0] in weak:  # a column: the barely seen cube is under it
                placed[under[0]] = np.array([p[0], p[1], a[2], p[3]])
            elif unseen:
                new = unseen.pop(0)
                weak.add(new)
                placed[new] = spot
            elif options:
                x = min(options, key=lambda n: (np.linalg.norm(placed[n][:2] - spot[:2]), n))
                placed[x] = spot
            else:
                continue
            changed = True
            break  # the supports changed: look again from the bottom
        if not changed:
            break
    return placed


def _overlaps(spots, q, half):
    """`_overlap` of many upright cubes `spots` (n, 4) sharing one yaw with cube q: (n,) bool."""
    hit = np.ones(len(spots), bool)
    for yaw in (spots[0, 3], spots[0, 3] + np.pi / 2, q[3], q[3] + np.pi / 2):
        axis = np.array([np.cos(yaw), np.sin(yaw)])
        ra = half * (abs(np.cos(spots[0, 3] - yaw)) + abs(np.sin(spots[0, 3] - yaw)))
        rb = half * (abs(np.cos(q[3] - yaw)) + abs(np.sin(q[3] - yaw)))
        hit &= np.abs(spots[:, :2] @ axis - q[:2] @ axis) <= ra + rb - 0.003
    return hit


def _shown(centres, yaw, half, depth, camera):
    """Per centre (n, 3): the fraction of a cube's faces turned to the camera that the depth
    image shows, samples inside the image that nothing observed lies in front of (a dropout
    shows nothing); the cubes share the yaw."""
    K = np.asarray(camera["K"], dtype=float)
    T = np.asarray(camera["T_world_camera"], dtype=float)
    samples, normals = _face_samples(half, n=4)
    c, s = np.cos(yaw), np.sin(yaw)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    world = centres[:, None, :] + (samples @ Rz.T)[None]  # (n, k, 3)
    facing = np.einsum("nkj,kj->nk", T[:3, 3] - world, normals @ Rz.T) > 0
    cam = (world - T[:3, 3]) @ T[:3, :3]
    z = cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.round(K[0, 0] * cam[..., 0] / z + K[0, 2])
        v = np.round(K[1, 1] * cam[..., 1] / z + K[1, 2])
    h, w = depth.shape
    inside = facing & (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    uc = np.clip(np.nan_to_num(u), 0, w - 1).astype(int)
    vc = np.clip(np.nan_to_num(v), 0, h - 1).astype(int)
    observed = depth[vc, uc]
    shown = inside & (observed > 0) & (observed > z - UNSEEN_MARGIN)
    return shown.sum(axis=1) / np.maximum(facing.sum(axis=1), 1)


def _unseen_spot(placed, half, depth, camera):
    """Where a cube the camera does not show at all, and that holds nothing up, stands: on the
    table, clear of every other cube, where the camera cannot see it (behind the cubes that
    hide it), inside the placement region, as close to the placed cubes as can be — or in line
    with one of them at the rows' pitch when that is hidden and hardly farther (a goal's rows
    and pyramid bases stand `ROW_GAP` apart): the nearest of the places the image allows."""
    pitch = 2 * half + ROW_GAP
    rows = np.arange(-2, 3) * pitch  # a level-0 cube's row neighbours: whole pitches
    halves = (np.arange(-2, 2) + 0.5) * pitch  # an upper cube's supporters: half pitches
    others = list(placed.values())
    found = []  # (spots (n, 4), on a row (n,), shown (n,), distance to the nearest cube (n,))
    for q in others:
        on_row = rows if q[2] < 2 * half else halves
        steps = [(a, b, False) for a in UNSEEN_STEPS for b in UNSEEN_STEPS]
        steps += [(a, b, True) for a in on_row for b in on_row]
        a, b, row = (np.array(v) for v in zip(*steps, strict=True))
        c, s = np.cos(q[3]), np.sin(q[3])
        spots = np.c_[q[0] + c * a - s * b, q[1] + s * a + c * b]
        spots = np.c_[spots, np.full(len(a), half), np.full(len(a), q[3])]
        # the task's scenes keep every object inside PLACEMENT
        ok = (PLACEMENT.x[0] <= spots[:, 0]) & (spots[:, 0] <= PLACEMENT.x[1])
        ok &= (PLACEMENT.y[0] <= spots[:, 1]) & (spots[:, 1] <= PLACEMENT.y[1])
        for o in others:
            ok &= ~_overlaps(spots, o, half + UNSEEN_CLEARANCE)
        if ok.any():
            spots, row = spots[ok], row[ok]
            far = np.min([np.linalg.norm(spots[:, :2] - o[:2], axis=1) for o in others], axis=0)
            found.append((spots, row, _shown(spots[:, :3], q[3], half, depth, camera), far))
    if not found:  # no cube seen, or no room near them: the middle of the placement region
        return np.array([np.mean(PLACEMENT.x), np.mean(PLACEMENT.y), half, 0.0])
    spots, row, shown, far = (np.concatenate(v) for v in zip(*found, strict=True))
    hidden = shown <= UNSEEN_SHOWN
    if not hidden.any():
        return spots[int(np.lexsort((far, shown))[0])]
    nearest = far[hidden].min()
    in_line = hidden & row & (far <= nearest + ROW_GAP)
    pick = in_line if in_line.any() else hidden
    return spots[pick][int(np.argmin(far[pick]))]


def perceive(observation, meshes, camera):
    rgb = np.asarray(observation["rgb"], dtype=np.uint8)
    depth = np.asarray(observation["depth"], dtype=np.float32)
    camera = level_camera_on_table(depth, camera)  # the table shows the calibration's tilt
    key = "cube" if "cube" in meshes else sorted(meshes)[0]
    half = float(np.max(np.abs(np.asarray(meshes[key].vertices))))
    eye = np.asarray(camera["T_world_camera"], dtype=float)[:3, 3]
    focal = float(np.asarray(camera["K"], dtype=float)[0, 0])
    labels = _labels(rgb)
    kernel = np.ones((3, 3), np.uint8)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    fits, clouds = {}, {}
    for k, name in enumerate(HUES):
        raw = labels == k
        mask = cv2.erode(raw.astype(np.uint8), kernel).astype(bool)
        if mask.sum() < 3 * MIN_PIXELS:  # barely visible: keep all but one-pixel lines, which
            opened = cv2.morphologyEx(raw.astype(np.uint8), cv2.MORPH_OPEN, cross)
            mask = opened.astype(bool) if opened.sum() >= MIN_PIXELS else raw  # are blends
        pts = _points(mask, depth, camera)
        if len(pts) >= MIN_PIXELS:
            p, top = _fit(pts, half, eye)
            if p[2] < half - BELOW_TABLE:
                # a cube under the table: its few pixels are colour blends along other cubes'
                # edges with the depth of what lies behind, not a face; it counts as unseen
                continue
            face = (focal * 2 * half / np.linalg.norm(p[:3] - eye)) ** 2  # [px]
            fits[name] = (p, top, float(raw.sum()) / face)
            # a cube cut by the image border is as uncertain as a barely seen one
            cut = raw[:2].any() or raw[-2:].any() or raw[:, :2].any() or raw[:, -2:].any()
            clouds[name] = (pts, k, cut)
    for name, (p, top, shown) in list(fits.items()):
        pts, k, cut = clouds[name]
        if shown < REFINE_FACES or cut:
            firm = [
                q
                for n, (q, _, faces) in fits.items()
                if n != name and faces >= FIRM_FACES and not clouds[n][2]
            ]
            # points on another cube's surface are colour blends at its edges, not evidence
            keep = np.ones(len(pts), bool)
            for q in firm:
                keep &= np.abs(_residuals(q, pts, half)) > EXPLAINED
            if keep.sum() < MIN_PIXELS:
                del fits[name]
                continue
            if not keep.all():
                pts = pts[keep]
                p, top = _fit(pts, half, eye)
            others = [q for n, (q, _, _) in fits.items() if n != name]
            p = _free_space(p, pts, half, depth, labels, k, camera, firm, others)
            fits[name] = (p, top, shown)
    missing = [n for n in HUES if n not in fits]
    placed = _settle(fits, list(missing), half)
    placed = _repair(fits, placed, half, missing, clouds)
    for name in missing:  # shown nowhere and holding nothing up: still one of the six
        if name not in placed:
            placed[name] = _unseen_spot(placed, half, depth, camera)
    records = []
    for name in HUES:
        if name not in placed:
            continue
        x, y, z, yaw = placed[name]
        c, s = np.cos(yaw), np.sin(yaw)
        pose = np.array([[c, -s, 0.0, x], [s, c, 0.0, y], [0.0, 0.0, 1.0, z], [0.0, 0.0, 0.0, 1.0]])
        records.append({"id": name, "mesh": key, "pose": pose})
    return records
