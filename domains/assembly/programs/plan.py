# Written by people (the RIVET team), not by a model: the hand-written reference `plan` for
# the assembly domain, the level a model's program should reach. It uses numpy and the
# toolbox's exact polyhedral geometry (toolbox.stability).
"""plan(start_state, goal_state, meshes) -> plan: pick-and-place steps that rebuild the goal structure.

The parts' shapes are cut from the meshes `plan` receives into exact convex pieces
(`toolbox.Shape.from_mesh`: the arch into its legs and the slabs over its opening; the L-block
into foot and leg), so support, collision and stability are decided on the real shapes
(`toolbox.stability`), loads included: a part with everything resting only on it must keep its
joint centre of mass over its support.

1. Goal: every pose is snapped to a resting pose of its part (the nearest stable orientation,
   turned about the vertical) and dropped onto what carries it. A part floating, parts
   interpenetrating, a structure that would tip, or a part out of reach make the goal
   infeasible, with the reason.
2. Orientation: the gripper picks from above and turns parts only about the vertical, so a
   part keeps its resting pose. Each goal pose is replaced by its symmetric equivalent that a
   turn about the vertical reaches (a pillar upside down is the same pillar). A part whose
   goal needs another resting pose than its start cannot be re-oriented by this robot: no
   sequence of top-down transfers tips a part over, so the goal is declared infeasible.
3. Order (greedy construction, as a person would): every round, place a part whose goal
   supporters are already final, which nothing rests on or hangs over, whose goal spot is free
   and whose placement leaves every part standing — lowest goal first. When none can go, move
   a blocking part to a free temporary place on the table with room for the fingers (the top
   of a stack in the way, a part squatting on a goal spot). Every intermediate state is
   checked: nothing picked while loaded, no collision, every part stable.
4. The gripper (a Robotiq 2F-85 from above): a move is made only when the robot's own hand
   model (`toolbox.robot.Hand`, the one its executor and the plan checks use) finds one grasp
   with room at the pick and at the place, and when it takes no grasp away from a part still
   to move; parts in the fingers' way go aside first. Preferences, never dead ends: a
   placement that would wall in a goal place still to fill waits, and what keeps that place's
   part from going in (standing in the place, on the part or in its fingers' way) goes aside
   first, once; a temporary place is one from which the part can be taken on to its goal.
   When no order satisfies the gripper, the geometric order stands. Goals must lie inside the
   robot's workspace (`toolbox.robot.WORKSPACE`); temporary places lie in
   `toolbox.robot.PLACEMENT`.
"""

import hashlib

import numpy as np
from scipy.spatial import ConvexHull

from toolbox import Shape, collisions, separation, stable_poses, supports, unstable_objects
from toolbox.robot import (
    FINGER_DEPTH,
    GRASP_MARGINS,
    JAW_CLEARANCES,
    MAX_OPENING,
    PLACEMENT,
    WORKSPACE,
    YAW_ONLY,
    Hand,
)
from toolbox.stability import PERCEIVED_GAP, PERCEIVED_OVERLAP, RESTING_GAP, TOUCHING, VERTICAL

# a goal part perceived at most the perceived states' slack above what carries it rests on it;
# higher, it floats [m]
ON_GAP = PERCEIVED_GAP
# a part perceived within the perceived states' slack of its goal pose counts as placed [m]
SAME = PERCEIVED_GAP
TILT = np.radians(20.0)  # our choice: a goal turned farther from every resting pose is refused
# perceived states hold parts up to PERCEIVED_OVERLAP into one another (toolbox.stability):
# goal parts may overlap that much, and a part still to move that comes that near a place may
# in truth stand in it; a placement may touch others TOUCHING deep
# candidate temporary places lie on a square grid this fine: no free spot as wide as the open
# jaws' clearance is stepped over [m]
GRID = JAW_CLEARANCES[0]
# how far an open finger reaches beyond the side of the part it grips: the jaws' clearance, a
# fingertip's depth and the least margin the hand keeps (toolbox.robot.JAW_CLEARANCES,
# FINGER_DEPTH, GRASP_MARGINS)
FINGER_REACH = JAW_CLEARANCES[0] + FINGER_DEPTH + GRASP_MARGINS[-1]  # [m]
# (to parts, to unbuilt goals) [m], roomiest first: room for both fingers; then half-way to the
# open jaws' clearance and the jaws' narrower clearance to goals; then the open jaws only
CLEARANCES = (
    (FINGER_REACH, JAW_CLEARANCES[0]),
    ((FINGER_REACH + JAW_CLEARANCES[0]) / 2, JAW_CLEARANCES[1]),
    (JAW_CLEARANCES[0], 0.0),
)
# the open hand across its closing direction: the widest opening and a fingertip on each side;
# a part farther than this from another's box cannot take a grasp of it [m]
HAND_SPAN = MAX_OPENING + 2 * FINGER_DEPTH
SLIVER = 0.0002  # outlines overlapping deeper than this are above one another (not rounding) [m]
# a temporary place moves a part at least two and a half grid steps (nearer is where it
# stands; our own choice) [m]
MIN_SHIFT = 2.5 * GRID


