"""The 3D assembly domain: pillars, beam, arch, roof, cylinder, L-block and block built into
bridges, gates, towers and houses whose parts support and hide each other."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from domains import _layout
from domains._layout import Unit
from domains.assembly.dimensions import ARCH_H, BEAM, BLOCK, CYL_H, L_FOOT, PILLAR
from domains.base import Domain
from domains.errors import GenerationError
from domains.registry import register
from geometry import place, yaw_pose

MESH = {
    "pillar_1": "pillar",
    "pillar_2": "pillar",
    "beam": "beam",
    "arch": "arch",
    "roof": "roof",
    "cylinder": "cylinder",
    "lblock": "lblock",
    "block": "block",
}
PILLARS_FOR_BEAM = 0.055  # pillar centres at ±this under the beam [m]
PILLARS_FOR_ARCH = 0.045  # under the arch's legs [m]


def _at(x: float, z: float, yaw: float = 0.0) -> np.ndarray:
    return yaw_pose(x, 0.0, z, yaw)


def _top(part: str) -> float:
    """Height of a part's flat top in its upright pose [m] (the roof has none)."""
    return {
        "pillar": PILLAR[2],
        "beam": BEAM[2],
        "arch": ARCH_H,
        "block": BLOCK[2],
        "cylinder": CYL_H,
    }[MESH[part]]


# Structures: (name, parts used, members as (id, T_structure_part)). The main structure
# uses the pillars, beam or arch; a second, smaller one may stand beside it.
def _main(kind: str, top: str | None) -> list[tuple[str, np.ndarray]]:
    if kind == "portal":  # two pillars and a beam
        m = [
            ("pillar_1", _at(-PILLARS_FOR_BEAM, 0)),
            ("pillar_2", _at(PILLARS_FOR_BEAM, 0)),
            ("beam", _at(0, PILLAR[2])),
        ]
        z = PILLAR[2] + BEAM[2]
    elif kind == "arch_bridge":  # two pillars and the arch
        m = [
            ("pillar_1", _at(-PILLARS_FOR_ARCH, 0)),
            ("pillar_2", _at(PILLARS_FOR_ARCH, 0)),
            ("arch", _at(0, PILLAR[2])),
        ]
        z = PILLAR[2] + ARCH_H
    elif kind == "double":  # portal with the arch on the beam
        m = [*_main("portal", None), ("arch", _at(0, PILLAR[2] + BEAM[2]))]
        z = PILLAR[2] + BEAM[2] + ARCH_H
    elif kind == "gate":  # the arch alone
        m = [("arch", _at(0, 0))]
        z = ARCH_H
    elif kind == "gate_beam":  # the arch with the beam across it
        m = [("arch", _at(0, 0)), ("beam", _at(0, ARCH_H))]
        z = ARCH_H + BEAM[2]
    else:
        raise ValueError(kind)
    if top == "roof":
        m.append(("roof", _at(0, z)))
    elif top in ("cylinder", "block"):
        m.append((top, _at(0, z, np.pi / 2 if top == "block" else 0.0)))
    return m


def _second(kind: str) -> list[tuple[str, np.ndarray]]:
    if kind == "step":  # the cylinder on the L-block's foot, 10 mm from its leg
        return [("lblock", _at(0, 0)), ("cylinder", _at(0.02, L_FOOT[1]))]
    if kind == "step_block":  # the block across the foot
        return [("lblock", _at(0, 0)), ("block", _at(0.0175, L_FOOT[1], np.pi / 2))]
    if kind == "column":  # a pillar carrying the block
        return [("pillar_2", _at(0, 0)), ("block", _at(0, PILLAR[2]))]
    if kind == "post":  # the block carrying the cylinder
        return [("block", _at(0, 0)), ("cylinder", _at(0, BLOCK[2]))]
    if kind == "lamp":  # the cylinder carrying the block
        return [("cylinder", _at(0, 0)), ("block", _at(0, CYL_H))]
    raise ValueError(kind)


