"""The 3D assembly domain: pillars, beam, arch, roof, cylinder, L-block and block built into
bridges, gates, towers and houses whose parts support and hide each other.

Two splits (docs/domains.md, "Splits"): the dev split draws the 20 goals of `GOALS` (five
main structures, a top, a second structure) from starts with at most two small parts
stacked; the test split draws the 20 goals of `TEST_GOALS`, built on main structures no dev
goal has (pillars standing on the arch, a part standing between the pillars, a four-part
tower, a five-deep support chain, a block under the arch, the L-block buttressing a
pillar), from starts of stacked clutter close together, one stack on the goal's site.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from domains import _layout
from domains._layout import Unit
from domains.assembly.dimensions import (
    ARCH_H,
    ARCH_W,
    BEAM,
    BLOCK,
    CYL_H,
    L_FOOT,
    PILLAR,
    ROOF_H,
    ROOF_W,
)
from domains.base import Domain
from domains.errors import GenerationError
from domains.generation import retry
from domains.registry import register
from geometry import TOLERANCES, Workspace, place, yaw_pose

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
    properties = {  # noqa: RUF012
        "perceive": [
            ("resting_pose", {"tolerance_deg": 5.0}),
            (
                "physically_valid",
                {
                    "penetration": TOLERANCES.perceived_penetration,
                    "contact": TOLERANCES.perceived_contact,
                },
            ),
        ],
        "relate": [
            (
                "relations_match_geometry",
                {"kind": "on", "meaning": "(upper part → part it rests on)"},
            ),
            ("support_acyclic", {"kind": "on"}),
        ],
        "plan": [
            ("turns_about_vertical", {}),
            ("supporters_first", {}),
            ("stable_with_loads", {}),
            ("temporary_clear_of_goals", {}),
        ],
    }
    composed_goals = (
        "structures built level by level from any parts (bridges on the table or on a long "
        "part, gates, houses, towers up to 270 mm), with a second structure or none, the parts "
        "packed 3–30 mm apart"
    )

    def make_goal(
        self, rng: np.random.Generator, index: int | None, split: str = "dev"
    ) -> list[dict]:
        if split == "test":
            return retry(lambda: self._goal(rng, index, split))
        return self._goal(rng, index, split)

    def _goal(self, rng: np.random.Generator, index: int | None, split: str) -> list[dict]:
        goals = TEST_GOALS if split == "test" else GOALS
        if index is None:
            main, top, second = goals[int(rng.integers(len(goals)))]
        else:
            main, top, second = goals[(index - 1) % len(goals)]
        members = _test_main(main, top) if split == "test" else _main(main, top)
        used = {i for i, _ in members}
        extra = _second(second) if second else []
        if any(i in used for i, _ in extra):
            raise GenerationError(f"goal ({main}, {top}, {second}) uses a part twice")
        units = [_unit(members)]
        if extra:
            units.append(_unit(extra))
            used |= {i for i, _ in extra}
        units += [_unit([(i, np.eye(4))]) for i in MESH if i not in used]
        if index == 1 and split == "dev":  # the reference: the main structure centred,
            # facing the front camera
            pose = yaw_pose(0.52, 0.0, 0.0, np.pi / 2)
            first = _layout.records(units[0], pose)
            placed = [place(r["id"], self.parts[r["mesh"]], r["pose"]) for r in first]
            return first + _layout.scatter(
                rng, units[1:], self.parts, self.placement, placed=placed, clearance=0.04
            )
        yaws = (np.pi / 2 - 0.5, np.pi / 2 + 0.5)
        return _layout.scatter(rng, units, self.parts, self.placement, clearance=0.04, yaws=yaws)

    def compose(self, seed: int) -> tuple[list[dict], list[dict]] | None:
        """A main structure of `task_structure` (bridges, gates, houses and towers built level by
        level from any parts the task text allows), a second structure or none, the other parts
        beside, packed closer than any catalogue goal: a gap drawn in `COMPOSED_GAP`, the units'
        origins in a `COMPOSED_AREA` box centred in the middle half of the placement region;
        started as dev starts are. Never built on one of the test split's main structures
        (`contains_test_structure`: those stay held out)."""
        rng = np.random.default_rng(seed)
        members = task_structure(rng)
        if members is None or contains_test_structure(members):
            return None
        used = {i for i, _ in members}
        units = [_unit(members)]
        extra = _composed_second(rng, [i for i in MESH if i not in used])
        if extra:
            units.append(_unit(extra))
            used |= {i for i, _ in extra}
        units += [_unit([(i, np.eye(4))]) for i in MESH if i not in used]
        gap = float(rng.uniform(*COMPOSED_GAP))
        (x0, x1), (y0, y1) = self.placement.x, self.placement.y
        cx = float(rng.uniform(x0 + (x1 - x0) / 4, x1 - (x1 - x0) / 4))
        cy = float(rng.uniform(y0 + (y1 - y0) / 4, y1 - (y1 - y0) / 4))
        w, h = COMPOSED_AREA
        area = Workspace(x=(cx - w / 2, cx + w / 2), y=(cy - h / 2, cy + h / 2), reach=1.0)
        try:
            goal = _layout.scatter(rng, units, self.parts, self.placement, clearance=gap, area=area)
            return self.make_start(rng, goal), goal
        except GenerationError:
            return None

    def make_start(
        self, rng: np.random.Generator, goal: Sequence[Mapping], split: str = "dev"
    ) -> list[dict]:
        if split == "test":
            return retry(lambda: self._test_start(rng, goal))
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

    def _test_start(self, rng: np.random.Generator, goal: Sequence[Mapping]) -> list[dict]:
        """Stacked clutter: a stack of three and one or two pairs (every part upright, in the
        goal's resting pose), the first stack standing where a goal part stands on the
        table, the units 15 mm apart (`retry` draws again when they do not fit)."""
        free = [str(i) for i in rng.permutation(list(MESH))]
        triple = TEST_STACKS[int(rng.integers(len(TEST_STACKS)))]
        units = [_stack(triple)]
        free = [i for i in free if i not in triple]
        for _ in range(int(rng.integers(1, 3))):
            pairs = [(b, t) for b, t in STACKS if b in free and t in free]
            if not pairs:
                break
            pair = pairs[int(rng.integers(len(pairs)))]
            units.append(_stack(pair))
            free = [i for i in free if i not in pair]
        units += [_unit([(i, np.eye(4))]) for i in free]
        # the first stack on the site of a goal part that stands on the table
        pose = {r["id"]: np.asarray(r["pose"], float) for r in goal}
        ground = sorted(i for i, T in pose.items() if T[2, 3] < 1e-6)
        site = pose[ground[int(rng.integers(len(ground)))]]
        x, y = site[:2, 3] + rng.uniform(-0.01, 0.01, 2)
        first = _layout.records(
            units[0], yaw_pose(float(x), float(y), 0.0, rng.uniform(-np.pi, np.pi))
        )
        placed = [place(r["id"], self.parts[r["mesh"]], r["pose"]) for r in first]
        if not all(self.placement.contains(b.xy()) for b in placed):
            raise GenerationError("the first start stack leaves the placement region")
        return first + _layout.scatter(
            rng,
            units[1:],
            self.parts,
            self.placement,
            placed=placed,
            clearance=TEST_START_CLEARANCE,
        )


# -- the test split -----------------------------------------------------------------------

BUTTRESS_GAP = 0.002  # between the L-block's leg and the pillar it buttresses [m] (clearly
# `adjacent`, 5 mm)
# pillar centres on the arch's top: over its legs, 1 mm in from its ends (at ±45 mm a
# pillar's inner face would lie exactly on a seam between the arch's convex parts) [m]
PILLARS_ON_ARCH = 0.044


def _test_main(kind: str, top: str | None) -> list[tuple[str, np.ndarray]]:
    """A test main structure (none of them is part of any dev goal)."""
    if kind == "tiered":  # the pillars standing on the arch, carrying the beam
        m = [
            ("arch", _at(0, 0)),
            ("pillar_1", _at(-PILLARS_ON_ARCH, ARCH_H)),
            ("pillar_2", _at(PILLARS_ON_ARCH, ARCH_H)),
            ("beam", _at(0, ARCH_H + PILLAR[2])),
        ]
        z = ARCH_H + PILLAR[2] + BEAM[2]
    elif kind in ("core", "bench"):  # a portal with the cylinder (block) between its pillars
        m = [*_main("portal", None), ("cylinder" if kind == "core" else "block", _at(0, 0))]
        z = PILLAR[2] + BEAM[2]
    elif kind == "tower":  # pillar, block, pillar, cylinder: 250 mm, four deep
        m = [
            ("pillar_1", _at(0, 0)),
            ("block", _at(0, PILLAR[2])),
            ("pillar_2", _at(0, PILLAR[2] + BLOCK[2])),
            ("cylinder", _at(0, 2 * PILLAR[2] + BLOCK[2])),
        ]
        z = 2 * PILLAR[2] + BLOCK[2] + CYL_H
    elif kind == "beacon":  # the portal carrying the cylinder, the block and the roof
        m = [
            *_main("portal", None),
            ("cylinder", _at(0, PILLAR[2] + BEAM[2])),
            ("block", _at(0, PILLAR[2] + BEAM[2] + CYL_H)),
            ("roof", _at(0, PILLAR[2] + BEAM[2] + CYL_H + BLOCK[2])),
        ]
        z = None
    elif kind == "shelter":  # the block under the arch, across it (11 mm from the opening's
        # sides), the beam across the arch
        m = [("block", _at(0, 0, np.pi / 2)), ("arch", _at(0, 0)), ("beam", _at(0, ARCH_H))]
        z = ARCH_H + BEAM[2]
    elif kind == "buttress":  # an arch bridge, the L-block's leg 2 mm beside pillar_2
        # (the arch ends flush with the pillar, 10 mm above the leg), the cylinder on its foot
        x = PILLARS_FOR_ARCH + PILLAR[0] / 2 + BUTTRESS_GAP + L_FOOT[0] / 2
        m = [
            *_main("arch_bridge", None),
            ("lblock", _at(x, 0)),
            ("cylinder", _at(x + 0.02, L_FOOT[1])),
        ]
        z = PILLAR[2] + ARCH_H
    else:
        raise ValueError(kind)
    if top is not None:
        if z is None:
            raise ValueError(f"{kind} takes no top")
        m.append((top, _at(0, z, np.pi / 2 if top == "block" else 0.0)))
    return m


# Test goals: (main, top, second), main one of `_test_main`'s kinds, second one of the dev
# seconds (`_second`) or None; the other parts stand beside. Test goal k is TEST_GOALS[k - 1].
TEST_GOALS: tuple[tuple[str, str | None, str | None], ...] = (
    ("tiered", "roof", "step"),
    ("core", "roof", "step_block"),
    ("tower", None, None),
    ("beacon", None, None),
    ("shelter", "roof", "step"),
    ("buttress", "roof", None),
    ("tiered", "block", "step"),
    ("bench", "roof", "step"),
    ("tower", None, None),
    ("beacon", None, None),
    ("shelter", "cylinder", None),
    ("buttress", "block", None),
    ("tiered", None, "post"),
    ("core", "block", None),
    ("tiered", "cylinder", "step_block"),
    ("bench", "cylinder", None),
    ("shelter", None, "step"),
    ("buttress", None, None),
    ("tiered", "roof", "lamp"),
    ("core", None, "step_block"),
)
# Test starts: stacks of three (bottom to top) besides the dev split's pairs (`STACKS`).
TEST_STACKS = (
    ("beam", "block", "cylinder"),
    ("arch", "block", "cylinder"),
    ("lblock", "block", "cylinder"),
    ("beam", "arch", "cylinder"),
)
TEST_START_CLEARANCE = 0.015  # between start units in the test split [m] (dev: 0.03)


# -- composed goals: any structure the task text allows ------------------------------------

COMPOSED_GAP = (0.003, 0.03)  # between the composed goal's units [m]
COMPOSED_AREA = (0.2, 0.3)  # the box (along x, y) the units' origins are drawn in [m]
COMPOSED_HEIGHT = 0.27  # the tallest composed structure [m] (the arm reaches over it)
# what may stand centred on a flat top: a part whose footprint the top carries wherever it
# is centred (pillar, block, cylinder, roof), or a long part across a long top (the beam on
# the arch or a block along it, the arch on the beam: its legs need the beam's length)
ON_LONG_TOP = {"beam": ("arch", "block"), "arch": ("beam",)}
UNDER_SPAN = ("cylinder", "block")  # what may stand between two pillars, under their span


def task_structure(rng: np.random.Generator) -> list[tuple[str, np.ndarray]] | None:
    """Members (id, T_structure_part) of a structure the task text allows, built level by
    level: a base — two pillars carrying the beam or the arch (a bridge), standing on the
    table or on the other long part, maybe with a small part between them; or one part on the
    table, the arch maybe over a block across its opening (a gate) — then up to three parts,
    each centred on the flat top below (a tower; the roof ends it: a house), no taller than
    `COMPOSED_HEIGHT`; None when the draw runs out of parts or height. The dev catalogue's
    main structures are among them; the property tests and the checks draw goals from it."""
    free = list(MESH)
    members: list[tuple[str, np.ndarray]] = []

    def take(i: str, x: float, z: float, yaw: float = 0.0) -> None:
        free.remove(i)
        members.append((i, _at(x, z, yaw)))

    if rng.random() < 0.5:  # a bridge
        span = "beam" if rng.random() < 0.5 else "arch"
        d = PILLARS_FOR_BEAM if span == "beam" else PILLARS_FOR_ARCH
        z = 0.0
        if rng.random() < 1 / 3:  # on a plinth: the other long part
            plinth = "arch" if span == "beam" else "beam"
            take(plinth, 0.0, 0.0)
            z = _top(plinth)
            d = min(d, PILLARS_ON_ARCH) if plinth == "arch" else d
        take("pillar_1", -d, z)
        take("pillar_2", d, z)
        if rng.random() < 1 / 3:
            under = str(rng.choice(UNDER_SPAN))
            take(under, 0.0, z, np.pi / 2 if under == "block" else 0.0)
        take(span, 0.0, z + PILLAR[2])
        z, top = z + PILLAR[2] + _top(span), span
    else:  # one part on the table
        base = str(rng.choice(["arch", "beam", "pillar_1", "block", "cylinder"]))
        if base == "arch" and rng.random() < 1 / 3:  # a block across the opening, under it
            take("block", 0.0, 0.0, np.pi / 2)
        take(base, 0.0, 0.0)
        z, top = _top(base), base
    for _ in range(int(rng.integers(0, 4))):
        fits = [
            i
            for i in free
            if MESH[i] in ("pillar", "block", "cylinder", "roof")
            or MESH[top] in ON_LONG_TOP.get(MESH[i], ())
        ]
        if not fits:
            break
        i = fits[int(rng.integers(len(fits)))]
        high = ROOF_H if MESH[i] == "roof" else _top(i)
        if z + high > COMPOSED_HEIGHT:
            break
        turned = MESH[i] == "block" and (MESH[top] not in ("beam", "arch") or rng.random() < 0.5)
        take(i, 0.0, z, np.pi / 2 if turned else 0.0)
        if MESH[i] == "roof":
            break
        z, top = z + high, i
    return members if len(members) > 1 else None


def _composed_second(rng: np.random.Generator, free: Sequence[str]) -> list:
    """A second, smaller structure of the parts left (one of the dev seconds, or a small part
    on a flat top as starts stack them), or none."""
    seconds = [_second(k) for k in ("step", "step_block", "column", "post", "lamp")]
    options = [m for m in seconds if all(i in free for i, _ in m)]
    options += [_stack_members(pair) for pair in STACKS if all(i in free for i in pair)]
    if not options or rng.random() < 0.25:
        return []
    return options[int(rng.integers(len(options)))]


def _extent(i: str, T: np.ndarray) -> tuple[float, float, float, float]:
    """(x0, x1, z0, z1) of a structure member standing along the structure's x axis (turned
    0 or 90°); z1 is its flat top where parts rest (the L-block's foot)."""
    length, depth = {
        "pillar": PILLAR[:2],
        "beam": BEAM[:2],
        "arch": (ARCH_W, BEAM[1]),
        "roof": (ROOF_W, BEAM[1]),
        "cylinder": (0.04, 0.04),
        "lblock": (L_FOOT[0], BEAM[1]),
        "block": BLOCK[:2],
    }[MESH[i]]
    along = depth if abs(T[1, 0]) > 0.7 else length
    high = {"roof": ROOF_H, "lblock": L_FOOT[1]}.get(MESH[i]) or _top(i)
    x, z = float(T[0, 3]), float(T[2, 3])
    return x - along / 2, x + along / 2, z, z + high


def structure_key(members: Sequence[tuple[str, np.ndarray]]) -> Counter:
    """The labelled relations of a structure's members (along its x axis): ("on", upper mesh,
    lower mesh) for a part resting on another, ("over", …) for one above another it does not
    rest on, ("in", …) for one standing within another's length and height (a block in the
    arch's opening). One structure contains another when its key does (a multiset)."""
    key: Counter = Counter()
    ext = {i: _extent(i, T) for i, T in members}
    for a, (ax0, ax1, az0, az1) in ext.items():
        for b, (bx0, bx1, bz0, bz1) in ext.items():
            if a == b or min(ax1, bx1) - max(ax0, bx0) < 1e-3:
                continue
            if abs(az0 - bz1) < 1e-3:
                key["on", MESH[a], MESH[b]] += 1
            elif az0 > bz1:
                key["over", MESH[a], MESH[b]] += 1
            elif bx0 <= ax0 and ax1 <= bx1 and bz0 <= az0 and az1 < bz1 and MESH[b] == "arch":
                key["in", MESH[a], MESH[b]] += 1
    return key


def contains_test_structure(members: Sequence[tuple[str, np.ndarray]]) -> bool:
    """Whether a structure contains one of the test split's main structures (its
    `structure_key` holds the test structure's, without its top)."""
    key = structure_key(members)
    return any(
        not (structure_key(_test_main(kind, None)) - key) for kind in {g[0] for g in TEST_GOALS}
    )


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


def _stack(ids: Sequence[str]) -> Unit:
    """Parts stacked bottom to top, each centred on the flat top below (on the L-block's
    foot, the block across it as in `step_block`)."""
    return _unit(_stack_members(ids))


def _stack_members(ids: Sequence[str]) -> list[tuple[str, np.ndarray]]:
    members, z, x = [], 0.0, 0.0
    for k, i in enumerate(ids):
        below = ids[k - 1] if k else None
        if below is not None and MESH[below] == "lblock":
            x, z = 0.0175, L_FOOT[1]
        elif below is not None:
            z += _top(below)
        yaw = np.pi / 2 if (MESH[i], below and MESH[below]) == ("block", "lblock") else 0.0
        members.append((i, _at(x, z, yaw)))
    return members


def _unit(members: Sequence[tuple[str, np.ndarray]]) -> Unit:
    return _layout.unit(*((i, MESH[i], pose) for i, pose in members))