# symmetries from the task: (kind, order about z); a part that looks the same upside down
# turns over about its middle, found from the mesh `plan` receives (`FLIP_Z`)
SYMMETRY = {
    "pillar": ("dihedral", 4),
    "beam": ("dihedral", 2),
    "block": ("dihedral", 2),
    "arch": ("cyclic", 2),
    "roof": ("cyclic", 2),
    "cylinder": ("revolution", 0),
    "lblock": ("identity", 1),
}
# each part's shape is cut from the mesh `plan` receives into exact convex pieces
# (`Shape.from_mesh`: the arch into its legs and the slabs over its opening, the L-block into
# foot and leg), at the first call that brings the mesh; with it its resting orientations and
# the turn within which it counts as in its goal orientation (one that moves no point of the
# part farther than SAME) [rad]
SHAPES = {}  # mesh key → Shape
REST = {}  # mesh key → rotations (3, 3) of its resting poses
SAME_ANGLE = {}  # mesh key → [rad]
FLIP_Z = {}  # mesh key → its lowest plus highest z: turned over about its middle, z → FLIP_Z - z
_MESH_HASH = {}  # mesh key → content hash of the mesh its shape was cut from


def _learn_shapes(meshes):
    for k, m in meshes.items():
        v = np.ascontiguousarray(np.asarray(m.vertices, dtype=np.float64))
        f = np.ascontiguousarray(np.asarray(m.faces, dtype=np.int64))
        digest = hashlib.sha1(v.tobytes() + f.tobytes()).hexdigest()
        if _MESH_HASH.get(k) == digest:
            continue
        s = Shape.from_mesh(m)
        SHAPES[k], _MESH_HASH[k] = s, digest
        REST[k] = [p.rotation for p in stable_poses(s)]
        SAME_ANGLE[k] = SAME / float(np.linalg.norm(np.concatenate(s.pieces), axis=1).max())
        FLIP_Z[k] = float(v[:, 2].min() + v[:, 2].max())
        _GEOMETRY.clear()


# a part moved out of the fingers' way keeps this far from them: a finger's reach for its own
# fingers and one for the fingers that need the room [m]
FINGER_ROOM = 2 * FINGER_REACH
SLOT_TRIES = 40  # temporary places tried for one that leaves goal places room and the
# part a grasp onwards to its goal


def _rz(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _pose(R, t):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _symmetries(mesh, yaw_free=0.0):
    """Object-frame transforms (4, 4) under which the part looks the same."""
    kind, n = SYMMETRY.get(mesh, ("identity", 1))
    if kind == "identity":
        return [np.eye(4)]
    turns = [yaw_free] if kind == "revolution" else [2 * np.pi * k / n for k in range(n)]
    out = [_pose(_rz(a), np.zeros(3)) for a in turns]
    if kind in ("dihedral", "revolution"):  # also upside down, about the centre
        flip = _pose(np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, FLIP_Z[mesh]])
        out += [T @ flip for T in out]
    return out


_GEOMETRY = {}  # (mesh, pose bytes) → (world points, outline from above, lower/upper corner)


