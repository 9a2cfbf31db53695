"""Whole moves: whether the robot can carry an object from one pose to another among its
neighbours — a grasp (`geometry.grasps`) that clears them at the pick and at the place, and
nothing above the object at either end (it rises straight up and comes straight down) — and the
first move of an order it cannot make. Cached on the poses involved."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh

from geometry.convex import Body, Piece, body_separation, place
from geometry.grasps import Grasp, Obstacle, plan_grasps, pose_key
from geometry.robot import ROBOT
from geometry.tolerances import TOLERANCES

NEAR = 0.2  # neighbours farther than this (horizontally) from the object cannot be hit [m]
UP = np.array([0.0, 0.0, 1.0])  # the vertical sweep above a pick or a place [m]


@dataclass(frozen=True, kw_only=True)
class MoveVerdict:
    """Whether the robot can make a move; if not, why, and the neighbours in the way.

    Attributes:
        ok: True when some grasp makes the move.
        blockers: when not `ok`, the ids (str) of the neighbours in the way, most blocking
            first; empty when no neighbour is to blame (e.g. no face pair fits the jaws).
        reason: when not `ok`, why in words ("'b' is above the object at the pick", "no
            top-down 2F-85 grasp clears the neighbours: …"); "" when `ok`.
        grasps: feasible grasps found (at most the `limit` asked for; not ranked).
    """

    ok: bool
    blockers: tuple[str, ...] = ()  # most blocking first
    reason: str = ""
    grasps: tuple[Grasp, ...] = ()


@dataclass(frozen=True, kw_only=True)
class Infeasible:
    """The first step of an order that the robot cannot make."""

    step: int
    object: str
    verdict: MoveVerdict

    def __str__(self) -> str:
        return f"step {self.step} ({self.object}): {self.verdict.reason}"


class MoveCheck:
    """Whether the robot can make single moves — a grasp that clears the neighbours at the pick
    and at the place, and nothing above the object at either (it rises straight up and comes
    straight down) — cached on the poses involved.

    Args:
        meshes: mesh key → mesh (object frame).
        symmetries: mesh key → (n, 4, 4) object-frame symmetry transforms.
        pieces: mesh key → convex pieces (object frame), for the vertical sweep.
        margins: clearances tried between the gripper and the neighbours [m].
    """

    def __init__(
        self,
        meshes: Mapping[str, trimesh.Trimesh],
        symmetries: Mapping[str, np.ndarray],
        pieces: Mapping[str, Sequence[Piece]],
        *,
        margins: tuple[float, ...] = TOLERANCES.grasp_margins,
    ) -> None:
        self.meshes = meshes
        self.symmetries = symmetries
        self.parts = pieces
        self.margins = margins
        self._cache: dict[Any, MoveVerdict] = {}
        self._sweeps: dict[Any, Body] = {}
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
        *,
        limit: int = 1,
    ) -> MoveVerdict:
        """Can `oid` be moved from `T_from` to `T_to` with `others` ({id: (mesh, pose)})
        around the pick and `place_others` (default: the same) around the place? Collects up
        to `limit` feasible grasps (their reachability is the arm's IK, outside this model)."""
        place_others = others if place_others is None else place_others
        pick = self._near(T_from, mesh, others, oid)
        place = self._near(T_to, mesh, place_others, oid)
        key = (oid, mesh, pose_key(T_from), pose_key(T_to), pick, place, limit)
        if key not in self._cache:
            self._cache[key] = self._plan(oid, mesh, T_from, T_to, others, place_others, key)
        return self._cache[key]

    def pickable(
        self, oid: str, mesh: str, T: np.ndarray, others: Mapping[str, tuple[str, np.ndarray]]
    ) -> MoveVerdict:
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
                out.append((j, m, pose_key(pose)))
        return tuple(out)

    def _above(self, mesh: str, T: np.ndarray, near: tuple, pool: Mapping) -> list[str]:
        """Neighbours in the vertical sweep of the object's convex parts above pose `T`."""
        touch, clear = TOLERANCES.sweep_touch, TOLERANCES.sweep_clearance
        lo, hi = self._box(mesh, T)
        swept: Body | None = None
        out = []
        for j, m, _ in near:
            lo_j, hi_j = self._box(m, pool[j][1])
            # a neighbour wholly over the object (an overhang) must clear its sweep: the object
            # passes under its edge; one beside it may touch the sweep (it stands next to it)
            need = clear if lo_j[2] >= hi[2] else -touch
            reach = max(need, touch)
            # a neighbour beside the object's outline, or wholly below it, is not above it
            if np.any(lo_j[:2] > hi[:2] + reach) or np.any(hi_j[:2] < lo[:2] - reach):
                continue
            if hi_j[2] < lo[2]:
                continue
            if swept is None:
                swept = self._sweep(mesh, T)
            body = place(j, self.parts[m], pool[j][1])
            if body_separation(swept, body, cutoff=reach)[0] < need:
                out.append(j)
        return out

    def _box(self, mesh: str, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned bounds (lo, hi) of the mesh at `T`."""
        v = np.asarray(self.meshes[mesh].vertices) @ T[:3, :3].T + T[:3, 3]
        return v.min(axis=0), v.max(axis=0)

    def _sweep(self, mesh: str, T: np.ndarray) -> Body:
        """The object's convex parts at `T` swept straight up (cached on the pose)."""
        key = (mesh, pose_key(T))
        got = self._sweeps.get(key)
        if got is None:
            pieces = []
            for p in place("", self.parts[mesh], T).pieces:
                v = p.vertices
                pieces.append(Piece.of(np.vstack([v, v + UP])))
            got = self._sweeps[key] = Body(id="", pieces=tuple(pieces))
        return got

    def _plan(self, oid, mesh, T_from, T_to, others, place_others, key) -> MoveVerdict:
        for where, T, near, pool in (
            ("pick", T_from, key[4], others),
            ("place", T_to, key[5], place_others),
        ):
            above = self._above(mesh, T, near, pool)
            if above:
                return MoveVerdict(
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
            limit=key[6],
        )
        if report.grasps:
            return MoveVerdict(ok=True, grasps=report.grasps)
        blockers = tuple(sorted(report.blockers, key=lambda j: -report.blockers[j]))
        return MoveVerdict(
            ok=False,
            blockers=blockers,
            reason=f"no top-down {ROBOT.gripper.name} grasp clears the neighbours: "
            f"{report.summary()}",
        )


__all__ = ["Infeasible", "MoveCheck", "MoveVerdict"]
