"""Applying a plan of object transfers abstractly: what every step leaves, and whether the
goal is reached.

Design rule: the one judge of "plan success" — the plan checks and the trials' scoring both
call `apply_plan`, with the same tolerances (`geometry.TOLERANCES`). Each step may move an
object only when nothing rests on it; the state after it must be free of interpenetration,
every object supported and stable with its load, and the moved object inside the workspace;
the last state must put every object within the domain's tolerance of its goal pose, modulo
its symmetries.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from contracts import se3
from geometry.contacts import collisions, supports, unstable_objects
from geometry.shape import Shape
from geometry.tolerances import TOLERANCES


@dataclass(frozen=True, kw_only=True)
class Workspace:
    """Where objects may be: every vertex inside an x, y box and within `reach` of the robot's
    base axis [m].

    Attributes:
        x: (min, max) world x [m].
        y: (min, max) world y [m].
        reach: largest horizontal distance from the robot's base axis (the world z axis) [m].
    """

    x: tuple[float, float]
    y: tuple[float, float]
    reach: float

    def contains(self, points: np.ndarray) -> bool:
        """Whether every point — (n, 2) or (n, 3), x and y are what count — lies inside."""
        pts = np.asarray(points, float)
        pts = pts.reshape(-1, pts.shape[-1])
        return self.outside(np.c_[pts[:, :2], np.zeros(len(pts))]) is None

    def outside(self, points: np.ndarray) -> np.ndarray | None:
        """The point (3,) farthest outside, or None when all are inside."""
        pts = np.asarray(points, float)
        xy = pts[:, :2]
        excess = np.stack(
            [
                self.x[0] - xy[:, 0],
                xy[:, 0] - self.x[1],
                self.y[0] - xy[:, 1],
                xy[:, 1] - self.y[1],
                np.linalg.norm(xy, axis=1) - self.reach,
            ],
            axis=1,
        ).max(axis=1)
        i = int(np.argmax(excess))
        return pts[i] if excess[i] > 1e-9 else None

    def describe(self) -> str:
        return (
            f"x∈[{self.x[0]}, {self.x[1]}], y∈[{self.y[0]}, {self.y[1]}] m, within {self.reach} m "
            "of the robot's base"
        )


@dataclass(frozen=True, kw_only=True)
class PlanProblem:
    """The first thing wrong when a plan's steps are applied (step None: the final state)."""

    kind: str  # unknown_object | not_clear | collision | unsupported | workspace | goal
    message: str
    step: int | None = None
    object: str | None = None


@dataclass(frozen=True, kw_only=True)
class PlanOutcome:
    """What applying a plan did: its first problem (None when it reaches the goal) and the
    states after each step (records, poses as arrays)."""

    problem: PlanProblem | None
    states: list[list[dict]] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.problem is None


def apply_plan(
    shapes: Mapping[str, Shape],
    start: Sequence[Mapping[str, Any]],
    steps: Sequence[Mapping[str, Any]],
    goal: Sequence[Mapping[str, Any]],
    *,
    trans_tol: float,
    rot_tol: float | None = None,
    symmetries: Mapping[str, Sequence[np.ndarray]] | None = None,
    workspace: Workspace | None = None,
) -> PlanOutcome:
    """Apply transfer steps ``{"object", "target_pose"}`` to `start` and judge every state
    (see the module docstring); `symmetries` maps mesh keys to object-frame transforms."""
    state = [dict(r, pose=se3.as_matrix(r["pose"])) for r in start]
    index = {r["id"]: i for i, r in enumerate(state)}
    states: list[list[dict]] = []
    for k, step in enumerate(steps):
        oid = step["object"]

        def problem(kind: str, message: str, who: str | None = None, k=k, oid=oid) -> PlanOutcome:
            return PlanOutcome(
                problem=PlanProblem(kind=kind, step=k, object=who or str(oid), message=message),
                states=states,
            )

        if oid not in index:
            return problem(
                "unknown_object", f"step {k} moves unknown object {oid!r}; known: {sorted(index)}"
            )
        loaded = sorted(i for i, on in supports(state, shapes).items() if oid in on)
        if loaded:
            names = ", ".join(f"'{i}'" for i in loaded)
            return problem("not_clear", f"step {k} picks '{oid}' while {names} rest(s) on it")
        state = [dict(r) for r in state]
        state[index[oid]] = dict(state[index[oid]], pose=se3.as_matrix(step["target_pose"]))
        states.append(state)
        if workspace is not None:
            moved = state[index[oid]]
            body = shapes[moved["mesh"]]._posed(moved["pose"])
            far = workspace.outside(np.concatenate([p.vertices for p in body]))
            if far is not None:
                return problem(
                    "workspace",
                    f"step {k} puts '{oid}' outside the reachable workspace (a point at "
                    f"x={far[0]:.3f}, y={far[1]:.3f} m; allowed {workspace.describe()})",
                )
        hits = collisions(state, shapes, tolerance=TOLERANCES.penetration)
        if hits:
            a, b, depth = max(hits, key=lambda h: (oid in (h[0], h[1]), h[2]))
            return problem(
                "collision",
                f"after step {k} (moving '{oid}'): '{a}' and '{b}' interpenetrate by "
                f"{1000 * depth:.1f} mm (more than {1000 * TOLERANCES.penetration:.1f} mm)",
            )
        falling = unstable_objects(state, shapes, contact_tol=TOLERANCES.contact)
        if falling:
            who = oid if oid in falling else sorted(falling)[0]
            return problem(
                "unsupported",
                f"after step {k} (moving '{oid}'): '{who}' {falling[who]}",
                who,
            )
    target = {r["id"]: r for r in goal}
    worst: tuple[float, str] | None = None
    for r in state:
        g = target.get(r["id"])
        if g is None:
            continue
        syms = list((symmetries or {}).get(r["mesh"], [np.eye(4)]))
        G = se3.as_matrix(g["pose"])
        if se3.within_tolerance(
            r["pose"], G, trans_tol=trans_tol, rot_tol=rot_tol, symmetries=syms
        ):
            continue
        dist, angle = se3.pose_error(r["pose"], G, syms)
        if rot_tol is None:
            err = f"{dist * 1000:.1f} mm from its goal (tolerance {trans_tol * 1000:.0f} mm)"
        else:
            err = (
                f"{dist * 1000:.1f} mm and {np.degrees(angle):.1f}° from its goal (tolerance "
                f"{trans_tol * 1000:.0f} mm, {np.degrees(rot_tol):.1f}°)"
            )
        if worst is None or dist > worst[0]:
            worst = (dist, f"'{r['id']}' ends {err}")
    if worst is not None:
        return PlanOutcome(
            problem=PlanProblem(
                kind="goal", message=f"the plan does not reach the goal: {worst[1]}"
            ),
            states=states,
        )
    return PlanOutcome(problem=None, states=states)
