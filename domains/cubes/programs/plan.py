# Written by people (the RIVET team), not by a model: the hand-written reference `plan` for
# the cubes domain, the level a model's program should reach. It uses only numpy.
"""plan(start_state, goal_state, meshes) -> plan: pick-and-place steps that rebuild the goal.

Greedy construction: every round, place a cube whose goal supporters are already final, whose
goal column is free and which nothing rests on, lowest goal first; when none can be placed,
move one blocking cube to a free temporary place on the table (a cube squatting on a goal spot,
the top of a stack in the wrong order, …). Support is read from geometry (upright cubes, their
edge read from the meshes): the relation graphs are not needed, so perception noise in them cannot mislead it.
Goal poses are snapped to resting heights and to upright yaw rotations; orientation about the
vertical is kept from the goal (cube rows and pyramids need it to fit). A goal that no plan can
reach (floating or interpenetrating cubes, unknown ids) gives an explicit "infeasible".

The robot is a parallel-jaw gripper (Robotiq 2F-85) coming down from above, so a move is only
made when the robot's own hand model (`toolbox.robot.Hand`, the model its executor and the plan
checks use) finds a grasp with room among the other cubes at the pick and at the place, and
when it does not take away the last grasp of a cube that still has to move: neither where that
cube stands now nor at its goal place (a cube with goal neighbours on two perpendicular sides
goes before the second of them, or the jaws find no way down). The goal places are therefore
filled in an order, found by a depth-first search, in which each has room for the fingers
among those filled before it; a cube goes into its place only while the places still to fill
keep such an order. A cube in the fingers' way goes to a temporary place first. When
no order satisfies that, the plan falls back to the geometric order alone. Goals must lie
inside the robot's workspace (`toolbox.robot.WORKSPACE`); temporary places are in the placement
region (`toolbox.robot.PLACEMENT`), where the arm is comfortable.
"""

import numpy as np

from toolbox import cube_symmetries
from toolbox.robot import (
    FINGER_DEPTH,
    GRASP_MARGINS,
    JAW_CLEARANCES,
    MAX_OPENING,
    PLACEMENT,
    WORKSPACE,
    Hand,
    Workspace,
)
from toolbox.stability import PERCEIVED_GAP, PERCEIVED_OVERLAP

# the cubes' edge, read from the meshes `plan` receives (`_learn_side`; 40 mm, the task text
# says), and what follows from it: half of it, a yaw within SAME_YAW moving no corner farther
# than SAME, and NEAR (below) [m]
SIDE = HALF = SAME_YAW = NEAR = None
# a cube perceived at most the perceived states' slack above (or into) a cube's top rests on it
# [m]; one perceived within that slack of its goal position counts as placed
ON_GAP = SAME = PERCEIVED_GAP
# goals may lie anywhere in the workspace, with the perceived states' slack [m]
SLACK = SAME
GOALS = Workspace(
    x=(WORKSPACE.x[0] - SLACK, WORKSPACE.x[1] + SLACK),
    y=(WORKSPACE.y[0] - SLACK, WORKSPACE.y[1] + SLACK),
    reach=WORKSPACE.reach + SLACK,
)
REGION = PLACEMENT  # where cubes are put aside
# how far an open finger reaches beyond the side of the cube it grips: the jaws' clearance, a
# fingertip's depth and the least margin the hand keeps (toolbox.robot) [m]
FINGER_REACH = JAW_CLEARANCES[0] + FINGER_DEPTH + GRASP_MARGINS[-1]
# candidate temporary places lie on a square grid this fine: no free spot as wide as the open
# jaws' clearance is stepped over [m]
GRID = JAW_CLEARANCES[0]
# (to cubes, to goals still to build) [m], roomiest first: room for both fingers and the open
# jaws' clearance to goals; then half-way, with the jaws' narrower clearance to goals; then the
# open jaws only
CLEARANCES = (
    (FINGER_REACH, JAW_CLEARANCES[0]),
    ((FINGER_REACH + JAW_CLEARANCES[0]) / 2, JAW_CLEARANCES[1]),
    (JAW_CLEARANCES[0], 0.0),
)
# footprints or heights that overlap by more than this do overlap: perceived cubes that touch
# may lie this far into one another (toolbox.stability) [m]
OVERLAP = PERCEIVED_OVERLAP
SLIVER = 0.0002  # footprints overlapping deeper than this share a column (not rounding) [m]


def _learn_side(meshes, keys):
    """SIDE and what follows from it, from the widest extent of the cubes' meshes."""
    global SIDE, HALF, SAME_YAW, NEAR
    extents = [np.ptp(np.asarray(meshes[k].vertices, dtype=float), axis=0) for k in keys]
    SIDE = float(max(e.max() for e in extents))
    HALF = SIDE / 2
    SAME_YAW = SAME / (HALF * np.sqrt(2))  # modulo 90°
    # cubes whose centres are farther apart than the open hand (the widest opening and a
    # fingertip on each side) and a cube's diagonal never meet the gripper at the other
    NEAR = MAX_OPENING + 2 * FINGER_DEPTH + SIDE * np.sqrt(2)


