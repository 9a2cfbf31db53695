# A realistic failing draft, kept to show what the checks reject (not a reference program).
# plan v1 is the first version of the reference plan. It let a goal placement touch the
# parts already there as deeply as it tolerates overlaps between perceived goal parts (3 mm),
# so a part put down beside one still at its start position can sink into it; it judged
# "hangs over" by axis-aligned bounding boxes of the footprints (a beam turned 64° "hangs
# over" a block lying beside its spot) and kept temporary places clear of unbuilt goals only
# in 3D (a place under a beam's goal is 50 mm below it, so "clear"); and it would place a part
# over one that must still be picked, which then cannot be reached from above and is moved
# back and forth until the move budget runs out. `rivet check assembly plan
# domains/assembly/programs/drafts/plan_v1.py --deps domains/assembly/programs` fails
# `property.reaches_goal` (a collision after a step, or "infeasible" on a reachable goal);
# on the 60 benchmark instances 13 of its plans fail.
"""plan(start_state, goal_state, meshes) -> plan: pick-and-place steps that rebuild the goal structure.

The parts' shapes come from the task's dimensions as convex pieces (the arch: two legs and
sixteen slabs over its half-round opening; the L-block: foot and leg), so support, collision
and stability are decided on the real shapes (`toolbox.stability`), loads included: a part
with everything resting only on it must keep its joint centre of mass over its support.

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
"""

import itertools

import numpy as np
from scipy.spatial import ConvexHull

from toolbox import Shape, collisions, separation, stable_poses, supports, unstable_objects
from toolbox.robot import PLACEMENT, WORKSPACE

DEPTH = 0.035  # extrusion depth of the profiled parts [m]
ON_GAP = 0.008  # a goal part at most this far above its support rests on it [m]
SAME = 0.004  # a part this close to its goal pose counts as placed [m]
SAME_ANGLE = np.radians(4.0)
TILT = np.radians(20.0)  # a goal orientation farther than this from every resting pose
GOAL_OVERLAP = 0.003  # goal parts may interpenetrate this much (perception noise) [m]
TOUCH = 0.001  # a placement may touch others this deep [m]
GRID = 0.01  # spacing of candidate temporary places [m]
CLEARANCES = ((0.03, 0.01), (0.015, 0.005), (0.008, 0.0))  # (to parts, to unbuilt goals) [m]


def _box(sx, sy, sz, x0=0.0, z0=0.0):
    return np.array(
        [
            (x0 + a * sx / 2, b * sy / 2, z0 + c * sz)
            for a in (-1, 1)
            for b in (-1, 1)
            for c in (0, 1)
        ]
    )


def _profile(xz):
    """A convex x–z polygon extruded by DEPTH along y."""
    xz = np.asarray(xz, dtype=float)
    return np.concatenate([np.c_[xz[:, 0], np.full(len(xz), y), xz[:, 1]] for y in (-1, 1)]) * [
        1,
        DEPTH / 2,
        1,
    ]


def _arch():
    w, h, r, spring = 0.06, 0.065, 0.03, 0.02
    t = np.linspace(np.pi, 0.0, 17)
    arc = np.c_[r * np.cos(t), spring + r * np.sin(t)]
    pieces = [_profile([(-w, 0), (-r, 0), (-r, h), (-w, h)])]
    for a, b in itertools.pairwise(arc):
        pieces.append(_profile([a, b, (b[0], h), (a[0], h)]))
    pieces.append(_profile([(r, 0), (w, 0), (w, h), (r, h)]))
    return pieces


def _cylinder(radius=0.02, height=0.06, sides=48):
    t = np.arange(sides) * 2 * np.pi / sides
    ring = np.c_[radius * np.cos(t), radius * np.sin(t)]
    return [np.concatenate([np.c_[ring, np.zeros(sides)], np.c_[ring, np.full(sides, height)]])]


PIECES = {  # the task's parts, origin at the centre of the bottom of their upright bounding box
    "pillar": [_box(0.03, 0.03, 0.08)],
    "beam": [_box(0.16, DEPTH, 0.02)],
    "block": [_box(0.05, DEPTH, 0.03)],
    "cylinder": _cylinder(),
    "roof": [_profile([(-0.07, 0), (0.07, 0), (0, 0.04)])],
    "lblock": [_box(0.08, DEPTH, 0.03), _box(0.03, DEPTH, 0.04, x0=-0.025, z0=0.03)],
    "arch": _arch(),
}
# symmetries from the task: (kind, order about z, half height for the flip)
SYMMETRY = {
    "pillar": ("dihedral", 4, 0.04),
    "beam": ("dihedral", 2, 0.01),
    "block": ("dihedral", 2, 0.015),
    "arch": ("cyclic", 2, 0.0),
    "roof": ("cyclic", 2, 0.0),
    "cylinder": ("revolution", 0, 0.03),
    "lblock": ("identity", 1, 0.0),
}
SHAPES = {k: Shape.from_pieces(v) for k, v in PIECES.items()}
REST = {k: [p.rotation for p in stable_poses(s)] for k, s in SHAPES.items()}