# Benchmark goals: (main, top, second); goal 1 is the authoring reference.
GOALS: tuple[tuple[str, str | None, str | None], ...] = (
    ("double", "roof", "step"),
    ("arch_bridge", "roof", "post"),
    ("portal", "roof", "step_block"),
    ("gate_beam", "roof", "step"),
    ("portal", "cylinder", "step_block"),
    ("arch_bridge", "block", "step"),
    ("gate", "roof", "lamp"),
    ("double", "cylinder", None),
    ("portal", "block", None),
    ("arch_bridge", "cylinder", "step_block"),
    ("gate_beam", "cylinder", None),
    ("gate", "block", "step"),
    ("portal", None, "post"),
    ("double", None, "post"),
    ("arch_bridge", None, "lamp"),
    ("gate_beam", "block", None),
    ("gate", "cylinder", "step_block"),
    ("double", "block", None),
    ("portal", "roof", "lamp"),
    ("gate_beam", None, "step"),
)


@register("assembly")
class Assembly(Domain):
    name = "assembly"
    root = Path(__file__).parent
    REFERENCE_RELATIONS = {  # noqa: RUF012
        "on": "the source part rests on (is supported by) the target part",
        "adjacent": "the two parts touch side by side (at most 5 mm apart)",
    }
    on_gap = 0.008
    adjacent_gap = 0.005

    def make_goal(self, rng: np.random.Generator, index: int | None) -> list[dict]:
        if index is None:
            main, top, second = GOALS[int(rng.integers(len(GOALS)))]
        else:
            main, top, second = GOALS[(index - 1) % len(GOALS)]
        members = _main(main, top)
        used = {i for i, _ in members}
        extra = _second(second) if second else []
        if any(i in used for i, _ in extra):
            raise GenerationError(f"goal ({main}, {top}, {second}) uses a part twice")
        units = [_unit(members)]
        if extra:
            units.append(_unit(extra))
            used |= {i for i, _ in extra}
        units += [_unit([(i, np.eye(4))]) for i in MESH if i not in used]
        if index == 1:  # the reference: the main structure centred, facing the front camera
            pose = yaw_pose(0.52, 0.0, 0.0, np.pi / 2)
            first = _layout.records(units[0], pose)
            placed = [place(r["id"], self.parts[r["mesh"]], r["pose"]) for r in first]
            return first + _layout.scatter(
                rng, units[1:], self.parts, self.placement, placed=placed, clearance=0.04
            )
        yaws = (np.pi / 2 - 0.5, np.pi / 2 + 0.5)
        return _layout.scatter(rng, units, self.parts, self.placement, clearance=0.04, yaws=yaws)

    def make_start(self, rng: np.random.Generator, goal: Sequence[Mapping]) -> list[dict]:
        # every part starts upright, as the goal uses it; some start stacked on others
        free = [str(i) for i in rng.permutation(list(MESH))]
        units: list[Unit] = []
        for _ in range(int(rng.choice([0, 1, 2], p=[0.35, 0.4, 0.25]))):
            pairs = [(b, t) for b, t in STACKS if b in free and t in free]
            if not pairs:
                break
            base, top = pairs[int(rng.integers(len(pairs)))]
            yaw = np.pi / 2 if (MESH[top], MESH[base]) == ("block", "lblock") else 0.0
            x = 0.0175 if MESH[base] == "lblock" else 0.0
            units.append(
                _unit(
                    [
                        (base, np.eye(4)),
                        (top, _at(x, _top(base) if MESH[base] != "lblock" else L_FOOT[1], yaw)),
                    ]
                )
            )
            free = [i for i in free if i not in (base, top)]
        units += [_unit([(i, np.eye(4))]) for i in free]
        return _layout.scatter(rng, units, self.parts, self.placement, clearance=0.03)


# Start stacks (base, top): small parts left on a flat top.
STACKS = (
    ("beam", "block"),
    ("beam", "cylinder"),
    ("beam", "roof"),
    ("arch", "block"),
    ("arch", "cylinder"),
    ("block", "cylinder"),
    ("lblock", "block"),
    ("lblock", "cylinder"),
    ("pillar_1", "block"),
)


def _unit(members: Sequence[tuple[str, np.ndarray]]) -> Unit:
    return _layout.unit(*((i, MESH[i], pose) for i, pose in members))