def _yaw(R):
    """Yaw [rad] in [-π/4, π/4) of an upright cube's rotation (any of its 24 symmetries)."""
    R = np.asarray(R, dtype=float)
    horizontal = int(np.argmin(np.abs(R[2, :])))  # a body axis lying flat
    yaw = np.arctan2(R[1, horizontal], R[0, horizontal])
    return float((yaw + np.pi / 4) % (np.pi / 2) - np.pi / 4)


def _tilt(R):
    """Angle [rad] between the cube's most vertical body axis and the world z axis."""
    return float(np.arccos(np.clip(np.max(np.abs(np.asarray(R, float)[2, :])), -1.0, 1.0)))


def _pose(x, y, z, yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = (x, y, z)
    return T


def _corners(p):
    """Footprint corners (4, 2) of an upright cube at p = (x, y, z, yaw)."""
    c, s = np.cos(p[3]), np.sin(p[3])
    local = HALF * np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]], dtype=float)
    return local @ np.array([[c, s], [-s, c]]) + p[:2]


def _footprint_gap(a, b):
    """Separation [m] of two footprints (negative: overlap depth), separating-axis test."""
    best = -np.inf
    for p in (a, b):
        for yaw in (p[3], p[3] + np.pi / 2):
            axis = np.array([np.cos(yaw), np.sin(yaw)])
            pa, pb = _corners(a) @ axis, _corners(b) @ axis
            best = max(best, pa.min() - pb.max(), pb.min() - pa.max())
    return best


def _rests_on(a, b):
    """Cube a rests on cube b."""
    return abs(a[2] - b[2] - SIDE) <= ON_GAP and _footprint_gap(a, b) < -OVERLAP


def _supporters(poses):
    return {i: sorted(j for j in poses if j != i and _rests_on(poses[i], poses[j])) for i in poses}


def _as_xyzy(T):
    T = np.asarray(T, dtype=float)
    return np.array([T[0, 3], T[1, 3], T[2, 3], _yaw(T[:3, :3])])


def _yaw_close(a, b):
    d = (a - b + np.pi / 4) % (np.pi / 2) - np.pi / 4
    return abs(d) <= SAME_YAW


def _in_region(points):
    return REGION.contains(np.atleast_2d(points))


def _reachable(points):
    """Inside the robot's workspace (where goals may be)."""
    return GOALS.contains(np.atleast_2d(points))


def _snap_goal(goal):
    """Goal poses at exact resting heights, or a reason why no plan can reach them."""
    sup = _supporters(goal)
    snapped = {}
    for i in sorted(goal, key=lambda k: (goal[k][2], k)):
        p = goal[i].copy()
        if sup[i]:
            p[2] = max(snapped[j][2] for j in sup[i]) + SIDE
        elif p[2] - HALF > ON_GAP:
            return None, f"'{i}' floats {1000 * (p[2] - HALF):.0f} mm above the table in the goal"
        else:
            p[2] = HALF
        snapped[i] = p
    ids = sorted(goal)
    for k, i in enumerate(ids):
        for j in ids[k + 1 :]:
            a, b = snapped[i], snapped[j]
            if abs(a[2] - b[2]) < SIDE - OVERLAP and _footprint_gap(a, b) < -OVERLAP:
                return None, f"'{i}' and '{j}' overlap in the goal"
    return snapped, ""


def _in_column(p, q, settled):
    """Whether a cube at q stands in the column at and above goal pose p. The cube comes down
    vertically, so even a sliver overhanging p is in its way; and a cube still to move (not
    `settled` in its goal) was perceived apart from p's goal, so one nearer to p than perceived
    states' slack may in truth stand in it."""
    if q[2] <= p[2] - SIDE + OVERLAP:
        return False
    return _footprint_gap(p, q) < (-SLIVER if settled else PERCEIVED_OVERLAP)


def _column_free(i, p, current, settled):
    """Nothing but i occupies the column at and above goal pose p (`settled(j)`: cube j is
    final in its goal)."""
    return not any(j != i and _in_column(p, q, settled(j)) for j, q in current.items())


def _top_of(j, current):
    """The cube at the top of the stack standing on j (j itself when it is clear)."""
    sup = _supporters(current)
    while True:
        above = sorted(k for k in current if j in sup[k])
        if not above:
            return j
        j = above[0]


