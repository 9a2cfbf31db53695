"""The reference construction order: top-down pick-and-place from a start to a goal.

Rules the order obeys (they are what the executor's oracle needs):
- an object is moved only when nothing rests on it;
- it goes to its goal pose only when everything it rests on in the goal is already final;
- a placement never leaves anything resting on the placed object (no inserting underneath);
- a target never interpenetrates the objects already there; temporary places keep a
  gripper-sized clearance from everything present and from every goal still to be built;
- every move changes the object's orientation only by a rotation about the vertical: the
  target is the symmetry-equivalent of the goal pose that a yaw rotation reaches.
Greedy: place whatever can be placed, lowest first; otherwise move one blocking object
aside. It is not optimal in the number of moves; it is deterministic.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from domains._geometry import Body, ConvexPart, body_separation, place, resting_height, supports
from domains.errors import GenerationError


@dataclass(frozen=True, kw_only=True)
class Region:
    """Where objects may be put down: an axis-aligned box in x, y and a disc about the base."""

    x: tuple[float, float]  # [m]
    y: tuple[float, float]  # [m]
    reach: float  # largest horizontal distance from the robot base axis [m]

    def contains(self, xy: np.ndarray) -> bool:
        xy = np.asarray(xy, float).reshape(-1, 2)
        return bool(
            (xy[:, 0] >= self.x[0]).all()
            and (xy[:, 0] <= self.x[1]).all()
            and (xy[:, 1] >= self.y[0]).all()
            and (xy[:, 1] <= self.y[1]).all()
            and (np.linalg.norm(xy, axis=1) <= self.reach).all()
        )


@dataclass(frozen=True, kw_only=True)
class Planner:
    """Plans construction orders for one domain's objects."""

    parts: Mapping[str, Sequence[ConvexPart]]  # mesh key → convex parts
    symmetries: Mapping[str, np.ndarray]  # mesh key → (n, 4, 4)
    region: Region  # where temporary places may be
    clearance: float = 0.03  # free gap around a temporary place, for the fingers [m]
    goal_clearance: float = 0.01  # gap between a temporary place and unbuilt goals [m]
    grid: float = 0.01  # spacing of candidate temporary places [m]
    touch: float = 5e-4  # penetration still counted as touching [m]

    def order(self, start: Sequence[Mapping], goal: Sequence[Mapping]) -> list[dict]:
        """Steps ``{"object", "target_pose"}`` that turn `start` into `goal`.

        Raises:
            GenerationError: no order was found (the instance should be re-drawn).
        """
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
            for i in movable:
                if not all(is_done(s) for s in goal_sup[i]):
                    continue
                pose = self._reachable(mesh[i], state[i], target[i])
                if pose is not None and self._fits(i, place(i, self.parts[mesh[i]], pose), bodies):
                    move = (i, pose)
                    break
            if move is None:
                blocker = self._blocker(movable, bodies, goal_bodies, goal_sup, sup, is_done)
                if blocker is None:
                    raise GenerationError("no movable object unblocks the construction")
                pending = [goal_bodies[i] for i in ids if not is_done(i) and i != blocker]
                pose = self._temporary(blocker, mesh[blocker], state[blocker], bodies, pending)
                move = (blocker, pose)
            i, pose = move
            state[i] = pose
            steps.append({"object": i, "target_pose": pose})
        raise GenerationError(f"no construction order within {len(steps)} moves")

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

    def _fits(self, i: str, body: Body, bodies: Mapping[str, Body]) -> bool:
        others = [b for j, b in bodies.items() if j != i]
        for b in others:
            gap, _ = body_separation(body, b, cutoff=0.01)
            if gap < -self.touch:
                return False
        # nothing may end up resting on the object just placed
        after = supports([body, *others])
        return not any(i in s for s in after.values())

    def _blocker(self, movable, bodies, goal_bodies, goal_sup, sup, is_done) -> str | None:
        # 1. something sits where a goal, whose supports are ready, must go
        for i in sorted(goal_bodies):
            if is_done(i) or not all(is_done(s) for s in goal_sup[i]):
                continue
            for j in movable:
                if (
                    j != i
                    and body_separation(goal_bodies[i], bodies[j], cutoff=0.01)[0] < -self.touch
                ):
                    return j
        # 2. something rests on an object that still has to move
        for j in movable:
            if any(not is_done(s) for s in sup[j]):
                return j
        # 3. anything not final that is in a goal's way or lies in the wrong place
        return movable[0] if movable else None

    def _temporary(self, i, mesh, current, bodies, pending) -> np.ndarray:
        rot = current[:3, :3]
        z = resting_height(self.parts[mesh], rot)
        xs = np.arange(self.region.x[0], self.region.x[1] + 1e-9, self.grid)
        ys = np.arange(self.region.y[0], self.region.y[1] + 1e-9, self.grid)
        cand = np.array([(x, y) for x in xs for y in ys])
        order = np.argsort(np.linalg.norm(cand - current[:2, 3], axis=1), kind="stable")
        others = [b for j, b in bodies.items() if j != i]
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
            return pose
        raise GenerationError(f"no free temporary place for {i!r}")