def _rz(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _pose(R, t):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _symmetries(mesh, yaw_free=0.0):
    """Object-frame transforms (4, 4) under which the part looks the same."""
    kind, n, half = SYMMETRY.get(mesh, ("identity", 1, 0.0))
    if kind == "identity":
        return [np.eye(4)]
    turns = [yaw_free] if kind == "revolution" else [2 * np.pi * k / n for k in range(n)]
    out = [_pose(_rz(a), np.zeros(3)) for a in turns]
    if kind in ("dihedral", "revolution"):  # also upside down, about the centre
        flip = _pose(np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, 2 * half])
        out += [T @ flip for T in out]
    return out


def _lowest(mesh, T):
    pts = np.concatenate(SHAPES[mesh].pieces)
    return float((pts @ T[:3, :3].T + T[:3, 3])[:, 2].min())


def _footprint(mesh, T):
    pts = np.concatenate(SHAPES[mesh].pieces)
    return (pts @ T[:3, :3].T + T[:3, 3])[:, :2]


def _in_region(xy, region):
    return bool(
        (xy[:, 0] >= region.x[0]).all()
        and (xy[:, 0] <= region.x[1]).all()
        and (xy[:, 1] >= region.y[0]).all()
        and (xy[:, 1] <= region.y[1]).all()
        and (np.linalg.norm(xy, axis=1) <= region.reach).all()
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
        if rel[2, 2] < np.cos(np.radians(3.0)):
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
            if ang <= SAME_ANGLE:
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
            gap, axis = separation(SHAPES[mesh[i]], T, SHAPES[mesh[j]], U, cutoff=0.02)
            if axis[2] >= 0.7 and -GOAL_OVERLAP <= gap < drop:
                drop = gap
        if drop > ON_GAP:
            return None, f"'{i}' floats {1000 * drop:.0f} mm above its support in the goal"
        if drop >= -GOAL_OVERLAP:
            T = T.copy()
            T[2, 3] -= drop
        placed[i] = T
    recs = _records(placed, mesh)
    hits = collisions(recs, SHAPES, tolerance=GOAL_OVERLAP)
    if hits:
        a, b, depth = hits[0]
        return None, f"'{a}' and '{b}' overlap by {1000 * depth:.0f} mm in the goal"
    for i, T in placed.items():
        if not _in_region(_footprint(mesh[i], T), WORKSPACE):
            return None, f"'{i}' is out of the robot's reach in the goal"
    bad = unstable_objects(recs, SHAPES, contact_tol=0.002, margin=-0.002)
    if bad:
        i = sorted(bad)[0]
        return None, f"the goal structure cannot stand: '{i}' {bad[i]}"
    return placed, ""


class _World:
    """The current poses, with the support relation of the state cached."""

    def __init__(self, poses, mesh):
        self.poses, self.mesh = dict(poses), mesh
        self._sup = None

    def moved(self, i, T):
        w = _World(self.poses, self.mesh)
        w.poses[i] = T
        return w

    @property
    def sup(self):
        if self._sup is None:
            self._sup = supports(_records(self.poses, self.mesh), SHAPES, contact_tol=0.002)
        return self._sup

    def loaded(self):
        """Parts something rests on."""
        return {j for s in self.sup.values() for j in s}

    def hits(self, i, T, tolerance=TOUCH, clearance=0.0, skip=()):
        """Whether part i at pose T comes closer than `clearance` to another part."""
        for j, U in self.poses.items():
            if j == i or j in skip or np.any(np.abs(U[:3, 3] - T[:3, 3]) > 0.3):
                continue
            gap, _ = separation(
                SHAPES[self.mesh[i]], T, SHAPES[self.mesh[j]], U, cutoff=clearance + 0.001
            )
            if gap < (clearance if clearance > 0 else -tolerance):
                return True
        return False

    def stands(self):
        return not unstable_objects(_records(self.poses, self.mesh), SHAPES, contact_tol=0.002)


def _hangs_over(world, i):
    """Parts lying entirely above part i whose footprint overlaps it (the gripper comes from
    above, so they must go first)."""
    mesh, poses = world.mesh, world.poses
    top = _lowest(mesh[i], poses[i]) + _height(mesh[i], poses[i])
    fi = _footprint(mesh[i], poses[i])
    out = []
    for j in sorted(poses):
        if j == i or _lowest(mesh[j], poses[j]) < top - 0.002:
            continue
        fj = _footprint(mesh[j], poses[j])
        if (fj.min(axis=0) < fi.max(axis=0) - 0.002).all() and (
            fi.min(axis=0) < fj.max(axis=0) - 0.002
        ).all():
            out.append(j)
    return out


def _outline_gap(a, b):
    """Gap [m] between the convex outlines of two 2D point sets (negative: overlap depth)."""
    best = -np.inf
    for pts in (a, b):
        h = pts[ConvexHull(pts).vertices]
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


def _temporary(world, i, pending):
    """A free place on the table for part i (same orientation), nearest to where it is."""
    mesh = world.mesh[i]
    T0 = world.poses[i].copy()
    T0[2, 3] -= _lowest(mesh, T0)
    xs = np.arange(PLACEMENT.x[0], PLACEMENT.x[1] + 1e-9, GRID)
    ys = np.arange(PLACEMENT.y[0], PLACEMENT.y[1] + 1e-9, GRID)
    cand = np.array([(x, y) for x in xs for y in ys])
    order = np.argsort(np.linalg.norm(cand - T0[:2, 3], axis=1), kind="stable")
    for clearance, goal_clearance in CLEARANCES:
        for k in order:
            T = T0.copy()
            T[:2, 3] = cand[k]
            if not _in_region(_footprint(mesh, T), PLACEMENT):
                continue
            if world.hits(i, T, clearance=clearance):
                continue
            if goal_clearance > 0 and any(
                separation(SHAPES[mesh], T, SHAPES[world.mesh[j]], G, cutoff=goal_clearance)[0]
                < goal_clearance
                for j, G in pending
            ):
                continue
            return T
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
        if str(r["mesh"]) != mesh[i] or mesh[i] not in SHAPES:
            return {"status": "infeasible", "reason": f"'{i}' has no known shape ({mesh[i]!r})"}
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
    goal_world = _World(target, mesh)
    goal_sup = {i: set(s) for i, s in goal_world.sup.items()}
    world = _World(start, mesh)
    steps = []
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
        move = None
        for i in ready:
            if i in loaded or _hangs_over(world, i):
                continue
            T = _reachable(mesh[i], world.poses[i], target[i])
            if T is None or world.hits(i, T, tolerance=GOAL_OVERLAP):
                continue
            after = world.moved(i, T)
            if any(i in s for s in after.sup.values()) or not after.stands():
                continue  # it would slide under a part, or leave something tipping
            move = (i, T)
            break
        if move is None:
            move = _clear_the_way(world, ready, target, goal_sup, is_done, mesh)
            if isinstance(move, str):
                return {"status": "infeasible", "reason": move}
        i, T = move
        world = world.moved(i, T)
        steps.append({"object": i, "target_pose": T.tolist()})
    return {"status": "infeasible", "reason": f"no plan within {len(steps)} moves"}


def _clear_the_way(world, ready, target, goal_sup, is_done, mesh):
    """A move of one blocking part to a temporary place, or the reason there is none."""
    candidates = []
    for i in ready:  # what stands on, over or in the way of a part that could be placed
        if i in world.loaded() or _hangs_over(world, i):
            candidates.append(_top_of(world, i))
        T = _reachable(mesh[i], world.poses[i], target[i])
        if T is None:
            continue
        for j in sorted(world.poses, key=lambda j: (-_lowest(mesh[j], world.poses[j]), j)):
            if j == i:
                continue
            gap, _ = separation(SHAPES[mesh[i]], T, SHAPES[mesh[j]], world.poses[j], cutoff=0.002)
            if gap < -TOUCH:
                candidates.append(_top_of(world, j))
    # a stack in the wrong order: the highest part that is not final and can be lifted
    loaded = world.loaded()
    for i in sorted(world.poses, key=lambda i: (-_lowest(mesh[i], world.poses[i]), i)):
        if not is_done(i) and i not in loaded:
            candidates.append(i)
    seen = []
    for b in candidates:
        if b in seen:
            continue
        seen.append(b)
        pending = [(i, target[i]) for i in sorted(target) if not is_done(i) and i != b]
        T = _temporary(world, b, pending)
        if T is None:
            continue
        if world.moved(b, T).stands():
            return (b, T)
    if not seen:
        return "no part can be moved"
    return f"no free place on the table to put '{seen[0]}' down"