class _Hand:
    """The robot's hand model on states {id: (x, y, z, yaw)}."""

    def __init__(self, meshes, mesh_of):
        self.hand = Hand(meshes, {k: cube_symmetries() for k in meshes})
        self.mesh_of = mesh_of

    def records(self, cubes):
        return [{"id": j, "mesh": self.mesh_of[j], "pose": _pose(*q)} for j, q in cubes.items()]

    def room(self, i, p, cubes):
        """Whether some grasp of cube i at p has room among `cubes`."""
        return self.hand.can_pick(self.records({**cubes, i: p}), i).ok

    def blockers(self, i, p, current):
        """[] when cube i can be carried from where it is to p (the others staying as in
        `current`) with room for the gripper at both ends; else the cubes in the way, most
        blocking first."""
        after = {**current, i: p}
        verdict = self.hand.can_move(
            self.records(current), i, _pose(*p), place_records=self.records(after)
        )
        return [] if verdict.ok else [j for j in verdict.blockers if j in current] or [i]


def _takes_grasp(hand, i, p, current, pickable):
    """Cubes of `pickable` (each can be picked in `current`) that cannot once cube i is at p."""
    after = {**current, i: p}
    return [
        j
        for j in pickable
        if j != i
        and np.hypot(*(current[j][:2] - p[:2])) < NEAR
        and not hand.room(j, current[j], after)
    ]


def _takes_place(hand, i, goal, placed, pending):
    """Cubes of `pending` whose goal place keeps room for the fingers among the cubes already
    `placed` in their goals, but not once cube i is in its goal too: placing i first would wall
    that place in (two neighbours on perpendicular sides leave the jaws no way down), so the
    pending cube goes first."""
    built = {j: goal[j] for j in placed if j != i}
    return [
        j
        for j in pending
        if j != i
        and np.hypot(*(goal[j][:2] - goal[i][:2])) < NEAR
        and hand.room(j, goal[j], built)
        and not hand.room(j, goal[j], {**built, i: goal[i]})
    ]


def _goal_order(hand, goal, goal_sup):
    """A function: the set of cubes already in their goal places → an order of all goal places,
    those first, in which each cube, put down after its supporters, has room for the fingers
    among the cubes placed before it (depth-first, lowest goal first; dead ends memoised
    on the placed set), or None when there is none. Cubes that wall each other's places in (each beside one
    and at right angles to another) need it: the greedy step sees one placement ahead only."""
    ids = sorted(goal, key=lambda i: (goal[i][2], i))
    dead = set()

    def extend(order):
        if len(order) == len(ids):
            return order
        placed = frozenset(order)
        if placed in dead:
            return None
        built = {j: goal[j] for j in order}
        for i in ids:
            if i in placed or not set(goal_sup[i]) <= placed:
                continue
            if hand.room(i, goal[i], built):
                found = extend([*order, i])
                if found is not None:
                    return found
        dead.add(placed)
        return None

    return lambda placed: extend(sorted(placed, key=ids.index))


def _temporary(i, current, pending, hand=None, pickable=()):
    """A free place on the table for cube i, as near as possible to where it is; with a
    `hand`, one the gripper can put it down at, taking no grasp from the cubes of `pickable`."""
    here = current[i]
    grip = hand is not None
    if grip and not hand.room(i, here, current):
        return None  # it cannot be picked where it stands
    others = [q for j, q in current.items() if j != i]
    xs = np.arange(REGION.x[0], REGION.x[1] + 1e-9, GRID)
    ys = np.arange(REGION.y[0], REGION.y[1] + 1e-9, GRID)
    cand = np.array([(x, y) for x in xs for y in ys])
    order = np.argsort(np.linalg.norm(cand - here[:2], axis=1), kind="stable")
    levels = CLEARANCES
    if grip:  # keep goals still to build free for the fingers on every side first
        levels = ((FINGER_REACH, FINGER_REACH), *levels)
    for clearance, goal_clearance in levels:
        for k in order:
            p = np.array([cand[k][0], cand[k][1], HALF, here[3]])
            if np.hypot(*(p[:2] - here[:2])) < HALF:
                continue  # a place, not where it stands
            if not _in_region(_corners(p)):
                continue
            if any(_footprint_gap(p, q) < clearance for q in others):
                continue
            if any(_footprint_gap(p, g) < goal_clearance for g in pending):
                continue
            if grip and (
                hand.blockers(i, p, current) or _takes_grasp(hand, i, p, current, pickable)
            ):
                continue
            return p
    return None


