"""Drawing instances: goals and starts from a domain's generator, kept only when valid.

Design rule: a draw is rejected unless it is physically valid — by geometry here (workspace,
height, interpenetration: `geometric_problems`), and, when the caller passes one, by a physics
check such as `sim.settle.physical_problems` (MuJoCo settling; the simulator builds on the
domains, so it is handed in, never imported) — and unless the reference planner finds a
construction order for it (one the robot can execute with `grasps`). Every draw is seeded, so
an instance is a pure function of its keys.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from domains.errors import GenerationError
from domains.instance import Instance
from geometry import TOLERANCES, bodies_of, body_separation

if TYPE_CHECKING:
    from domains.base import Domain

ATTEMPTS = 40  # draws per goal and per start before a key is given up


@dataclass(frozen=True, kw_only=True)
class Problem:
    """Something physically wrong with one object (or with the scene when `object` is None)."""

    object: str | None
    problem: str

    def __str__(self) -> str:
        return (
            f"object {self.object!r}: {self.problem}" if self.object is not None else self.problem
        )


PhysicsCheck = Callable[[Any, Mapping], Sequence[Problem]]
"""(domain, scene) → the scene's problems; [] when it is valid."""


def geometric_problems(domain: Domain, scene: Mapping) -> list[Problem]:
    """Workspace, height, table and interpenetration problems of a scene (no simulation)."""
    out: list[Problem] = []
    bodies = bodies_of(scene["objects"], domain.parts)
    ws = domain.workspace
    for b in bodies:
        far = ws.outside(b.vertices)
        if far is not None:
            out.append(
                Problem(
                    object=b.id,
                    problem=(
                        f"outside the reachable workspace (a point at x={far[0]:.3f}, "
                        f"y={far[1]:.3f} m; allowed {ws.describe()})"
                    ),
                )
            )
        if b.lowest < -TOLERANCES.penetration:
            out.append(
                Problem(object=b.id, problem=f"penetrates the table by {-b.lowest * 1000:.1f} mm")
            )
        if b.highest > domain.max_height:
            out.append(
                Problem(
                    object=b.id, problem=f"reaches z={b.highest:.3f} m, above {domain.max_height} m"
                )
            )
    for i, a in enumerate(bodies):
        for b in bodies[i + 1 :]:
            gap, _ = body_separation(a, b, cutoff=0.0)
            if gap < -TOLERANCES.penetration:
                out.append(
                    Problem(object=a.id, problem=f"penetrates {b.id!r} by {-gap * 1000:.1f} mm")
                )
    return out


def draw_instance(
    domain: Domain,
    *,
    name: str,
    seed: int | None,
    goal_key: tuple,
    goal_index: int | None,
    start_key: tuple,
    physics: PhysicsCheck | None,
    grasps: bool,
    split: str = "dev",
    ordered: bool = True,
) -> Instance:
    """The first valid goal and start drawn from the keys, with their construction order
    (`split`: which of the domain's goal and start families, "dev" or "test"; `ordered=False`:
    the first valid start, with no order, for those who need only the scenes — a start the
    order planner refuses is then kept).

    Raises:
        GenerationError: no valid goal or start within `ATTEMPTS` draws.
    """
    planner = domain.robot_reference_planner if grasps else domain.reference_planner
    problems: list[str] = []

    def invalid(records: Sequence[Mapping]) -> list[str]:
        scene = domain.scene(records)
        found = [str(p) for p in geometric_problems(domain, scene)]
        if not found and physics is not None:
            found = [str(p) for p in physics(domain, scene)]
        return found

    for attempt in range(ATTEMPTS):
        goal = domain.make_goal(
            np.random.default_rng([*goal_key, attempt]), goal_index, split=split
        )
        goal_problems = invalid(goal)
        if not goal_problems:
            break
        problems.append(f"goal draw {attempt}: {goal_problems[0]}")
    else:
        raise GenerationError(f"{domain.name} {name}: no valid goal; " + "; ".join(problems[-3:]))
    for attempt in range(ATTEMPTS):
        rng = np.random.default_rng([*start_key, attempt])
        start = domain.make_start(rng, goal, split=split)
        start_problems = invalid(start)
        if start_problems:
            problems.append(f"start draw {attempt}: {start_problems[0]}")
            continue
        order: Sequence[dict] = ()
        if ordered:
            try:
                order = planner.order(start, goal)
            except GenerationError as e:
                problems.append(f"start draw {attempt}: {e}")
                continue
            if not order:
                problems.append(f"start draw {attempt}: start equals goal")
                continue
        return Instance(
            domain=domain.name,
            name=name,
            seed=seed,
            start=domain.scene(start),
            goal=domain.scene(goal),
            order=tuple(order),
        )
    raise GenerationError(f"{domain.name} {name}: no valid start; " + "; ".join(problems[-3:]))


def retry(make: Callable[[], list[dict]], tries: int = 20) -> list[dict]:
    """`make()` again (its random generator moves on) while it raises `GenerationError`
    (e.g. finds no free place), at most `tries` times; the last error propagates."""
    for _ in range(tries - 1):
        try:
            return make()
        except GenerationError:
            pass
    return make()
