"""Physical validity: geometry checks, settling, and checks of construction orders.

A scene is physically valid when
- every object lies inside the domain's reachable workspace (every mesh vertex), no higher
  than `Domain.max_height`;
- nothing penetrates the table or another object by more than the oracle's tolerance
  (`geometry.TOLERANCES.penetration`, 1 mm);
- it is settled: simulating it without the robot for `DURATION` (2 s), no point of any
  object moves more than `MOTION` (2 mm).
The first two are the oracle geometry (`geometry`); the last is MuJoCo.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from domains import Domain
from domains.generation import Problem, geometric_problems
from geometry import TOLERANCES
from sim.errors import InvalidSceneError
from sim.scene import scene_model

PENETRATION = TOLERANCES.penetration  # [m]
MOTION = 0.002  # [m]
DURATION = 2.0  # [s]


@dataclass(frozen=True, kw_only=True)
class SettleResult:
    """The outcome of simulating a scene at rest."""

    scene: dict  # the scene with the poses after `duration`
    motion: dict[str, float]  # largest displacement of any vertex of each object [m]
    speed: dict[str, float]  # final linear speed of each object [m/s]

    @property
    def settled(self) -> bool:
        return all(m <= MOTION for m in self.motion.values())


def settle(domain: Domain, scene: Mapping, *, duration: float = DURATION) -> SettleResult:
    """Simulate the objects (no robot) for `duration` [s] from rest."""
    sm = scene_model(domain, scene)
    before = {r["id"]: np.asarray(r["pose"], float) for r in scene["objects"]}
    steps = round(duration / sm.model.opt.timestep)
    for _ in range(steps):
        mujoco.mj_step(sm.model, sm.data)
    after = sm.records()
    motion, speed = {}, {}
    for r in after:
        verts = np.concatenate([p.vertices for p in domain.parts[r["mesh"]]])
        h = np.c_[verts, np.ones(len(verts))]
        d = h @ (r["pose"] - before[r["id"]]).T
        motion[r["id"]] = float(np.linalg.norm(d[:, :3], axis=1).max())
        a = sm.qvel_address(r["id"])
        speed[r["id"]] = float(np.linalg.norm(sm.data.qvel[a : a + 3]))
    return SettleResult(scene={"domain": domain.name, "objects": after}, motion=motion, speed=speed)


def physical_problems(
    domain: Domain, scene: Mapping, *, duration: float = DURATION
) -> list[Problem]:
    """Objects that move more than `MOTION` when the scene is simulated for `duration` [s]."""
    result = settle(domain, scene, duration=duration)
    return [
        Problem(
            object=i,
            problem=f"is not at rest: moves {m * 1000:.1f} mm in {duration:g} s of simulation",
        )
        for i, m in result.motion.items()
        if m > MOTION
    ]


def check_scene(domain: Domain, scene: Mapping) -> list[Problem]:
    """Every problem of a parsed scene: geometry first, physics only if the geometry is sound."""
    return geometric_problems(domain, scene) or physical_problems(domain, scene)


def validate_scene(domain: Domain, scene: Mapping, *, where: str = "") -> None:
    """Raise InvalidSceneError (exit code 2) naming the first problem of a parsed scene."""
    problems = check_scene(domain, scene)
    if problems:
        raise InvalidSceneError(
            problems[0].object,
            problems[0].problem,
            problems=[(p.object, p.problem) for p in problems],
            where=where,
        )


def check_order(
    domain: Domain, start: Mapping, steps: Sequence[Mapping], goal: Mapping, *, physics: bool = True
) -> list[Problem]:
    """Problems of executing `steps` from `start` by teleporting one object per step.

    The abstract judge is `geometry.apply_plan` (the same as the plan checks'): at every step
    the moved object has nothing resting on it and the state after the move is free of
    interpenetration, supported and stable, inside the workspace; at the end every object is
    at its goal pose within the domain's tolerance, modulo symmetry. With `physics`, every
    state after a step must also settle in MuJoCo, and stay no higher than `max_height`.
    """
    from geometry import apply_plan

    tol = domain.tolerance
    symmetries = {k: list(domain.symmetries(k)) for k in domain.mesh_specs}
    outcome = apply_plan(
        domain.shapes,
        start["objects"],
        steps,
        goal["objects"],
        trans_tol=tol.translation,
        rot_tol=tol.rotation,
        symmetries=symmetries,
        workspace=domain.workspace,
    )
    if outcome.problem is not None:
        p = outcome.problem
        return [Problem(object=p.object, problem=p.message)]
    for k, state in enumerate(outcome.states):
        scene = {"domain": domain.name, "objects": state}
        found = [q for q in geometric_problems(domain, scene) if "above" in q.problem]
        if not found and physics:
            found = physical_problems(domain, scene)
        if found:
            moved = steps[k]["object"]
            return [
                Problem(object=q.object, problem=f"after step {k} ({moved}): {q.problem}")
                for q in found
            ]
    return []


__all__ = [
    "DURATION",
    "MOTION",
    "PENETRATION",
    "Problem",
    "SettleResult",
    "check_order",
    "check_scene",
    "geometric_problems",
    "physical_problems",
    "settle",
    "validate_scene",
]