def _geometry(mesh, T):
    key = (mesh, np.asarray(T, dtype=float).tobytes())
    got = _GEOMETRY.get(key)
    if got is None:
        if len(_GEOMETRY) > 20000:
            _GEOMETRY.clear()
        pts = np.concatenate(SHAPES[mesh].pieces) @ T[:3, :3].T + T[:3, 3]
        hull = pts[ConvexHull(pts[:, :2]).vertices, :2]
        got = _GEOMETRY[key] = (pts, hull, pts.min(axis=0), pts.max(axis=0))
    return got


def _lowest(mesh, T):
    return float(_geometry(mesh, T)[2][2])


def _footprint(mesh, T):
    """The outline (k, 2) of a posed part seen from above (convex)."""
    return _geometry(mesh, T)[1]


def _box_gap(a, b):
    """Gap [m] between two parts' axis-aligned boxes (a lower bound of their distance)."""
    (_, _, lo_a, hi_a), (_, _, lo_b, hi_b) = a, b
    return float(np.max(np.maximum(lo_a - hi_b, lo_b - hi_a)))


def _in_region(xy, x, y, reach):
    return bool(
        (xy[:, 0] >= x[0]).all()
        and (xy[:, 0] <= x[1]).all()
        and (xy[:, 1] >= y[0]).all()
        and (xy[:, 1] <= y[1]).all()
        and (np.linalg.norm(xy, axis=1) <= reach).all()
    )


def _snap_rotation(mesh, R):
    """The resting orientation Rz(yaw) @ R0 nearest to R, and the tilt [rad] between them."""
    up = R.T @ [0.0, 0.0, 1.0]  # the world's up in the object frame
    best, tilt = None, np.inf
    for R0 in REST[mesh]:
        a = float(np.arccos(np.clip(up @ (R0.T @ [0.0, 0.0, 1.0]), -1.0, 1.0)))
        if a < tilt - 1e-9:
            best, tilt = R0, a
    M = R @ best.T  # ≈ a turn about z
    return _rz(np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1])) @ best, tilt


def _reachable(mesh, current, goal):
    """The symmetric equivalent of `goal` reached from `current` by a turn about the vertical
    (the smallest), or None when it needs the part tipped into another resting pose."""
    yaw_free = 0.0
    if SYMMETRY.get(mesh, ("identity",))[0] == "revolution":  # keep the current heading
        M = goal[:3, :3].T @ current[:3, :3]
        yaw_free = float(np.arctan2(M[1, 0], M[0, 0]))
    best, best_yaw = None, np.inf
    for S in _symmetries(mesh, yaw_free):
        cand = goal @ S
        rel = cand[:3, :3] @ current[:3, :3].T
        if rel[2, 2] < np.cos(YAW_ONLY):
            continue
        yaw = abs(float(np.arctan2(rel[1, 0], rel[0, 0])))
        if yaw < best_yaw - 1e-9:
            best, best_yaw = cand, yaw
    if best is None:
        return None
    R, _ = _snap_rotation(mesh, best[:3, :3])  # exactly upright for the gripper
    return _pose(R, best[:3, 3])


def _same(mesh, a, b):
    for S in _symmetries(mesh):
        c = b @ S
        if np.linalg.norm(a[:3, 3] - c[:3, 3]) <= SAME:
            if SYMMETRY.get(mesh, ("identity",))[0] == "revolution":
                ang = np.arccos(np.clip(a[:3, 2] @ c[:3, 2], -1.0, 1.0))
            else:
                ang = np.arccos(np.clip((np.trace(a[:3, :3].T @ c[:3, :3]) - 1) / 2, -1.0, 1.0))
            if ang <= SAME_ANGLE[mesh]:
                return True
    return False


def _records(poses, mesh):
    return [{"id": i, "mesh": mesh[i], "pose": poses[i]} for i in sorted(poses)]


