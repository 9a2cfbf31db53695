"""Whether the FR3 reaches a grasp: IK at the grasp's pick and place TCP poses.

Design rule: one reachability test, the executor's: it ranks its grasp candidates with it, and
the plan checks ask it of every step (through `checks.robot`), so a step the checks accept has
an arm pose at both ends. Solutions are cached by pose (grasps share pick and place poses).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from geometry.grasps import Grasp
from sim import robot
from sim.ik import ArmIK, IKSolution


@dataclass(frozen=True, kw_only=True)
class Reached:
    """A grasp's reachability: `ok`, else why; the wrist's distance from its limits [rad]."""

    ok: bool
    reason: str = ""
    wrist_margin: float = 0.0


class Reach:
    """IK at grasp poses, seeded the executor's way (READY posture turned towards the pose)."""

    def __init__(self, ik: ArmIK | None = None) -> None:
        self.ik = ik or ArmIK()
        self._solved: dict[bytes, IKSolution] = {}
        lo, hi = robot.RobotIndex.from_model(self.ik.model).arm_range[6]
        self._wrist = (float(lo), float(hi))

    def solve(self, T: np.ndarray) -> IKSolution:
        key = np.round(np.asarray(T, float)[:3], 5).tobytes()
        if key not in self._solved:
            seed = robot.READY_QPOS.copy()
            seed[0] = np.arctan2(T[1, 3], T[0, 3])
            self._solved[key] = self.ik.solve(T, seed)
        return self._solved[key]

    def grasp(self, g: Grasp, wrist: tuple[float, float] | None = None) -> Reached:
        """Whether the arm reaches `g` at the pick and at the place."""
        lo, hi = wrist or self._wrist
        margins = []
        for where, T in (("grasp", g.pick_tcp), ("place", g.place_tcp)):
            sol = self.solve(T)
            if not sol.ok:
                return Reached(
                    ok=False,
                    reason=f"no IK solution at the {where} pose "
                    f"{np.round(T[:3, 3], 3).tolist()} (off by {sol.position_error * 1000:.0f} mm)",
                )
            margins.append(min(sol.q[6] - lo, hi - sol.q[6]))
        return Reached(ok=True, wrist_margin=float(min(margins)))

    def any(self, grasps: Sequence[Grasp]) -> Reached:
        """The first reachable grasp's result, else the first failure."""
        first: Reached | None = None
        for g in grasps:
            got = self.grasp(g)
            if got.ok:
                return got
            first = first or got
        return first or Reached(ok=False, reason="no grasp to reach")