def plan(start_state, goal_state, meshes):
    keys = {r["mesh"] for r in (*start_state["objects"], *goal_state["objects"])}
    unknown = sorted(k for k in keys if k not in meshes)
    if unknown:
        return {"status": "infeasible", "reason": f"no mesh for {unknown}"}
    if keys:
        _learn_side(meshes, keys)
    start = {str(r["id"]): _as_xyzy(r["pose"]) for r in start_state["objects"]}
    goal_raw = {str(r["id"]): r["pose"] for r in goal_state["objects"]}
    if sorted(start) != sorted(goal_raw):
        return {
            "status": "infeasible",
            "reason": f"start has {sorted(start)} but goal has {sorted(goal_raw)}",
        }
    for i, T in goal_raw.items():
        if _tilt(np.asarray(T, float)[:3, :3]) > np.radians(20):
            return {"status": "infeasible", "reason": f"'{i}' is tilted in the goal"}
    goal, why = _snap_goal({i: _as_xyzy(T) for i, T in goal_raw.items()})
    if goal is None:
        return {"status": "infeasible", "reason": why}
    for i, p in goal.items():
        if not _reachable(_corners(p)):
            return {"status": "infeasible", "reason": f"'{i}' is out of reach in the goal"}
    mesh_of = {str(r["id"]): r["mesh"] for r in start_state["objects"]}
    result = _build(start, goal, _Hand(meshes, mesh_of))
    if result["status"] != "ok":  # no order leaves the gripper room: the geometric order
        result = _build(start, goal, None)
    return result


def _build(start, goal, hand):
    """Greedy construction (see the module docstring); with a `hand`, every move must leave
    the gripper room at both ends and no cube still to move without a grasp."""
    grip = hand is not None
    goal_sup = _supporters(goal)
    finish = _goal_order(hand, goal, goal_sup) if grip else None
    order = finish(frozenset()) if grip else None
    rank = {i: k for k, i in enumerate(order)} if order else {}
    current = dict(start)
    steps = []
    for _ in range(4 * len(goal) + 4):
        sup = _supporters(current)
        done = {}

        def is_done(i, sup=sup, done=done):
            if i not in done:
                done[i] = False  # guards against support cycles
                p, g = current[i], goal[i]
                done[i] = (
                    np.linalg.norm(p[:3] - g[:3]) <= SAME
                    and _yaw_close(p[3], g[3])
                    and sup[i] == goal_sup[i]
                    and all(is_done(j) for j in goal_sup[i])
                )
            return done[i]

        if all(is_done(i) for i in goal):
            return {"status": "ok", "steps": steps}
        loaded = {j for i in current for j in sup[i]}
        ready = sorted(
            (i for i in goal if not is_done(i) and all(is_done(j) for j in goal_sup[i])),
            key=lambda i: (rank.get(i, 0), goal[i][2], i),
        )
        movers = [j for j in goal if not is_done(j)] if grip else []
        pickable = [j for j in movers if hand.room(j, current[j], current)]
        placed = [j for j in goal if is_done(j)]
        move, in_the_way = None, []
        for i in ready:
            if i not in loaded and _column_free(i, goal[i], current, is_done):
                if grip:
                    blockers = hand.blockers(i, goal[i], current)
                    blockers = blockers or _takes_grasp(hand, i, goal[i], current, pickable)
                    if blockers:  # no room for the gripper, or it would take a grasp away
                        in_the_way += [j for j in blockers if j not in in_the_way]
                        continue
                    if _takes_place(hand, i, goal, placed, movers):
                        continue  # a cube still to come goes first
                    if (
                        order
                        and finish(frozenset(placed)) is not None
                        and finish(frozenset(placed) | {i}) is None
                    ):
                        continue  # the places still to fill would have no order with room
                move = (i, goal[i])
                break
        if move is None:
            blocker = None
            if in_the_way:  # a cube in the fingers' way (one not done first), or what is on it
                blocker = _top_of(min(in_the_way, key=lambda j: (is_done(j), j)), current)
            for i in ready if blocker is None else ():  # what stands in the way of a cube
                if i in loaded:
                    blocker = _top_of(i, current)
                    break
                for j in sorted(current, key=lambda j: (-current[j][2], j)):
                    if j != i and _in_column(goal[i], current[j], is_done(j)):
                        blocker = _top_of(j, current)
                        break
                if blocker is not None:
                    break
            if blocker is None:  # a stack in the wrong order: take its top off
                for i in sorted(current, key=lambda i: (-current[i][2], i)):
                    if not is_done(i) and i not in loaded:
                        blocker = i
                        break
            if blocker is None:
                return {"status": "infeasible", "reason": "no cube can be moved"}
            pending = [goal[i] for i in goal if not is_done(i) and i != blocker]
            place = _temporary(blocker, current, pending, hand, pickable)
            if place is None and grip:
                return {"status": "infeasible", "reason": f"no room to put '{blocker}' down"}
            if place is None:
                return {"status": "infeasible", "reason": f"no free place to put '{blocker}' down"}
            move = (blocker, place)
        i, p = move
        current[i] = p
        steps.append({"object": i, "target_pose": _pose(*p).tolist()})
    return {"status": "infeasible", "reason": f"no plan within {len(steps)} moves"}