def _snap_goal(goal, mesh):
    """Goal poses resting exactly on what carries them, or a reason why no plan reaches them."""
    snapped = {}
    for i in sorted(goal):
        R, tilt = _snap_rotation(mesh[i], goal[i][:3, :3])
        if tilt > TILT:
            return None, f"'{i}' is tilted {np.degrees(tilt):.0f}° from every resting pose"
        snapped[i] = _pose(R, goal[i][:3, 3])
    placed = {}
    for i in sorted(snapped, key=lambda k: (_lowest(mesh[k], snapped[k]), k)):
        T = snapped[i]
        drop = _lowest(mesh[i], T)  # down to the table
        for j, U in placed.items():
            gap, axis = separation(SHAPES[mesh[i]], T, SHAPES[mesh[j]], U, cutoff=ON_GAP)
            if axis[2] >= VERTICAL and -PERCEIVED_OVERLAP <= gap < drop:
                drop = gap
        if drop > ON_GAP:
            return None, f"'{i}' floats {1000 * drop:.0f} mm above its support in the goal"
        if drop >= -PERCEIVED_OVERLAP:
            T = T.copy()
            T[2, 3] -= drop
        placed[i] = T
    recs = _records(placed, mesh)
    hits = collisions(recs, SHAPES, tolerance=PERCEIVED_OVERLAP)
    if hits:
        a, b, depth = hits[0]
        return None, f"'{a}' and '{b}' overlap by {1000 * depth:.0f} mm in the goal"
    for i, T in placed.items():
        if not _in_region(_footprint(mesh[i], T), WORKSPACE.x, WORKSPACE.y, WORKSPACE.reach):
            return None, f"'{i}' is out of the robot's reach in the goal"
    # a perceived goal's centre of mass may lie outside its support by the perceived slack
    bad = unstable_objects(recs, SHAPES, contact_tol=RESTING_GAP, margin=-PERCEIVED_OVERLAP)
    if bad:
        i = sorted(bad)[0]
        return None, f"the goal structure cannot stand: '{i}' {bad[i]}"
    return placed, ""


class _World:
    """The current poses, with the support relation of the state cached."""

    def __init__(self, poses, mesh, hand):
        self.poses, self.mesh, self.hand = dict(poses), mesh, hand
        self._sup = None

    def moved(self, i, T):
        w = _World(self.poses, self.mesh, self.hand)
        w.poses[i] = T
        return w

    @property
    def sup(self):
        if self._sup is None:
            self._sup = supports(_records(self.poses, self.mesh), SHAPES, contact_tol=RESTING_GAP)
        return self._sup

    def loaded(self):
        """Parts something rests on."""
        return {j for s in self.sup.values() for j in s}

    def hits(self, i, T, tolerance=TOUCHING, clearance=0.0, skip=()):
        """Whether part i at pose T comes closer than `clearance` to another part."""
        box = _geometry(self.mesh[i], T)
        for j, U in self.poses.items():
            if j == i or j in skip:
                continue
            if _box_gap(box, _geometry(self.mesh[j], U)) > max(clearance, 0.0) + TOUCHING:
                continue
            gap, _ = separation(
                SHAPES[self.mesh[i]], T, SHAPES[self.mesh[j]], U, cutoff=clearance + TOUCHING
            )
            if gap < (clearance if clearance > 0 else -tolerance):
                return True
        return False

    def stands(self):
        return not unstable_objects(
            _records(self.poses, self.mesh), SHAPES, contact_tol=RESTING_GAP
        )


_HANDS = {}  # (mesh key, content hash) pairs → the robot's hand model for those meshes


def _hand(meshes):
    _learn_shapes(meshes)
    key = tuple(sorted((k, _MESH_HASH[k]) for k in meshes))
    if key not in _HANDS:
        _HANDS[key] = Hand(meshes, {k: _symmetries(k) for k in meshes})
    return _HANDS[key]


def _room(world, j, G):
    """Whether some grasp of part j at pose G has room among the parts of `world`."""
    return world.hand.can_pick(_records({**world.poses, j: G}, world.mesh), j).ok


def _reach_box(mesh, T):
    """The corners (x, y) of the part's box at T grown by the open hand's span: a part whose
    box lies outside cannot be in the way of a grasp, whatever its height (the hand comes
    from above)."""
    _, _, lo, hi = _geometry(mesh, T)
    return lo[:2] - HAND_SPAN, hi[:2] + HAND_SPAN


def _takes_grasp(world, after, i, T, movers):
    """Parts of `movers` near pose T that can be picked in `world` but not once part i is at T."""
    lo, hi = _reach_box(world.mesh[i], T)
    out = []
    for j in movers:
        if j == i:
            continue
        _, _, lo_j, hi_j = _geometry(world.mesh[j], world.poses[j])
        if np.any(lo_j[:2] > hi) or np.any(hi_j[:2] < lo):
            continue
        if _room(world, j, world.poses[j]) and not _room(after, j, world.poses[j]):
            out.append(j)
    return out


