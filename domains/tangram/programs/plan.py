# Written by people (the RIVET team), not by a model: the hand-written reference `plan` for
# the tangram domain, the level a model's program should reach. It uses numpy and
# toolbox.packing.
"""plan(start_state, goal_state, meshes) -> plan: pick-and-place steps that rebuild the goal figure.

Pieces lie flat and turn only about the vertical, so a pose is (x, y, yaw) and a piece is its
outline (from the mesh it receives, per mesh key) plus the 16 mm
square knob at its centroid, which the gripper takes from above, closing along one of the
knob's two axes.

1. Goal check. Every goal piece must lie flat on the table and upright: a parallelogram (or
   any piece) shown upside down cannot be reached by turning about the vertical — the
   parallelogram's handedness is fixed — and a piece above the table or two pieces in one
   place cannot be built: these give "infeasible" with the reason.
2. Identity. Ids are colours (see perceive): each coloured piece has its own goal, so the two
   large and the two small triangles are never exchanged even though either would fit a
   slot; the goal slot of `large_1` is filled by `large_1`.
3. Targets for a tight figure. The figure packs pieces 0.5 mm apart; the perceived goal is
   accurate to about a millimetre and the robot places to a fraction of one, so placing the
   perceived poses as they are would land pieces on their neighbours' edges. The targets are
   spread (`toolbox.spread_footprints`): gaps opened towards 1.5 mm, no piece moved more than
   1.5 mm (the goal tolerance is 5 mm), pieces already at their goal left where they are.
4. Order. Greedy, one transfer per step: among the pieces whose target is free (no piece
   still to move within the perceived states' overlap slack of it: a perceived gap that
   narrow may be contact) and whose knob the fingers can take at the pick and at the place along the
   same knob axis (no other knob in the fingers' way), place first the one that keeps every
   other unplaced piece grippable at its goal afterwards, then the one that costs the pieces
   still to come least. While both of a piece's knob axes are open the gripper can hold it
   four ways instead of two; a piece without symmetry that turns far from pick to place
   needs them (the wrist turns within `toolbox.robot.WRIST_RANGE`, and one grasp must suit
   both ends), so taking away such a piece's axis costs, and a piece about to lose its own axis to a later
   neighbour gains by going first. The goal state's `blocks` edges (from `relate`) say which
   placed piece takes away which knob axis; the same test is made from geometry on the
   spread targets, so a graph without `blocks` edges (or a noisy one) still works: edges
   only add to the ordering constraints. When nothing can be placed, a piece lying on a
   pending goal (a start piece in the figure, or a cycle of pieces swapping places) goes to
   a temporary place first: on the table inside the robot's comfortable reach, an open
   finger's reach clear of every piece (`JAW_CLEARANCES[0] + FINGER_DEPTH`, 25 mm) and the
   open jaws' clearance (8 mm) clear of every unbuilt goal; with less room where there is none.
5. Regrasp. A piece that can be held only one way at its goal (a neighbour's knob takes the
   other axis) and must turn more than 100° is first turned halfway where it lies (or at the
   nearest free place), in the open where both ways work; then the long turn is two short
   ones.
"""

import numpy as np

from toolbox.packing import finger_footprints, polygon_gap, spread_footprints
from toolbox.robot import (
    FINGER_DEPTH,
    FINGER_WIDTH,
    GRASP_MARGINS,
    JAW_CLEARANCES,
    PLACEMENT,
    PLACEMENT_SPREAD,
    SWEEP_TOUCH,
    WORKSPACE,
    WRIST_RANGE,
    YAW_ONLY,
)
from toolbox.stability import PERCEIVED_GAP, PERCEIVED_OVERLAP, TOUCHING

SYMMETRY = {  # rotational symmetry order about the vertical (the task text)
    "large_triangle": 1,
    "medium_triangle": 1,
    "small_triangle": 1,
    "square": 4,
    "parallelogram": 2,
}
# the knob (the task text: a square knob at the centroid), its half side read from the top of
# the meshes `plan` receives (`_learn_knob`), and what follows from it: the jaws around a knob
# with neighbours close by (the smaller approach clearance per side), and the farthest another
# knob's centre can be from this knob's and still touch the open fingers around it (a
# fingertip's far corner, `toolbox.finger_footprints`, and the knob's half diagonal) [m]
KNOB_HALF = OPENING = KNOB_REACH = None
FINGER_MARGIN = GRASP_MARGINS[-1]  # the least clearance the hand keeps around its fingers [m]


