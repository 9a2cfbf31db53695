"""The robot's view of a plan, for the checks: can the executor carry out every step?

Design rule: nothing here is a model of its own. The hand is `geometry.moves` (the model the
executor picks its grasps with, and that programs get as `toolbox.hand`); the arm is
`sim.reach` (the executor's IK test). A step is executable when some top-down grasp of the
2F-85 clears every other object at the pick (in the state before the step) and at the place
(in the state after it), nothing lies above the object at either end (it rises and descends
vertically), and the arm has an IK solution at both ends of that grasp.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from contracts import se3

CANDIDATES = 4  # feasible grasps per step tried for an arm pose


@dataclass(frozen=True, kw_only=True)
class StepProblem:
    """The first step the robot could not execute (`step` None: all could); `checked` steps."""

    step: int | None
    object: str | None = None
    message: str = ""
    blockers: tuple[str, ...] = ()
    checked: int = 0


class RobotView:
    """Executability of plan steps for one domain's objects (cached on the poses)."""

    def __init__(self, domain: Any) -> None:
        from sim.reach import Reach

        self.moves = domain.grasps  # geometry.moves.MoveCheck over the domain's meshes
        self.reach = Reach()

    def first_problem(
        self, start: Sequence[Mapping[str, Any]], steps: Sequence[Mapping[str, Any]]
    ) -> StepProblem:
        """Apply `steps` from `start` and name the first the robot cannot execute."""
        state = {str(r["id"]): (str(r["mesh"]), np.asarray(r["pose"], float)) for r in start}
        for k, step in enumerate(steps):
            oid = str(step.get("object"))
            if oid not in state:
                return StepProblem(step=None, checked=k)  # reaches_goal reports it
            mesh, pose = state[oid]
            try:
                target = se3.as_matrix(step["target_pose"])
            except (KeyError, TypeError, ValueError):
                return StepProblem(step=None, checked=k)
            others = {j: v for j, v in state.items() if j != oid}
            verdict = self.moves.move(oid, mesh, pose, target, others, limit=CANDIDATES)
            if not verdict.ok:
                return StepProblem(
                    step=k,
                    object=oid,
                    message=f"moves '{oid}', but {verdict.reason}",
                    blockers=verdict.blockers,
                    checked=k + 1,
                )
            reached = self.reach.any(verdict.grasps)
            if not reached.ok:
                return StepProblem(
                    step=k,
                    object=oid,
                    message=f"moves '{oid}', but the arm cannot reach any of its grasps: "
                    f"{reached.reason}",
                    checked=k + 1,
                )
            state[oid] = (mesh, target)
        return StepProblem(step=None, checked=len(steps))


@functools.lru_cache(maxsize=8)
def robot_view(domain: str) -> RobotView:
    """The executor's hand and arm for a domain's objects (shared: its caches pay off across
    the drafts of an authoring run and the cases drawn for them)."""
    import domains

    return RobotView(domains.load(domain))