def _takes_slot(world, i, T, target, pending, final, below):
    """Parts of `pending` whose goal place has room for the gripper among the `final` parts
    but not once part i is at T as well: i would wall the place in, so it had better wait.
    `below[j]`: the parts j rests on in the goal, directly or not (they go first anyway)."""
    lo, hi = _reach_box(world.mesh[i], T)
    out = []
    for j in pending:
        if j == i or i in below[j]:
            continue
        _, _, lo_j, hi_j = _geometry(world.mesh[j], target[j])
        if np.any(lo_j[:2] > hi) or np.any(hi_j[:2] < lo):
            continue
        base = _World({**final, j: target[j]}, world.mesh, world.hand)
        if _room(base, j, target[j]) and not _room(base.moved(i, T), j, target[j]):
            out.append(j)
    return out


def _move_blockers(world, i, T_to, after):
    """None when part i can be carried from where it is in `world` to `T_to` (leaving
    `after`) by one grasp that has room at both ends; else the parts in the way, most
    blocking first ([] when no grasp could be had whatever moved)."""
    verdict = world.hand.can_move(
        _records(world.poses, world.mesh), i, T_to, place_records=_records(after.poses, world.mesh)
    )
    return None if verdict.ok else [j for j in verdict.blockers if j in world.poses]


def _hangs_over(world, i, T=None):
    """Parts with a piece above part i (at its pose, or at T) whose outline overlaps it: the
    part rises and comes down vertically, so they must go first (the slab over an arch's
    opening hangs over whatever stands in the opening)."""
    mesh, poses = world.mesh, world.poses
    T = poses[i] if T is None else T
    top = _geometry(mesh[i], T)[3][2]
    fi = _footprint(mesh[i], T)
    out = []
    for j in sorted(poses):
        if j == i or _geometry(mesh[j], poses[j])[3][2] < top - RESTING_GAP:
            continue
        for lo, hull in _pieces(mesh[j], poses[j]):
            if lo >= top - RESTING_GAP and _outline_gap(fi, hull) < -SLIVER:
                out.append(j)
                break
    return out


def _pieces(mesh, T):
    """Lowest point and outline from above of every convex piece of a posed part, cached."""
    key = (mesh, "pieces", np.asarray(T, dtype=float).tobytes())
    got = _GEOMETRY.get(key)
    if got is None:
        got = []
        for p in SHAPES[mesh].pieces:
            w = p @ T[:3, :3].T + T[:3, 3]
            got.append((float(w[:, 2].min()), w[ConvexHull(w[:, :2]).vertices, :2]))
        _GEOMETRY[key] = got
    return got


def _outline_gap(a, b):
    """Gap [m] between two convex outlines (k, 2) in order (negative: overlap depth)."""
    lo = np.maximum(a.min(axis=0) - b.max(axis=0), b.min(axis=0) - a.max(axis=0)).max()
    if lo > FINGER_ROOM:  # farther than any room asked for: the boxes' gap will do
        return float(lo)
    best = -np.inf
    for h in (a, b):
        e = np.roll(h, -1, axis=0) - h
        n = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.linalg.norm(e, axis=1)[:, None]
        pa, pb = a @ n.T, b @ n.T
        best = max(best, float(np.max(np.maximum(pa.min(0) - pb.max(0), pb.min(0) - pa.max(0)))))
    return best


def _height(mesh, T):
    pts = np.concatenate(SHAPES[mesh].pieces) @ T[:3, :3].T
    return float(np.ptp(pts[:, 2]))


def _top_of(world, j):
    """The part at the top of whatever rests on or hangs over j (j itself when clear)."""
    seen = set()
    while j not in seen:
        seen.add(j)
        above = sorted(k for k in world.poses if j in world.sup[k]) or _hangs_over(world, j)
        if not above:
            return j
        j = above[0]
    return j