def _learn_knob(meshes):
    global KNOB_HALF, OPENING, KNOB_REACH
    tops = []
    for key, mesh in meshes.items():
        if key in SYMMETRY:
            v = np.asarray(mesh.vertices, dtype=float)
            tops.append(np.abs(v[v[:, 2] > v[:, 2].max() - 1e-5, :2]).max())
    if not tops:
        return  # no piece this plan knows: it answers "infeasible" naming the mesh
    KNOB_HALF = float(max(tops))
    OPENING = 2 * KNOB_HALF + 2 * JAW_CLEARANCES[-1]
    KNOB_REACH = float(
        np.hypot(OPENING / 2 + FINGER_DEPTH + FINGER_MARGIN, FINGER_WIDTH / 2 + FINGER_MARGIN)
        + np.sqrt(2) * KNOB_HALF
    )


# a piece lies flat when it is tilted no more than a turn about the vertical allows
# (toolbox.robot.YAW_ONLY): |z axis · world z| at least this
UPRIGHT = np.cos(YAW_ONLY)
# a goal piece lies on the table when it is perceived no higher above it than the perceived
# states' slack under an object, and no deeper into it than their slack between objects [m]
ABOVE_TABLE, INTO_TABLE = PERCEIVED_GAP, PERCEIVED_OVERLAP
# goal pieces overlapping deeper than the perceived states' slack (and a touch) cannot both be
# built [m]
CROWDED = PERCEIVED_OVERLAP + TOUCHING
# gaps opened between goal pieces, moving no piece more than this (the executor can hit it) [m]
SPREAD_GAP, SPREAD_SHIFT = PLACEMENT_SPREAD
# a piece whose centre lies within the spread's shift of its goal, and whose outline its turn
# moves no farther, stays where it is
DONE_POS = SPREAD_SHIFT  # [m]
# a target this close to a piece not yet at its goal is occupied: perceived objects that touch
# may overlap by PERCEIVED_OVERLAP, so a perceived gap narrower than that may be contact [m]
FREE_GAP = PERCEIVED_OVERLAP
# … and a target may reach into a piece already at its goal (spreading could not open every
# gap) as deep as the hand model lets a held piece's sweep touch others [m]
PLACED_GAP = -SWEEP_TOUCH
# a turn the wrist makes with either of two grasps half a turn apart: one of them leaves it
# within a quarter turn of the middle of WRIST_RANGE, from where it turns WRIST_RANGE[1] - 90°
# (83°) either way; less, for where the arm's own pose puts the wrist
# (70°, this plan's own margin, chosen on the dev split)
EASY_TURN = min(np.radians(70.0), WRIST_RANGE[1] - np.pi / 2)
# longer turns held one way only are split in two (this plan's own choice, made on the dev
# split: a little more than WRIST_RANGE[1] - 90°, which a turn from the middle always makes)
REGRASP_TURN = np.radians(100.0)
# temporary places (to pieces, to unbuilt goals) [m], roomiest first: an open finger's reach
# beyond the jaws (JAW_CLEARANCES[0] + FINGER_DEPTH) from pieces and the open jaws' clearance from
# goals; then half-way, with the jaws' narrower clearance; then the open jaws' clearance and the
# figure's own gaps
FINGER_ROOM = JAW_CLEARANCES[0] + FINGER_DEPTH
TEMPORARY = (
    (FINGER_ROOM, JAW_CLEARANCES[0]),
    ((FINGER_ROOM + JAW_CLEARANCES[0]) / 2, JAW_CLEARANCES[1]),
    (JAW_CLEARANCES[0], SPREAD_GAP),
)
# candidate temporary places lie on a square grid this fine: no free spot as wide as the open
# jaws' clearance is stepped over [m]
GRID = JAW_CLEARANCES[0]
OUTLINES = {}  # mesh key → bottom outline (k, 2) in the piece's frame [m], counter-clockwise


def _outline(mesh):
    """The bottom outline of a piece's mesh: the convex hull of its vertices at z = 0."""
    v = np.asarray(mesh.vertices, dtype=float)
    pts = np.unique(np.round(v[v[:, 2] < v[:, 2].min() + 1e-5, :2], 9), axis=0)
    pts = sorted(map(tuple, pts))

    def half(points):
        out = []
        for p in points:
            while (
                len(out) >= 2
                and np.cross(np.subtract(out[-1], out[-2]), np.subtract(p, out[-2])) <= 1e-12
            ):
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


