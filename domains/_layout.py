"""Random placement of rigid groups of objects on the table, for the generators."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from domains.errors import GenerationError
from geometry import Body, Piece, Workspace, body_separation, place, yaw_pose


@dataclass(frozen=True, kw_only=True)
class Unit:
    """Objects that move together (a stack, a structure): poses relative to the unit frame."""

    members: tuple[tuple[str, str, np.ndarray], ...]  # (id, mesh, T_unit_object)


def unit(*members: tuple[str, str, np.ndarray]) -> Unit:
    return Unit(members=tuple(members))


def bodies(u: Unit, pose: np.ndarray, parts: Mapping[str, Sequence[Piece]]) -> list[Body]:
    return [place(i, parts[m], pose @ rel) for i, m, rel in u.members]


def records(u: Unit, pose: np.ndarray) -> list[dict]:
    return [{"id": i, "mesh": m, "pose": pose @ rel} for i, m, rel in u.members]


def fits(new: Sequence[Body], placed: Sequence[Body], region: Workspace, clearance: float) -> bool:
    """Inside the region and at least `clearance` [m] from every placed body."""
    if not all(region.contains(b.xy()) for b in new):
        return False
    return all(body_separation(a, b, cutoff=clearance)[0] >= clearance for a in new for b in placed)


def scatter(
    rng: np.random.Generator,
    units: Sequence[Unit],
    parts: Mapping[str, Sequence[Piece]],
    region: Workspace,
    *,
    placed: Sequence[Body] = (),
    clearance: float = 0.03,
    yaws: tuple[float, float] = (-np.pi, np.pi),
    area: Workspace | None = None,
    tries: int = 300,
) -> list[dict]:
    """Place each unit at a random position and heading, clear of the others.

    Args:
        area: where unit origins are drawn (default: `region`); bodies must stay in `region`.
    Returns:
        records of every member, in unit order.
    Raises:
        GenerationError: a unit found no free place in `tries` draws.
    """
    area = area or region
    out: list[dict] = []
    done = list(placed)
    for u in units:
        for _ in range(tries):
            x = rng.uniform(*area.x)
            y = rng.uniform(*area.y)
            pose = yaw_pose(x, y, 0.0, rng.uniform(*yaws))
            new = bodies(u, pose, parts)
            if fits(new, done, region, clearance):
                done += new
                out += records(u, pose)
                break
        else:
            raise GenerationError(f"no free place for {[m[0] for m in u.members]}")
    return out