def _gaps(hull, others, shifts):
    """Outline gaps [m] (n, m) between `hull` moved by each of `shifts` (n, 2) and each of the
    convex outlines `others` (separating axes of both polygons, all shifts at once)."""
    out = np.full((len(shifts), len(others)), np.inf)
    for m, h in enumerate(others):
        axes = []
        for poly in (hull, h):
            e = np.roll(poly, -1, axis=0) - poly
            axes.append(np.stack([e[:, 1], -e[:, 0]], axis=1) / np.linalg.norm(e, axis=1)[:, None])
        n = np.concatenate(axes)  # (k, 2)
        pa, pb = hull @ n.T, h @ n.T
        d = shifts @ n.T  # (s, k)
        gap = np.maximum(pa.min(0) + d - pb.max(0), pb.min(0) - pa.max(0) - d)
        out[:, m] = gap.max(axis=1)
    return out


def _temporary(world, i, pending, keep=(), poor_place=None, accept=None):
    """A free place on the table for part i (same orientation), nearest to where it is, with
    room for the fingers around it seen from above (nothing overhangs it either), which
    `accept` (when given) accepts: e.g. one the gripper can carry it to."""
    mesh = world.mesh[i]
    T0 = world.poses[i].copy()
    T0[2, 3] -= _lowest(mesh, T0)
    hull = _footprint(mesh, T0)
    xs = np.arange(PLACEMENT.x[0], PLACEMENT.x[1] + 1e-9, GRID)
    ys = np.arange(PLACEMENT.y[0], PLACEMENT.y[1] + 1e-9, GRID)
    cand = np.array([(x, y) for x in xs for y in ys])
    order = np.argsort(np.linalg.norm(cand - T0[:2, 3], axis=1), kind="stable")
    cand = cand[order]
    shifts = cand - T0[:2, 3]
    corners = hull[None, :, :] + shifts[:, None, :]  # the region is convex: corners suffice
    inside = (
        (corners[..., 0] >= PLACEMENT.x[0]).all(axis=1)
        & (corners[..., 0] <= PLACEMENT.x[1]).all(axis=1)
        & (corners[..., 1] >= PLACEMENT.y[0]).all(axis=1)
        & (corners[..., 1] <= PLACEMENT.y[1]).all(axis=1)
        & (np.linalg.norm(corners, axis=2) <= PLACEMENT.reach).all(axis=1)
    )
    others = [_footprint(world.mesh[j], U) for j, U in sorted(world.poses.items()) if j != i]
    to_parts = _gaps(hull, others, shifts).min(axis=1, initial=np.inf)
    goals = [_footprint(world.mesh[j], G) for j, G in pending]
    to_goals = _gaps(hull, goals, shifts).min(axis=1, initial=np.inf)
    to_keep = _gaps(hull, list(keep), shifts).min(axis=1, initial=np.inf)
    moved = np.linalg.norm(shifts, axis=1) >= MIN_SHIFT  # a place, not where it stands
    for clearance, goal_clearance in CLEARANCES:
        ok = inside & moved & (to_parts >= clearance) & (to_goals >= goal_clearance)
        ok &= to_keep >= max(goal_clearance, FINGER_ROOM if clearance >= CLEARANCES[0][0] else 0)
        first = None
        for k in np.flatnonzero(ok)[:SLOT_TRIES]:  # rather where it does no harm
            T = T0.copy()
            T[:2, 3] = cand[k]
            if accept is not None and not accept(T):
                continue
            if poor_place is None or not poor_place(i, T):
                return T
            first = T if first is None else first
        if first is not None:
            return first
    return None