class _Piece:
    """A piece at (x, y, yaw): its outline, knob and radius, world frame."""

    def __init__(self, key, x, y, yaw):
        self.key, self.x, self.y, self.yaw = key, float(x), float(y), float(yaw)
        c, s = np.cos(yaw), np.sin(yaw)
        self.R = np.array([[c, -s], [s, c]])
        self.centre = np.array([self.x, self.y])
        self.outline = OUTLINES[key] @ self.R.T + self.centre
        knob = KNOB_HALF * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
        self.knob = knob @ self.R.T + self.centre
        self.radius = float(np.linalg.norm(OUTLINES[key], axis=1).max())

    def moved(self, x, y, yaw=None):
        return _Piece(self.key, x, y, self.yaw if yaw is None else yaw)

    def pose(self):
        T = np.eye(4)
        T[:2, :2] = self.R
        T[:2, 3] = self.centre
        return T.tolist()


def _gap(a, b, cutoff=2 * FINGER_ROOM):
    """Signed gap [m] between two pieces' outlines (a lower bound beyond `cutoff`, which lies
    above every gap this plan compares with)."""
    far = float(np.linalg.norm(a.centre - b.centre)) - a.radius - b.radius
    if far > cutoff:
        return far
    return polygon_gap(a.outline, b.outline)[0]


def _free_axes(p, others):
    """Knob axes (0: x, 1: y, piece frame) along which the fingers can close on p's knob."""
    free = set()
    for axis in (0, 1):
        fingers = finger_footprints(p.centre, p.R[:, axis], OPENING, margin=FINGER_MARGIN)
        if all(
            np.linalg.norm(q.centre - p.centre) > KNOB_REACH
            or all(polygon_gap(f, q.knob)[0] >= 0 for f in fingers)
            for q in others
        ):
            free.add(axis)
    return free


def _grasp_axes(key, at_pick, at_place, others):
    """How many ways (knob axes, 0–2) one grasp can hold the piece at both ends."""
    pick = _free_axes(at_pick, others)
    place = _free_axes(at_place, others)
    if SYMMETRY[key] == 4:  # a quarter turn maps one knob axis onto the other
        return min(len(pick), len(place))
    return len(pick & place)


