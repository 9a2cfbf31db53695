"""The cases a suite checks a draft on, built on the host from the domain and the simulator.

Design rule: inputs come from the domain's seeded instance generator, never only from the
reference instance, and every case keeps its ground truth beside the arguments the draft will
get: the true records of an observation, the simulator's image of a scene, the reference
relations of a state. Only the arguments ever reach the draft. Everything is seeded and
cached, so the same draft gets the same cases.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from functools import lru_cache
from typing import Any

import numpy as np

import domains
from checks.budget import Budget
from contracts.errors import UsageError
from contracts.functions import FUNCTIONS
from domains import Domain

HALF_RES = 2  # image checks render at 1/2 of the domain cameras' resolution
# `perceive` is checked on observations as the trials make them (`sim.realism`'s default level:
# sensor noise, exposure, white balance, light, the stereo depth model), but seen through the
# true camera: the calibration error is an offset of the whole scene that no program can see,
# which the trials measure and the checks do not hold against a draft
CHECK_REALISM = "default, true camera"
PROPERTY_RES = 4  # render's property checks at 1/4


@lru_cache(maxsize=256)
def _instance(domain_name: str, seed: int) -> domains.Instance | None:
    try:
        return domains.load(domain_name).generate(seed)
    except domains.GenerationError:
        return None


def instances(domain: Domain, seeds: tuple[int, ...]) -> list[domains.Instance]:
    """Generated instances for `seeds` (a seed the generator cannot serve is replaced by the
    next unused one, deterministically)."""
    out, used, extra = [], set(seeds), max(seeds, default=0) + 1000
    for s in seeds:
        inst = _instance(domain.name, s)
        while inst is None:
            while extra in used:
                extra += 1
            used.add(extra)
            inst = _instance(domain.name, extra)
        out.append(inst)
    return out


@lru_cache(maxsize=256)
def _composed(domain_name: str, seed: int) -> domains.Instance | None:
    return domains.load(domain_name).composed_instance(seed)


def composed(domain: Domain, seeds: tuple[int, ...], n: int) -> list[domains.Instance]:
    """The first `n` composed instances of `seeds` that have an order the robot can execute
    (none when the domain has no composer)."""
    out: list[domains.Instance] = []
    if domain.composed_goals is None:
        return out
    for s in seeds:
        if len(out) >= n:
            break
        inst = _composed(domain.name, s)
        if inst is not None:
            out.append(inst)
    return out


def records(scene: Mapping) -> list[dict]:
    return [
        {"id": o["id"], "mesh": o["mesh"], "pose": np.asarray(o["pose"], float)}
        for o in scene["objects"]
    ]


def camera(domain: Domain, name: str, scale: int = 1) -> dict:
    """Camera `name` of the domain at 1/`scale` of its resolution (same view, centred)."""
    spec = domain.cameras[name]
    small = dataclasses.replace(spec, width=spec.width // scale, height=spec.height // scale)
    return small.to_camera()


@lru_cache(maxsize=64)
def _observation(domain_name: str, seed: int, side: str, cam: str, scale: int) -> dict[str, Any]:
    """The simulator's clean view (rgb, depth, mask) of an instance's scene."""
    from sim.observation import observe

    domain = domains.load(domain_name)
    inst = _instance(domain_name, seed)
    assert inst is not None
    scene = inst.start if side == "start" else inst.goal
    return observe(domain, scene, camera(domain, cam, scale), noise=None, mask=True)


@lru_cache(maxsize=64)
def _realistic(domain_name: str, seed: int, side: str, cam: str) -> dict[str, Any]:
    """The observation `perceive` is checked on (`CHECK_REALISM`), seeded by the instance."""
    from sim.observation import observe

    domain = domains.load(domain_name)
    inst = _instance(domain_name, seed)
    assert inst is not None
    scene = inst.start if side == "start" else inst.goal
    return observe(
        domain, scene, camera(domain, cam, 1), seed=seed * 2 + (side == "goal"), realism=_level()
    )


def _level():
    """`CHECK_REALISM`: the default realism level seen through the true camera."""
    from sim.realism import DEFAULT

    return dataclasses.replace(
        DEFAULT, name=CHECK_REALISM, calib_translation=0.0, calib_rotation=0.0
    )


@lru_cache(maxsize=16)
def _hidden(domain_name: str, seed: int) -> tuple[list[dict], str] | None:
    """(records, id) of `Domain.hidden_scene(seed)` when the scene is valid and its object
    shows no pixel to the front camera at full resolution; None otherwise."""
    from sim.settle import check_scene
    from toolbox import render_scene

    domain = domains.load(domain_name)
    drawn = domain.hidden_scene(seed)
    if drawn is None:
        return None
    recs, behind = records(domain.scene(drawn[0])), drawn[1]
    k = [r["id"] for r in recs].index(behind)
    small = render_scene(recs, domain.meshes(), camera(domain, "front", HALF_RES))["mask"]
    if (small == k).any():  # a cheap first look
        return None
    if (render_scene(recs, domain.meshes(), camera(domain, "front", 1))["mask"] == k).any():
        return None
    if check_scene(domain, domain.scene(drawn[0])):
        return None
    return recs, behind


def hidden_views(domain: Domain, seeds: tuple[int, ...], n: int) -> list[tuple[int, list, str]]:
    """(seed, records, hidden id) of the first `n` of `seeds` whose `Domain.hidden_scene` hides
    its object entirely from the front camera."""
    out: list[tuple[int, list, str]] = []
    for s in seeds:
        if len(out) >= n:
            break
        got = _hidden(domain.name, s)
        if got is not None:
            out.append((s, *got))
    return out


@lru_cache(maxsize=16)
def _hidden_observation(domain_name: str, seed: int) -> tuple[dict[str, Any], dict[str, Any]]:
    """(clean view with mask, observation as `_realistic` makes them) of a hidden scene."""
    from sim.observation import observe

    domain = domains.load(domain_name)
    got = _hidden(domain_name, seed)
    assert got is not None
    scene = domain.scene(got[0])
    cam = camera(domain, "front", 1)
    clean = observe(domain, scene, cam, noise=None, mask=True)
    return clean, observe(domain, scene, cam, seed=seed, realism=_level())


def _subsample(view: Mapping[str, Any], scale: int) -> dict[str, Any]:
    """Every `scale`-th pixel of a view: the view of the camera at 1/`scale` resolution, to a
    fraction of a pixel."""
    return {k: np.ascontiguousarray(view[k][::scale, ::scale]) for k in ("rgb", "depth", "mask")}


def build_cases(domain: Domain, function: str, budget: Budget) -> dict[str, Any]:
    """The cases of `function`'s suite.

    - render: ``scenes``: {name, records, camera, image (compared with the simulator),
      reference (the simulator's rgb/depth/mask, for image cases)};
    - perceive: ``observations``: {name, observation (rgb, noisy depth, camera), camera,
      render_camera, truth (true records), reference (the simulator's clean view at the
      render camera's resolution and the full-size observation)};
    - relate: ``scenes``: {name, records, reference (relations)};
    - plan: ``instances``: {name, start, goal, start_relations, goal_relations, order_len}
      (the generator's, then the domain's composed ones), ``infeasible``: goals no plan
      reaches, with why.
    """
    pool = instances(domain, budget.instance_seeds)
    cases: dict[str, Any] = {}

    def scene_of(i: int, side: str) -> list[dict]:
        return records(pool[i].start if side == "start" else pool[i].goal)

    if function == "relate":
        cases["scenes"] = [
            {
                "name": f"{inst.name}/{side}",
                "records": scene_of(i, side),
                "reference": domain.reference_relations(scene_of(i, side)),
            }
            for i, inst in enumerate(pool)
            for side in ("start", "goal")
        ]
    elif function == "plan":
        pool = [*pool, *composed(domain, budget.composed_seeds, budget.composed)]
        cases["instances"] = [
            {
                "name": inst.name,
                "start": scene_of(i, "start"),
                "goal": scene_of(i, "goal"),
                "start_relations": domain.reference_relations(scene_of(i, "start")),
                "goal_relations": domain.reference_relations(scene_of(i, "goal")),
                "order_len": len(inst.order),
            }
            for i, inst in enumerate(pool)
        ]
        cases["infeasible"] = infeasible_cases(domain, pool[0])
    elif function == "render":
        scenes = []
        for k, (i, side, cam) in enumerate(budget.render_cases):
            i = i % len(pool)
            recs = scene_of(i, side)
            name = f"{pool[i].name}/{side}/{cam}"
            scenes.append(
                {
                    "name": name,
                    "records": recs,
                    "camera": camera(domain, cam, HALF_RES),
                    "camera_name": cam,
                    "image": True,
                    "reference": _observation(domain.name, pool[i].seed, side, cam, HALF_RES),
                }
            )
            if k == 0:  # a small view for the cheap properties
                scenes.insert(
                    0,
                    {
                        "name": f"{name}@1/{PROPERTY_RES}",
                        "records": recs,
                        "camera": camera(domain, cam, PROPERTY_RES),
                        "camera_name": cam,
                    },
                )
        cases["scenes"] = scenes
    elif function == "perceive":
        obs = []
        chosen = [(i % len(pool), side, cam) for i, side, cam in budget.observations]
        search = instances(domain, budget.hard_seeds)
        for i, side, cam in _hardest(domain.name, budget.hard_seeds, budget.hard_observations):
            if (search[i].seed, side, cam) not in {(pool[j].seed, s_, c) for j, s_, c in chosen}:
                pool = [*pool, search[i]]
                chosen.append((len(pool) - 1, side, cam))
        for i, side, cam in chosen:
            i = i % len(pool)
            recs = scene_of(i, side)
            clean = _observation(domain.name, pool[i].seed, side, cam, 1)
            full = _realistic(domain.name, pool[i].seed or 0, side, cam)
            obs.append(
                {
                    "name": f"{pool[i].name}/{side}/{cam}",
                    "observation": {
                        "rgb": full["rgb"],
                        "depth": full["depth"],
                        "camera": full["camera"],
                    },
                    "camera": full["camera"],
                    "camera_name": cam,
                    "render_camera": camera(domain, cam, HALF_RES),
                    "truth": recs,
                    "reference": {**_subsample(clean, HALF_RES), "full": full},
                }
            )
        for seed, recs, behind in hidden_views(domain, budget.hidden_seeds, budget.hidden):
            clean, full = _hidden_observation(domain.name, seed)
            obs.append(
                {
                    "name": f"hidden/seed{seed}/front",
                    "observation": {
                        "rgb": full["rgb"],
                        "depth": full["depth"],
                        "camera": full["camera"],
                    },
                    "camera": full["camera"],
                    "camera_name": "front",
                    "render_camera": camera(domain, "front", HALF_RES),
                    "truth": recs,
                    # shown nowhere and holding nothing up: it must be reported, but where it
                    # stands the image cannot say
                    "unscored": [behind],
                    "reference": {**_subsample(clean, HALF_RES), "full": full},
                }
            )
        cases["observations"] = obs
    else:
        raise UsageError(f"unknown function '{function}'; known: {', '.join(FUNCTIONS)}")
    return cases


@lru_cache(maxsize=16)
def _hardest(domain_name: str, seeds: tuple[int, ...], n: int) -> list[tuple[int, str, str]]:
    domain = domains.load(domain_name)
    return hardest_views(domain, instances(domain, seeds), n, exclude=[])


def hardest_views(
    domain: Domain, pool: list, n: int, *, exclude: list[tuple[int, str, str]]
) -> list[tuple[int, str, str]]:
    """The `n` (instance, side, camera) views whose least visible object shows the fewest
    pixels: the views perception finds hardest, so that the checks see occlusion whenever the
    generator produces it. A view hiding an object entirely counts only when the object can be
    inferred — it holds up another object — since nothing could find it otherwise."""
    if n <= 0:
        return []
    from toolbox import render_scene

    meshes = domain.meshes()
    scored = []
    for i, inst in enumerate(pool):
        for side in ("start", "goal"):
            recs = records(inst.start if side == "start" else inst.goal)
            graph = domain.reference_relations(recs)
            supporters = {e["target"] for e in graph["edges"] if e["type"] == "on"}
            for cam in domain.cameras:
                if (i, side, cam) in exclude:
                    continue
                mask = render_scene(recs, meshes, camera(domain, cam, HALF_RES))["mask"]
                areas = np.bincount(mask[mask >= 0].ravel(), minlength=len(recs))
                hidden = [r["id"] for r, a in zip(recs, areas, strict=True) if a == 0]
                if any(h not in supporters for h in hidden):
                    continue
                scored.append((int(areas.min()), i, side, cam))
    scored.sort(key=lambda t: (t[0], t[1], t[2], t[3]))
    return [(i, side, cam) for _, i, side, cam in scored[:n]]


def infeasible_cases(domain: Domain, inst: domains.Instance) -> list[dict[str, Any]]:
    """Goals no plan can reach, made from an instance: a floating object, two objects in one
    place."""
    start = records(inst.start)
    goal = records(inst.goal)
    floating = [dict(r, pose=r["pose"].copy()) for r in goal]
    low = min(range(len(floating)), key=lambda k: floating[k]["pose"][2, 3])
    floating[low]["pose"][2, 3] += 0.10
    overlap = [dict(r, pose=r["pose"].copy()) for r in goal]
    overlap[1]["pose"] = overlap[0]["pose"].copy()
    out = []
    for name, g, why in (
        ("floating", floating, f"'{floating[low]['id']}' floats 100 mm above its support"),
        ("overlap", overlap, f"'{overlap[1]['id']}' and '{overlap[0]['id']}' share one place"),
    ):
        out.append(
            {
                "name": f"{inst.name}/{name}",
                "start": start,
                "goal": g,
                "start_relations": domain.reference_relations(start),
                "goal_relations": domain.reference_relations(g),
                "why": why,
            }
        )
    return out