def plan(start_state, goal_state, meshes):
    start_recs = {str(r["id"]): r for r in start_state["objects"]}
    goal_recs = {str(r["id"]): r for r in goal_state["objects"]}
    if sorted(start_recs) != sorted(goal_recs):
        missing = sorted(set(start_recs) ^ set(goal_recs))
        return {
            "status": "infeasible",
            "reason": f"start shows {sorted(start_recs)} but goal shows {sorted(goal_recs)} "
            f"({', '.join(missing)} seen in only one of them)",
        }
    mesh = {i: str(r["mesh"]) for i, r in start_recs.items()}
    for i, r in goal_recs.items():
        if str(r["mesh"]) != mesh[i] or mesh[i] not in SYMMETRY or mesh[i] not in meshes:
            return {"status": "infeasible", "reason": f"'{i}' has no known shape ({mesh[i]!r})"}
    _learn_shapes(meshes)
    start = {i: np.asarray(r["pose"], dtype=float) for i, r in start_recs.items()}
    goal, why = _snap_goal({i: np.asarray(r["pose"], float) for i, r in goal_recs.items()}, mesh)
    if goal is None:
        return {"status": "infeasible", "reason": why}
    target = {}
    for i in sorted(goal):
        target[i] = _reachable(mesh[i], start[i], goal[i])
        if target[i] is None:
            return {
                "status": "infeasible",
                "reason": f"'{i}' rests on another face in the goal than at the start: the "
                "gripper picks from above and turns parts only about the vertical, so no "
                "sequence of transfers can tip it over (it needs a re-grasp from the side)",
            }
    hand = _hand(meshes)
    goal_world = _World(target, mesh, hand)
    goal_sup = {i: set(s) for i, s in goal_world.sup.items()}
    result = _build(start, goal, target, goal_sup, mesh, hand, grip=True)
    if result["status"] != "ok":  # no order leaves the fingers room: the geometric order
        result = _build(start, goal, target, goal_sup, mesh, hand, grip=False)
    return result


def _build(start, goal, target, goal_sup, mesh, hand, grip):
    """Greedy construction (see the module docstring); `grip`: every move must leave the
    gripper room at both ends."""
    world = _World(start, mesh, hand)
    goal_world = _World(target, mesh, hand)
    below = {}  # part → the parts it rests on in the goal, directly or not
    for j in sorted(goal):
        stack, seen = [j], set()
        while stack:
            for k in goal_sup[stack.pop()] - {"table"} - seen:
                seen.add(k)
                stack.append(k)
        below[j] = seen
    steps = []
    cleared_for = set()  # parts whose goal place a deferred placement would wall in
    for _ in range(3 * len(goal) + 2):
        sup = world.sup
        done = {}

        def is_done(i, sup=sup, done=done, world=world):
            if i not in done:
                done[i] = False  # guards against support cycles
                done[i] = (
                    _same(mesh[i], world.poses[i], target[i])
                    and set(sup[i]) == goal_sup[i]
                    and all(is_done(j) for j in goal_sup[i] if j != "table")
                )
            return done[i]

        if all(is_done(i) for i in goal):
            return {"status": "ok", "steps": steps}
        loaded = world.loaded()
        ready = sorted(
            (
                i
                for i in goal
                if not is_done(i) and all(is_done(j) for j in goal_sup[i] - {"table"})
            ),
            key=lambda i: (_lowest(mesh[i], target[i]), i),
        )
        move, in_the_way, deferred = None, [], None
        final = {k: U for k, U in world.poses.items() if is_done(k)}
        pending = [j for j in goal if not is_done(j)]

        def slot_taken(i, T, world=world, final=final, pending=pending):
            return bool(_takes_slot(world, i, T, target, pending, final, below))

        def stuck_there(i, T, world=world):
            """Part i put down at T could not be taken from there to its goal by one grasp
            with room at both ends (seen against the finished goal)."""
            here = world.moved(i, T)
            return not hand.can_move(
                _records(here.poses, mesh),
                i,
                target[i],
                place_records=_records(goal_world.poses, mesh),
            ).ok

        def poor_place(i, T):
            return slot_taken(i, T) or stuck_there(i, T)

        for i in ready:
            if i in loaded or _hangs_over(world, i):
                continue
            T = _reachable(mesh[i], world.poses[i], target[i])
            if T is None or world.hits(i, T):
                continue
            if world.hits(i, T, clearance=PERCEIVED_OVERLAP, skip=final):
                continue  # a part still to move may in truth stand in its place
            after = world.moved(i, T)
            if any(i in s for s in after.sup.values()) or not after.stands():
                continue  # it would slide under a part, or leave something tipping
            if any(i in _hangs_over(after, j) for j in goal if not is_done(j)):
                continue  # it would hang over a part still to be moved
            if grip:
                # no room for the fingers, something over the place (it comes down
                # vertically), or it would take away another's grasp: those must go first,
                # well away from i
                moving = _move_blockers(world, i, T, after)
                if moving == []:
                    continue  # no grasp whatever moved: nothing to clear for it
                blockers = (
                    moving or _hangs_over(world, i, T) or _takes_grasp(world, after, i, T, pending)
                )
                if blockers:
                    for j in blockers:
                        if not is_done(j):
                            in_the_way.append((j, i, T))
                    continue
                walls_in = _takes_slot(world, i, T, target, pending, final, below)
                if walls_in:  # another goal place would lose its room: later
                    deferred = deferred or (i, T, walls_in)
                    continue
            move = (i, T)
            break
        walled = [j for j in deferred[2] if j not in cleared_for] if deferred else []
        if move is None and walled:
            # before walling a place in, clear the way (once) for the part that goes there
            cleared_for.update(walled)
            move = _clear_the_way(
                world,
                walled,
                target,
                goal_sup,
                is_done,
                mesh,
                [(j, k, U) for j, k, U in in_the_way if k in walled],
                grip,
                poor_place,
                any_stack=False,
            )
            move = move if isinstance(move, tuple) else None
        move = move or (deferred and deferred[:2])  # a preference, never a dead end
        if move is None:
            move = _clear_the_way(
                world, ready, target, goal_sup, is_done, mesh, in_the_way, grip, poor_place
            )
            if isinstance(move, str):
                return {"status": "infeasible", "reason": move}
        i, T = move
        world = world.moved(i, T)
        steps.append({"object": i, "target_pose": T.tolist()})
    return {"status": "infeasible", "reason": f"no plan within {len(steps)} moves"}