def _flat(T):
    """(x, y, z, yaw) of a pose, or a reason why it is not a piece lying upright."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        return None, "its pose is not a finite 4x4 matrix"
    zz = T[2, 2]
    if zz < -UPRIGHT:
        return None, "it lies upside down (pieces cannot be turned over)"
    if zz < UPRIGHT:
        return None, f"it is tilted {np.degrees(np.arccos(np.clip(zz, -1, 1))):.0f}° from flat"
    return (T[0, 3], T[1, 3], T[2, 3], float(np.arctan2(T[1, 0], T[0, 0]))), ""


def _nearest_yaw(goal_yaw, current_yaw, n):
    """The symmetric equivalent of goal_yaw closest to current_yaw."""
    period = 2 * np.pi / n
    d = (goal_yaw - current_yaw + period / 2) % period - period / 2
    return current_yaw + d


def _yaw_close(a, b, n, radius):
    """Yaws a and b (modulo 1/n of a turn) move no point `radius` from the centre farther
    apart than DONE_POS."""
    period = 2 * np.pi / n
    return abs((a - b + period / 2) % period - period / 2) * radius <= DONE_POS


def _inside(points, region):
    return bool(
        np.all(points[:, 0] >= region.x[0])
        and np.all(points[:, 0] <= region.x[1])
        and np.all(points[:, 1] >= region.y[0])
        and np.all(points[:, 1] <= region.y[1])
        and np.all(np.linalg.norm(points, axis=1) <= region.reach)
    )


def _blockers_from(graph, ids):
    """{target: {axis: {source, …}}} from the `blocks` edges of a relation graph."""
    out = {i: {0: set(), 1: set()} for i in ids}
    edges = graph.get("edges", []) if isinstance(graph, dict) else []
    for e in edges:
        if e.get("type") != "blocks":
            continue
        s, t, axis = str(e.get("source")), str(e.get("target")), e.get("axis")
        if t in out and s in out and axis in ("x", "y"):
            out[t][0 if axis == "x" else 1].add(s)
    return out


def _temporary(i, current, pending_goals, yaw=None):
    """A free place for piece i on the table (turned to `yaw`), as near as possible to where
    it is."""
    p = current[i] if yaw is None else current[i].moved(current[i].x, current[i].y, yaw)
    others = [q for j, q in current.items() if j != i]
    xs = np.arange(PLACEMENT.x[0], PLACEMENT.x[1] + 1e-9, GRID)
    ys = np.arange(PLACEMENT.y[0], PLACEMENT.y[1] + 1e-9, GRID)
    cand = np.array([(x, y) for x in xs for y in ys])
    order = np.argsort(np.linalg.norm(cand - p.centre, axis=1), kind="stable")
    for clear, goal_clear in TEMPORARY:
        for k in order:
            q = p.moved(*cand[k])
            if not _inside(q.outline, PLACEMENT):
                continue
            if any(_gap(q, o) < clear for o in others):
                continue
            if any(_gap(q, g) < goal_clear for g in pending_goals):
                continue
            return q
    return None


def _turned(i, current, yaw, pending_goals):
    """Piece i turned to `yaw` where it lies if there is room (and both knob axes free),
    else at the nearest free place."""
    p = current[i].moved(current[i].x, current[i].y, yaw)
    others = [q for j, q in current.items() if j != i]
    if (
        _inside(p.outline, PLACEMENT)
        and all(_gap(p, o) >= TEMPORARY[0][0] for o in others)
        and all(_gap(p, g) >= TEMPORARY[0][1] for g in pending_goals)
        and len(_free_axes(p, others)) == 2
    ):
        return p
    return _temporary(i, current, pending_goals, yaw=yaw)


def _targets(goal, current, done):
    """Goal pieces spread apart a little (see the module docstring); done pieces stay."""
    ids = sorted(goal)
    shapes = [current[i].outline if i in done else goal[i].outline for i in ids]
    fixed = [k for k, i in enumerate(ids) if i in done]
    shift = spread_footprints(shapes, gap=SPREAD_GAP, max_shift=SPREAD_SHIFT, fixed=fixed)
    out = {}
    for k, i in enumerate(ids):
        g = current[i] if i in done else goal[i]
        out[i] = g.moved(g.x + shift[k, 0], g.y + shift[k, 1])
    return out


def plan(start_state, goal_state, meshes):
    for key, mesh in meshes.items():
        if key in SYMMETRY and key not in OUTLINES:
            OUTLINES[key] = _outline(mesh)
    _learn_knob(meshes)
    start_recs = {str(r["id"]): r for r in start_state["objects"]}
    goal_recs = {str(r["id"]): r for r in goal_state["objects"]}
    if sorted(start_recs) != sorted(goal_recs):
        return {
            "status": "infeasible",
            "reason": f"start has {sorted(start_recs)} but goal has {sorted(goal_recs)}",
        }
    current, goal = {}, {}
    for name, recs, out in (("start", start_recs, current), ("goal", goal_recs, goal)):
        for i, r in sorted(recs.items()):
            key = r["mesh"]
            if key not in OUTLINES:
                return {"status": "infeasible", "reason": f"'{i}' has unknown mesh '{key}'"}
            flat, why = _flat(r["pose"])
            if flat is None:
                return {"status": "infeasible", "reason": f"'{i}' in the {name}: {why}"}
            x, y, z, yaw = flat
            if name == "goal" and not -INTO_TABLE <= z <= ABOVE_TABLE:
                where = "above" if z > 0 else "below"
                return {
                    "status": "infeasible",
                    "reason": f"'{i}' is {1000 * abs(z):.0f} mm {where} the table in the goal",
                }
            out[i] = _Piece(key, x, y, yaw)
    ids = sorted(goal)
    for k, i in enumerate(ids):
        if start_recs[i]["mesh"] != goal_recs[i]["mesh"]:
            return {"status": "infeasible", "reason": f"'{i}' has different meshes"}
        if not _inside(goal[i].outline, WORKSPACE):
            return {"status": "infeasible", "reason": f"'{i}' is out of reach in the goal"}
        for j in ids[k + 1 :]:
            if _gap(goal[i], goal[j]) < -CROWDED:
                return {
                    "status": "infeasible",
                    "reason": f"'{i}' and '{j}' overlap in the goal (one place, two pieces)",
                }
    done = {
        i
        for i in ids
        if np.linalg.norm(current[i].centre - goal[i].centre) <= DONE_POS
        and _yaw_close(current[i].yaw, goal[i].yaw, SYMMETRY[goal[i].key], goal[i].radius)
    }
    target = _targets(goal, current, done)
    # which goal piece's knob takes away which knob axis of which other, at the targets
    blockers = _blockers_from(goal_state.get("relations"), ids)
    for i in ids:
        for axis in (0, 1):
            fingers = finger_footprints(
                target[i].centre, target[i].R[:, axis], OPENING, margin=FINGER_MARGIN
            )
            for j in ids:
                if j != i and any(polygon_gap(f, target[j].knob)[0] < 0 for f in fingers):
                    blockers[i][axis].add(j)
    placed = set(done)
    pending = [i for i in ids if i not in done]
    steps = []
    turned = set()
    for _ in range(3 * len(ids)):
        if not pending:
            return {"status": "ok", "steps": steps}
        ready = []
        for i in pending:
            n = SYMMETRY[goal[i].key]
            t = target[i].moved(
                target[i].x, target[i].y, _nearest_yaw(target[i].yaw, current[i].yaw, n)
            )
            others = {j: q for j, q in current.items() if j != i}
            if any(
                _gap(t, q) < (PLACED_GAP if j in placed else FREE_GAP) for j, q in others.items()
            ):
                continue
            ways = _grasp_axes(goal[i].key, current[i], t, list(others.values()))
            if ways:
                ready.append((i, t, ways))
        if ready:
            need = {j: _need(goal[j].key, target[j].yaw, current[j].yaw) for j in pending}
            i, t, ways = min(
                ready, key=lambda it: _priority(it[0], blockers, placed, pending, need)
            )
            turn = t.yaw - current[i].yaw
            if ways < 2 and abs(turn) > REGRASP_TURN and i not in turned:
                # held one way only, with a long turn: turn it halfway first, in the open
                goals_left = [target[j] for j in pending if j != i]
                spot = _turned(i, current, current[i].yaw + turn / 2, goals_left)
                if spot is not None:
                    turned.add(i)
                    current[i] = spot
                    steps.append({"object": i, "target_pose": spot.pose()})
                    continue
            current[i] = t
            placed.add(i)
            pending.remove(i)
            steps.append({"object": i, "target_pose": t.pose()})
            continue
        blocker = _in_the_way(pending, target, current, placed)
        if blocker is None:
            return {"status": "infeasible", "reason": "no piece can be placed or moved aside"}
        goals_left = [target[j] for j in pending if j != blocker]
        spot = _temporary(blocker, current, goals_left)
        if spot is None:
            return {"status": "infeasible", "reason": f"no free place to put '{blocker}' aside"}
        current[blocker] = spot
        steps.append({"object": blocker, "target_pose": spot.pose()})
    return {"status": "infeasible", "reason": f"no plan within {len(steps)} moves"}


def _need(key, goal_yaw, current_yaw):
    """How much a piece needs both knob axes free at its goal, in [0, 1]: with one axis the
    gripper holds it two ways (half a turn apart), and the wrist's range may not cover both
    the pick and the turn to the place; a turn of up to `EASY_TURN` (modulo the piece's
    symmetry) is always fine."""
    n = SYMMETRY[key]
    turn = abs(_nearest_yaw(goal_yaw, current_yaw, n) - current_yaw)
    return float(np.clip((turn - EASY_TURN) / (np.pi - EASY_TURN), 0.0, 1.0))


def _priority(i, blockers, placed, pending, need):
    """Sort key of a placeable piece: does placing it strand another piece (no knob axis
    left); what it costs the pieces still to come (knob axes it takes away, weighted by their
    `need`) minus what it saves itself by going now (its own axes a later piece would take);
    its id."""
    after = placed | {i}
    stranded = sum(
        1 for j in pending if j != i and all(blockers[j][axis] & after for axis in (0, 1))
    )
    harm = sum(
        need[j]
        for j in pending
        if j != i
        and any(i in blockers[j][axis] and not blockers[j][axis] & placed for axis in (0, 1))
    )
    later = set(pending) - {i}
    losing = sum(
        1 for axis in (0, 1) if not blockers[i][axis] & placed and blockers[i][axis] & later
    )
    return (stranded, round(harm - losing * need[i], 9), i)


def _in_the_way(pending, target, current, placed):
    """A piece not at its goal that lies on a pending goal or crowds its knob, else None."""
    for i in pending:  # something on a goal that is still to be built
        for j in pending:
            if j != i and _gap(target[i], current[j]) < FREE_GAP:
                return j
    for i in pending:  # a knob in the way of the fingers at a goal or at a pick
        others = [q for j, q in current.items() if j != i]
        ends = (target[i], current[i])
        if not all(_free_axes(p, others) for p in ends):
            for j in pending:  # one whose knob the open fingers there can touch
                near = min(np.linalg.norm(current[j].centre - p.centre) for p in ends)
                if j != i and near <= KNOB_REACH:
                    return j
    return None
