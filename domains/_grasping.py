"""Whether the robot can make a move: the executor's grasp predicate, for generators.

Design rule: the predicate is exactly the executor's, `sim.grasp.plan_grasps` with every other
object as a neighbour at both the pick and the place (no stricter margin: tangram pieces are
packed so that the fingertips pass 2 mm above the neighbours' plates, the executor's smaller
clearance), plus what the executor takes for granted: the object rises straight up from the
pick and comes straight down onto the place, so nothing may hang above either (a beam laid
across the pillars over the roof's end would be knocked off when the roof is lifted).
`sim` is imported on first use only: `domains` stays importable without MuJoCo, while using a
`GraspCheck` needs the robot models (`MENAGERIE_ROOT`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh

from domains._geometry import Body, ConvexPart, body_separation, place

NEAR = 0.2  # neighbours farther than this (horizontally) from the object cannot be hit [m]
UP = np.array([0.0, 0.0, 1.0])  # the vertical sweep above a pick or a place [m]
TOUCH = 5e-4  # penetration of the sweep still counted as touching [m]


@dataclass(frozen=True, kw_only=True)
class Verdict:
    """Whether the robot can make a move; if not, the neighbours in the way and why."""

    ok: bool
    blockers: tuple[str, ...] = ()  # most blocking first
    reason: str = ""


@dataclass(frozen=True, kw_only=True)
class Infeasible:
    """The first step of an order that the robot cannot make."""

    step: int
    object: str
    verdict: Verdict

    def __str__(self) -> str:
        return f"step {self.step} ({self.object}): {self.verdict.reason}"


class GraspCheck:
    """Whether the robot can make single moves (a grasp; nothing above the pick or the
    place), cached on the poses involved."""

    def __init__(
        self,
        meshes: Mapping[str, trimesh.Trimesh],
        symmetries: Mapping[str, np.ndarray],
        parts: Mapping[str, Sequence[ConvexPart]],
        *,
        margins: tuple[float, ...] = (0.006, 0.002),
    ) -> None:
        self.meshes = meshes  # mesh key → mesh (object frame)
        self.symmetries = symmetries  # mesh key → (n, 4, 4)
        self.parts = parts  # mesh key → convex parts (object frame)
        self.margins = margins
        self._cache: dict[Any, Verdict] = {}
        self._xy: dict[str, np.ndarray] = {
            k: np.asarray(m.vertices)[:, :2] for k, m in meshes.items()
        }

    def move(
        self,
        oid: str,
        mesh: str,
        T_from: np.ndarray,
        T_to: np.ndarray,
        others: Mapping[str, tuple[str, np.ndarray]],
        place_others: Mapping[str, tuple[str, np.ndarray]] | None = None,
    ) -> Verdict:
        """Can `oid` be moved from `T_from` to `T_to` with `others` ({id: (mesh, pose)})
        around the pick and `place_others` (default: the same) around the place?"""
        place_others = others if place_others is None else place_others
        pick = self._near(T_from, mesh, others, oid)
        place = self._near(T_to, mesh, place_others, oid)
        key = (oid, mesh, _key(T_from), _key(T_to), pick, place)
        if key not in self._cache:
            self._cache[key] = self._plan(oid, mesh, T_from, T_to, others, place_others, key)
        return self._cache[key]

    def pickable(
        self, oid: str, mesh: str, T: np.ndarray, others: Mapping[str, tuple[str, np.ndarray]]
    ) -> Verdict:
        """Can `oid` be picked (and put back) where it is, among `others`?"""
        return self.move(oid, mesh, T, T, others, others)

    def first_infeasible(
        self, start: Sequence[Mapping], steps: Sequence[Mapping]
    ) -> Infeasible | None:
        """The first step of `steps` from the records `start` the robot cannot make, or None."""
        state = {r["id"]: (r["mesh"], np.asarray(r["pose"], float)) for r in start}
        for k, step in enumerate(steps):
            oid = step["object"]
            mesh, pose = state[oid]
            others = {j: v for j, v in state.items() if j != oid}
            target = np.asarray(step["target_pose"], float)
            verdict = self.move(oid, mesh, pose, target, others)
            if not verdict.ok:
                return Infeasible(step=k, object=oid, verdict=verdict)
            state[oid] = (mesh, target)
        return None

    # -- internals ---------------------------------------------------------------------------

    def _near(
        self, T: np.ndarray, mesh: str, others: Mapping[str, tuple[str, np.ndarray]], oid: str
    ) -> tuple:
        """The neighbours that could be in the gripper's way (a cache key: ids and poses)."""
        centre = self._xy[mesh] @ T[:2, :2].T + T[:2, 3]
        lo, hi = centre.min(axis=0) - NEAR, centre.max(axis=0) + NEAR
        out = []
        for j in sorted(others):
            if j == oid:
                continue
            m, pose = others[j]
            xy = self._xy[m] @ pose[:2, :2].T + pose[:2, 3]
            if np.all(xy.max(axis=0) >= lo) and np.all(xy.min(axis=0) <= hi):
                out.append((j, m, _key(pose)))
        return tuple(out)

    def _above(self, mesh: str, T: np.ndarray, near: tuple, pool: Mapping) -> list[str]:
        """Neighbours in the vertical sweep of the object's convex parts above pose `T`."""
        sweep = []
        for p in place("", self.parts[mesh], T).parts:
            v = p.vertices
            sweep.append(ConvexPart.from_points(np.vstack([v, v + UP])))
        swept = Body(id="", parts=tuple(sweep))
        out = []
        for j, m, _ in near:
            body = place(j, self.parts[m], pool[j][1])
            if body_separation(swept, body, cutoff=TOUCH)[0] < -TOUCH:
                out.append(j)
        return out

    def _plan(self, oid, mesh, T_from, T_to, others, place_others, key) -> Verdict:
        from sim.grasp import Obstacle, plan_grasps  # sim builds on domains

        for where, T, near, pool in (
            ("pick", T_from, key[4], others),
            ("place", T_to, key[5], place_others),
        ):
            above = self._above(mesh, T, near, pool)
            if above:
                return Verdict(
                    ok=False,
                    blockers=tuple(above),
                    reason=f"{above[0]!r} is above the object at the {where}",
                )

        def obstacles(near, pool):
            return [Obstacle(id=j, mesh=self.meshes[m], pose=pool[j][1]) for j, m, _ in near]

        report = plan_grasps(
            self.meshes[mesh],
            T_from,
            T_to,
            symmetries=list(self.symmetries[mesh]),
            pick_obstacles=obstacles(key[4], others),
            place_obstacles=obstacles(key[5], place_others),
            margins=self.margins,
            limit=1,
        )
        if report.grasps:
            return Verdict(ok=True)
        blockers = tuple(sorted(report.blockers, key=lambda j: -report.blockers[j]))
        return Verdict(ok=False, blockers=blockers, reason=f"no grasp: {report.summary()}")


def _key(T: np.ndarray) -> bytes:
    return np.round(np.asarray(T, float)[:3], 7).tobytes()