def _clear_the_way(
    world, ready, target, goal_sup, is_done, mesh, in_the_way, grip, poor_place, any_stack=True
):
    """A move of one blocking part to a temporary place, or the reason there is none: a part
    in the fingers' way (`in_the_way`: (part, for part, its target)), on, over or in the goal
    place of a `ready` part, or (`any_stack`) the highest movable part of a stack in the wrong
    order."""
    keep = {}  # part → outlines it must stay clear of: where the fingers must go
    room_for = {}  # part → the moves (i, T) whose fingers it is in the way of
    for j, i, T in in_the_way:
        top = _top_of(world, j)
        keep.setdefault(top, []).extend(_footprint(mesh[i], U) for U in (world.poses[i], T))
        room_for.setdefault(top, []).append((i, T))
    candidates = list(keep)
    for i in ready:  # what stands on, over or in the way of a part that could be placed
        if i in world.loaded() or _hangs_over(world, i):
            candidates.append(_top_of(world, i))
        T = _reachable(mesh[i], world.poses[i], target[i])
        if T is None:
            continue
        after = world.moved(i, T)
        for j in sorted(world.poses, key=lambda j: (-_lowest(mesh[j], world.poses[j]), j)):
            if j == i:
                continue
            gap, _ = separation(
                SHAPES[mesh[i]], T, SHAPES[mesh[j]], world.poses[j], cutoff=2 * PERCEIVED_OVERLAP
            )
            if is_done(j):
                blocks = gap < -TOUCHING
            else:  # perceived apart from i's goal, so it may in truth stand in it
                blocks = gap < PERCEIVED_OVERLAP or i in _hangs_over(after, j)
            if blocks:
                candidates.append(_top_of(world, j))
    # a stack in the wrong order: the highest part that is not final and can be lifted
    loaded = world.loaded()
    for i in sorted(world.poses, key=lambda i: (-_lowest(mesh[i], world.poses[i]), i)):
        if any_stack and not is_done(i) and i not in loaded:
            candidates.append(i)
    seen = []
    for b in candidates:
        if b in seen:
            continue
        seen.append(b)
        pending = [(i, target[i]) for i in sorted(target) if not is_done(i) and i != b]

        def carried(T, b=b):
            """Part b put down at T leaves every part standing, and (`grip`) one grasp has
            room for the fingers at both ends, and b is out of the way of the fingers it was
            moved for."""
            after = world.moved(b, T)
            if not after.stands():
                return False
            if grip and _move_blockers(world, b, T, after) is not None:
                return False
            return not any(
                b in (_move_blockers(after, i, U, after.moved(i, U)) or ())
                for i, U in room_for.get(b, ())
            )

        T = _temporary(world, b, pending, keep.get(b, []), poor_place if grip else None, carried)
        if T is not None:
            return (b, T)
    if not seen:
        return "no part can be moved"
    return f"no free place on the table to put '{seen[0]}' down"
