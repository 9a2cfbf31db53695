"""The reference construction order: top-down pick-and-place from a start to a goal.

Rules the order obeys (they are what the executor's oracle needs):
- an object is moved only when nothing rests on it;
- it goes to its goal pose only when everything it rests on in the goal is already final;
- a placement never leaves anything resting on the placed object (no inserting underneath);
- a target never interpenetrates the objects already there, and keeps 3 mm from those not
  in their final place (a goal packs final objects as tightly as it wants, but a placement
  that grazes an object lying anywhere would shove or tilt it); temporary places keep a
  gripper-sized clearance from everything present and from every goal still to be built;
- every move changes the object's orientation only by a rotation about the vertical: the
  target is the symmetry-equivalent of the goal pose that a yaw rotation reaches.
Greedy: place whatever can be placed, lowest first; otherwise move one blocking object
aside. It is not optimal in the number of moves; it is deterministic.

With a `MoveCheck` the order must also be executable by the robot: every move has a top-down
grasp of the 2F-85 that clears the neighbours at both ends. The geometric order is kept when
it is; otherwise the planner plans again, grasp-aware: a move must have a grasp and must not
take away the grasp of an object that still has to move (to pick it, or to put it on its
goal); when nothing can be placed, an object that blocks a grasp is moved aside; temporary
places must be reachable and leave the object pickable among the finished goal.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from domains.errors import GenerationError
from geometry import Body, Piece, Workspace, body_separation, place, resting_height
from geometry import resting_on as supports

if TYPE_CHECKING:
    from geometry import MoveCheck


@dataclass(frozen=True, kw_only=True)
class ReferencePlanner:
    """Plans construction orders for one domain's objects."""

    parts: Mapping[str, Sequence[Piece]]  # mesh key → convex parts
    symmetries: Mapping[str, np.ndarray]  # mesh key → (n, 4, 4)
    region: Workspace  # where temporary places may be
    clearance: float = 0.03  # free gap around a temporary place, for the fingers [m]
    goal_clearance: float = 0.01  # gap between a temporary place and unbuilt goals [m]
    grid: float = 0.01  # spacing of candidate temporary places [m]
    touch: float = 5e-4  # penetration still counted as touching [m]
    loose_gap: float = 0.003  # least gap from an object not in its final place [m]
    grasps: MoveCheck | None = None  # when set, every move must have a grasp
    temporary_checks: int = 60  # temporary places whose grasps are checked, nearest first

    def order(self, start: Sequence[Mapping], goal: Sequence[Mapping]) -> list[dict]:
        """Steps ``{"object", "target_pose"}`` that turn `start` into `goal`.

        Raises:
            GenerationError: no order was found (the instance should be re-drawn).
        """
        steps = self._order(start, goal, careful=False)
        if self.grasps is None or self.grasps.first_infeasible(start, steps) is None:
            return steps
        steps = self._order(start, goal, careful=True)
        bad = self.grasps.first_infeasible(start, steps)
        if bad is not None:
            raise GenerationError(f"the construction order is not executable: {bad}")
        return steps

    def _order(
        self, start: Sequence[Mapping], goal: Sequence[Mapping], *, careful: bool
    ) -> list[dict]:
        mesh = {r["id"]: r["mesh"] for r in goal}
        ids = sorted(mesh)
        if sorted(r["id"] for r in start) != ids:
            raise GenerationError("start and goal have different objects")
        state = {r["id"]: np.asarray(r["pose"], float) for r in start}
        target = {r["id"]: np.asarray(r["pose"], float) for r in goal}
        goal_bodies = {i: place(i, self.parts[mesh[i]], target[i]) for i in ids}
        goal_sup = supports(list(goal_bodies.values()))
        steps: list[dict] = []

        for _ in range(4 * len(ids) + 4):
            bodies = {i: place(i, self.parts[mesh[i]], state[i]) for i in ids}
            sup = supports(list(bodies.values()))
            done: dict[str, bool] = {}

            def is_done(i: str, sup=sup, done=done) -> bool:
                if i not in done:
                    done[i] = False  # guards against support cycles
                    done[i] = (
                        self._same(mesh[i], state[i], target[i])
                        and sup[i] == goal_sup[i]
                        and all(is_done(s) for s in goal_sup[i])
                    )
                return done[i]

            if all(is_done(i) for i in ids):
                return steps
            loaded = {s for i in ids for s in sup[i]}
            movable = [i for i in ids if not is_done(i) and i not in loaded]
            movable.sort(key=lambda i: (goal_bodies[i].lowest, i))

            move = None
            robot = (
                _RobotView(self, mesh, state, target, goal_sup, sup, is_done) if careful else None
            )
            for i in movable:
                if not all(is_done(s) for s in goal_sup[i]):
                    continue
                pose = self._reachable(mesh[i], state[i], target[i])
                body = place(i, self.parts[mesh[i]], pose) if pose is not None else None
                if pose is None or body is None or not self._fits(i, body, bodies, is_done):
                    continue
                if robot is not None and not robot.allows(i, pose):
                    continue
                move = (i, pose)
                break
            if move is None:
                blocker, occupies = self._blocker(
                    movable, bodies, goal_bodies, goal_sup, sup, is_done
                )
                if robot is not None:
                    blocker = robot.blocker(movable, blocker, occupies)
                if blocker is None:
                    raise GenerationError("no movable object unblocks the construction")
                pending = [goal_bodies[i] for i in ids if not is_done(i) and i != blocker]
                pose = self._temporary(
                    blocker, mesh[blocker], state[blocker], bodies, pending, robot=robot
                )
                move = (blocker, pose)
            i, pose = move
            state[i] = pose
            steps.append({"object": i, "target_pose": pose})
        moved = " ".join(s["object"] for s in steps[-8:])
        raise GenerationError(f"no construction order within {len(steps)} moves (last: {moved})")

    # -- helpers -------------------------------------------------------------------------

    def _same(self, mesh: str, a: np.ndarray, b: np.ndarray, tol: float = 1e-6) -> bool:
        sym = b @ self.symmetries[mesh]  # (n, 4, 4)
        return bool(np.any(np.abs(sym - a).reshape(len(sym), -1).max(axis=1) <= tol))

    def _reachable(self, mesh: str, current: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        """The symmetric equivalent of `goal` reached from `current` by the smallest yaw."""
        best, best_yaw = None, np.inf
        for s in self.symmetries[mesh]:
            cand = goal @ s
            r = cand[:3, :3] @ current[:3, :3].T
            if abs(r[2, 2] - 1) > 1e-6:
                continue  # needs a tilt, not a pure yaw
            yaw = abs(np.arctan2(r[1, 0], r[0, 0]))
            if yaw < best_yaw - 1e-9:
                best, best_yaw = cand, yaw
        return best

    def _fits(self, i: str, body: Body, bodies: Mapping[str, Body], is_done) -> bool:
        """`i` may go to `body`: it touches final objects at most as closely as the goal packs
        them, keeps `loose_gap` from the others (lying anywhere, they would be shoved), and
        nothing ends up resting on it."""
        others = [b for j, b in bodies.items() if j != i]
        for j, b in bodies.items():
            if j == i:
                continue
            gap, _ = body_separation(body, b, cutoff=0.01)
            if gap < (-self.touch if is_done(j) else self.loose_gap):
                return False
        # nothing may end up resting on the object just placed
        after = supports([body, *others])
        return not any(i in s for s in after.values())

    def _blocker(
        self, movable, bodies, goal_bodies, goal_sup, sup, is_done
    ) -> tuple[str | None, bool]:
        """The object to move aside, and whether it occupies a goal that is ready."""
        # 1. something sits where a goal, whose supports are ready, must go
        for i in sorted(goal_bodies):
            if is_done(i) or not all(is_done(s) for s in goal_sup[i]):
                continue
            for j in movable:
                if (
                    j != i
                    and body_separation(goal_bodies[i], bodies[j], cutoff=0.01)[0] < self.loose_gap
                ):
                    return j, True
        # 2. something rests on an object that still has to move
        for j in movable:
            if any(not is_done(s) for s in sup[j]):
                return j, False
        # 3. anything not final that is in a goal's way or lies in the wrong place
        return (movable[0] if movable else None), False

    def _temporary(self, i, mesh, current, bodies, pending, robot=None) -> np.ndarray:
        rot = current[:3, :3]
        z = resting_height(self.parts[mesh], rot)
        xs = np.arange(self.region.x[0], self.region.x[1] + 1e-9, self.grid)
        ys = np.arange(self.region.y[0], self.region.y[1] + 1e-9, self.grid)
        cand = np.array([(x, y) for x in xs for y in ys])
        order = np.argsort(np.linalg.norm(cand - current[:2, 3], axis=1), kind="stable")
        others = [b for j, b in bodies.items() if j != i]
        checked = 0
        for k in order:
            pose = np.eye(4)
            pose[:3, :3] = rot
            pose[:3, 3] = (*cand[k], z)
            body = place(i, self.parts[mesh], pose)
            if not self.region.contains(body.xy()):
                continue
            if any(
                body_separation(body, b, cutoff=self.clearance)[0] < self.clearance for b in others
            ):
                continue
            if any(
                body_separation(body, g, cutoff=self.goal_clearance)[0] < self.goal_clearance
                for g in pending
            ):
                continue
            if robot is not None:
                if checked >= self.temporary_checks:
                    break
                checked += 1
                if not robot.allows_temporary(i, pose):
                    continue
            return pose
        raise GenerationError(f"no free temporary place for {i!r}")


class _RobotView:
    """The grasp-aware rules of one planning step (see the module docstring)."""

    def __init__(self, planner, mesh, state, target, goal_sup, sup, is_done) -> None:
        self.grasps: MoveCheck = planner.grasps
        self.mesh, self.state, self.target = mesh, state, target
        self.goal_sup, self.is_done = goal_sup, is_done
        loaded = {s for i in state for s in sup[i]}
        self.todo = [i for i in sorted(state) if not is_done(i)]
        self.free = [i for i in self.todo if i not in loaded]
        self.blocked: list[str] = []  # neighbours that blocked a wanted move, in order
        self.harmed: list[str] = []  # objects a wanted move would leave ungraspable
        self.wanted: dict[str, tuple[str, np.ndarray]] = {}  # such an object → that move

    def _world(self, moved: str | None = None, pose: np.ndarray | None = None) -> dict:
        world = {j: (self.mesh[j], p) for j, p in self.state.items()}
        if moved is not None:
            world[moved] = (self.mesh[moved], pose)
        return world

    def _can_pick(self, j: str, world: Mapping) -> bool:
        return self.grasps.pickable(j, self.mesh[j], world[j][1], world).ok

    def _can_place(self, j: str, world: Mapping) -> bool:
        """`j` could go onto its goal (if it were there already: the place side only)."""
        goal = self.target[j]
        return self.grasps.move(j, self.mesh[j], goal, goal, {}, world).ok

    def _ready(self, j: str) -> bool:
        return all(self.is_done(s) for s in self.goal_sup[j])

    def _harm(self, i: str, pose: np.ndarray, before: Mapping | None = None) -> list[str]:
        """Objects still to move that `i` at `pose` would leave without a grasp."""
        before = self._world() if before is None else before
        after = {**before, i: (self.mesh[i], pose)}

        def lost_pick(j: str) -> bool:
            return j in self.free and self._can_pick(j, before) and not self._can_pick(j, after)

        def lost_place(j: str) -> bool:
            return self._ready(j) and self._can_place(j, before) and not self._can_place(j, after)

        return [j for j in self.todo if j != i and (lost_pick(j) or lost_place(j))]

    def allows(self, i: str, pose: np.ndarray) -> bool:
        """Moving `i` to its goal `pose` has a grasp and harms no other object."""
        verdict = self.grasps.move(i, self.mesh[i], self.state[i], pose, self._world())
        if not verdict.ok:
            self.blocked += [j for j in verdict.blockers if j not in self.blocked]
            for j in verdict.blockers:
                self.wanted.setdefault(j, (i, pose))
            return False
        harmed = self._harm(i, pose)
        self.harmed += [j for j in harmed if j not in self.harmed]
        for j in harmed:
            self.wanted.setdefault(j, (i, pose))
        return not harmed

    def allows_temporary(self, i: str, pose: np.ndarray) -> bool:
        """A temporary place: away from where `i` is, reachable now, harmless, and `i` can be
        picked from it among the finished goal (every other object at its goal pose); if `i`
        is moved aside for a wanted move, that move no longer finds it in the way."""
        if np.linalg.norm(pose[:2, 3] - self.state[i][:2, 3]) < 0.01:
            return False
        if not self.grasps.move(i, self.mesh[i], self.state[i], pose, self._world()).ok:
            return False
        finished = {j: (self.mesh[j], self.target[j]) for j in self.state if j != i}
        if not self.grasps.pickable(i, self.mesh[i], pose, finished).ok:
            return False
        if self._harm(i, pose):
            return False
        if i in self.wanted:
            c, c_pose = self.wanted[i]
            world = self._world(i, pose)
            verdict = self.grasps.move(c, self.mesh[c], self.state[c], c_pose, world)
            if i in verdict.blockers or i in self._harm(c, c_pose, world):
                return False
        return True

    def blocker(self, movable: Sequence[str], geometric: str | None, occupies: bool) -> str | None:
        """What to move aside: an object occupying a goal that is ready first, then one that
        blocks a wanted grasp, then one a wanted move would harm, else the geometric choice."""
        if occupies:
            return geometric
        for j in [*self.blocked, *self.harmed]:
            if j in movable:
                return j
        return geometric
