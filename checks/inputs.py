"""The cases a suite checks a draft on, drawn on the host from the task's whole space.

Design rule: every case is *drawn* from a case seed (`build_cases(..., seed=S)`), fresh for
each check run — each attempt of an authoring run gets its own (`case_seed`), recorded in the
journal and the transcript so that a replay draws the same cases — so no draft can be tuned
to a fixed case list, and nothing one attempt's feedback shows about its cases is of use on
the next. Cases come from what the task text allows, not from the benchmark catalogue:
instances of the domain's generator at fresh seeds, goals composed from the task's parts
(`Domain.compose`), the task text's hiding case (`Domain.hidden_scene`), and — for `perceive` —
cameras drawn from the domain's camera envelope (`Domain.camera_envelope`) as well as its named
views, seen with the trials' realism and *calibrated* camera at full resolution, exactly as the
runtime calls `perceive`. Every case keeps its ground truth beside the arguments the draft
will get (the true records of an observation, the simulator's image of a scene, the reference
relations of a state); only the arguments ever reach the draft.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Mapping
from functools import lru_cache
from typing import Any

import numpy as np

import domains
from checks.budget import Budget
from checks.robot import robot_view
from contracts.errors import UsageError
from contracts.functions import FUNCTIONS
from domains import Domain
from domains.cameras import CameraEnvelope, resized

HALF_RES = 2  # image checks render at 1/2 of the observation's resolution …
IMAGE_PIXEL_MAX = 0.0016  # [m] … or finer, so that a pixel covers at most this at the scene
# (the named views at half resolution: 1.35-1.6 mm): IoU on objects a few pixels wide would
# judge the pixel grid, not the pose
IMAGE_SIZE_MAX = (1920, 1080)  # [px] the simulator's offscreen buffer
# `perceive` is checked on observations exactly as the trials make them: `sim.realism`'s
# default level (sensor noise, exposure, white balance, light, the stereo depth model) and
# the calibrated camera (the true camera with the trials' calibration error)
CHECK_REALISM = "default"
PROPERTY_RES = 4  # render's property checks at 1/4
SEED_SPACE = 2**31  # drawn generator and composer seeds are in [FRESH_FROM, SEED_SPACE)
FRESH_FROM = 10**6  # above every benchmark split's seeds
NAMED_VIEW_SHARE = 0.25  # of perceive's observations use a named view, the rest the envelope
COMPOSED_SHARE = 1 / 3  # of perceive's and relate's scenes are composed, where a composer is


def case_seed(run_seed: int, function: str, attempt: int) -> int:
    """The case seed of one attempt of an authoring run (a fresh draw per attempt)."""
    h = hashlib.sha256(f"{run_seed}:{function}:{attempt}".encode()).digest()
    return int.from_bytes(h[:8], "big") >> 1


def fresh_seed() -> int:
    """A case seed nobody chose (`rivet check` without `--seed`, a new authoring run)."""
    import secrets

    return secrets.randbits(62)


def _rng(seed: int, *key: str) -> np.random.Generator:
    return np.random.default_rng(
        [seed, *(int.from_bytes(hashlib.sha256(k.encode()).digest()[:4], "big") for k in key)]
    )


@lru_cache(maxsize=512)
def _instance(domain_name: str, seed: int, ordered: bool = True) -> domains.Instance | None:
    """The generator's instance at `seed` with an order the robot can execute (every step has
    a 2F-85 grasp): `plan`'s hand-aware checks hold a plan to that. `ordered=False`: its
    start and goal only (no order is searched: most of a draw's time)."""
    try:
        return domains.load(domain_name).generate(seed, grasps=True, ordered=ordered)
    except domains.GenerationError:
        return None


def instances(
    domain: Domain,
    rng: np.random.Generator,
    n: int,
    *,
    executable: bool = False,
    scenes_only: bool = False,
) -> list[domains.Instance]:
    """`n` instances of the domain's generator at seeds drawn from `rng` (a seed the
    generator cannot serve is replaced by another draw). `executable`: also replace an
    instance whose reference order the arm cannot carry out (`_executable`); `scenes_only`:
    their start and goal scenes, with no order (what `perceive` is shown)."""
    out: list[domains.Instance] = []
    for _ in range(50 * max(n, 1)):
        if len(out) >= n:
            break
        seed = int(rng.integers(FRESH_FROM, SEED_SPACE))
        inst = _instance(domain.name, seed, ordered=not scenes_only)
        if inst is not None and (not executable or _executable(domain.name, inst)):
            out.append(inst)
    return out


def _executable(domain_name: str, inst: domains.Instance) -> bool:
    """Whether the robot the plan checks hold a plan to (`checks.robot.robot_view`: the
    hand's grasps and the arm's reach) can carry out the instance's reference order. The
    generator asks only for a grasp of the hand; a case whose every plan the checks would
    refuse is no test of a draft."""
    return robot_view(domain_name).first_problem(records(inst.start), list(inst.order)).step is None


@lru_cache(maxsize=256)
def _composed(domain_name: str, seed: int, ordered: bool = True) -> domains.Instance | None:
    return domains.load(domain_name).composed_instance(seed, ordered=ordered)


def composed(
    domain: Domain,
    rng: np.random.Generator,
    n: int,
    *,
    executable: bool = False,
    scenes_only: bool = False,
) -> list[domains.Instance]:
    """`n` composed instances (goals built from the task's parts, `Domain.composed_instance`)
    with an order the hand can execute (and the arm too, when `executable`), at seeds drawn
    from `rng` (none when the domain has no composer); `scenes_only`: their two scenes, with
    no order."""
    out: list[domains.Instance] = []
    if domain.composed_goals is None:
        return out
    for _ in range(20 * max(n, 1)):
        if len(out) >= n:
            break
        seed = int(rng.integers(FRESH_FROM, SEED_SPACE))
        inst = _composed(domain.name, seed, ordered=not scenes_only)
        if inst is not None and (not executable or _executable(domain.name, inst)):
            out.append(inst)
    return out


def composed_scene(domain: Domain, rng: np.random.Generator) -> tuple[str, list[dict]] | None:
    """(side, records) of one side of a composed draw (`Domain.compose`; no order needed);
    None when the domain has no composer or no draw gives a scene."""
    if domain.composed_goals is None:
        return None
    for _ in range(20):
        drawn = domain.compose(int(rng.integers(FRESH_FROM, SEED_SPACE)))
        if drawn is not None:
            side = "start" if rng.random() < 0.5 else "goal"
            return side, [dict(r) for r in drawn[0 if side == "start" else 1]]
    return None


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


def _observation(domain: Domain, recs: list[dict], cam: dict) -> dict[str, Any]:
    """The simulator's clean view (rgb, depth, mask) of a scene from camera `cam`."""
    from sim.observation import observe

    return observe(domain, domain.scene(recs), cam, noise=None, mask=True)


def _realistic(
    domain: Domain, recs: list[dict], cam: dict, seed: int
) -> tuple[dict[str, Any], dict[str, Any]]:
    """(what `perceive` gets of a scene seen by the true camera `cam` — `CHECK_REALISM`: the
    trials' default realism, the calibrated camera — with the true camera's mask, the clean
    render's rgb and depth) from one render."""
    from sim.observation import observe_with_truth

    obs, truth = observe_with_truth(
        domain, domain.scene(recs), cam, seed=seed, realism=CHECK_REALISM, mask=True, clean=True
    )
    return obs, {"rgb": truth["clean_rgb"], "depth": truth["clean_depth"], "mask": obs["mask"]}


def _subsample(view: Mapping[str, Any], scale: int) -> dict[str, Any]:
    """Every `scale`-th pixel of a view: the view of the camera at 1/`scale` resolution (the
    same view and field of view, `domains.cameras.scaled`), to a fraction of a pixel."""
    return {k: np.ascontiguousarray(view[k][::scale, ::scale]) for k in ("rgb", "depth", "mask")}


def _corners(domain: Domain, recs: list[dict]) -> np.ndarray:
    """The corners of every object's bounding box in the world (N·8, 3): what a camera must
    show for the scene to be in its frame."""
    meshes = domain.meshes()
    pts = []
    for r in recs:
        lo, hi = meshes[r["mesh"]].bounds
        box = np.array(
            [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        )
        pose = np.asarray(r["pose"], float)
        pts.append(box @ pose[:3, :3].T + pose[:3, 3])
    return np.concatenate(pts) if pts else np.zeros((0, 3))


@lru_cache(maxsize=64)
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
    small = render_scene(recs, domain.meshes(), camera(domain, "front", PROPERTY_RES))["mask"]
    if (small == k).any():  # a cheap first look
        return None
    if (render_scene(recs, domain.meshes(), camera(domain, "front", 1))["mask"] == k).any():
        return None
    if check_scene(domain, domain.scene(drawn[0])):
        return None
    return recs, behind


def hidden_views(domain: Domain, rng: np.random.Generator, n: int) -> list[tuple[int, list, str]]:
    """(seed, records, hidden id) of `n` draws of `Domain.hidden_scene` (seeds from `rng`)
    that hide their object entirely from the front camera."""
    out: list[tuple[int, list, str]] = []
    if n <= 0:
        return out
    for _ in range(40 * n):
        if len(out) >= n:
            break
        s = int(rng.integers(FRESH_FROM, SEED_SPACE))
        got = _hidden(domain.name, s)
        if got is not None:
            out.append((s, *got))
    return out


def observation_case(
    domain: Domain,
    name: str,
    recs: list[dict],
    true_camera: dict,
    camera_name: str,
    seed: int,
    unscored: tuple[str, ...] = (),
) -> dict[str, Any]:
    """One `perceive` case: the observation (and its calibrated camera) the draft gets, the
    truth, and the simulator's clean view at `image_factor` for the image check (host only)."""
    full, clean = _realistic(domain, recs, true_camera, seed)
    factor = image_factor(true_camera, recs)
    if factor == 1 / HALF_RES:
        reference = _subsample(clean, HALF_RES)
    elif factor == 1:
        reference = {k: clean[k] for k in ("rgb", "depth", "mask")}
    else:  # a far or wide camera: the reference is rendered finer than the observation
        reference = _observation(domain, recs, resized(true_camera, factor))
    case: dict[str, Any] = {
        "name": name,
        "observation": {"rgb": full["rgb"], "depth": full["depth"], "camera": full["camera"]},
        "camera": full["camera"],
        "camera_name": camera_name,
        # the perceived records are judged where they are in the world: redrawn from the true
        # camera (the judge's, never the draft's), an error of the calibration the draft left
        # uncorrected shows as it does in the trials
        "render_camera": (judge_camera := resized(true_camera, factor)),
        "truth": recs,
        "reference_camera": judge_camera,
        "reference": {**reference, "full": full},
    }
    if unscored:
        # shown nowhere and holding nothing up: it must be reported, but where it stands the
        # image cannot say
        case["unscored"] = list(unscored)
    return case


def image_factor(camera: Mapping, recs: list[dict]) -> float:
    """The image check's resolution for a camera, as a factor of its own: 1/`HALF_RES` where
    a pixel then covers at most `IMAGE_PIXEL_MAX` at the scene's centre, else the smallest of
    1, 1.5, 2, 3 that does (within `IMAGE_SIZE_MAX`)."""
    t = np.asarray(camera["T_world_camera"], float)
    centre = np.mean([np.asarray(r["pose"], float)[:3, 3] for r in recs], axis=0)
    depth = float((centre - t[:3, 3]) @ t[:3, 2])
    pixel = depth / float(np.asarray(camera["K"])[1, 1])  # [m] at full resolution
    if pixel * HALF_RES <= IMAGE_PIXEL_MAX:
        return 1 / HALF_RES
    w, h = int(camera["width"]), int(camera["height"])
    fits = [
        f for f in (1.0, 1.5, 2.0, 3.0) if w * f <= IMAGE_SIZE_MAX[0] and h * f <= IMAGE_SIZE_MAX[1]
    ]
    return next((f for f in fits if pixel / f <= IMAGE_PIXEL_MAX), fits[-1])


def perceive_cases(
    domain: Domain, budget: Budget, seed: int, *, envelope: CameraEnvelope | None = None
) -> list[dict[str, Any]]:
    """`budget.observations` observations drawn from the task's space (see the module
    docstring), `budget.hidden` of them the task text's hiding case where the domain has one.
    `envelope`: every other camera drawn from it instead (no named view), e.g. one side of
    the domain's (`python -m benchmarks.perceive_draws --azimuth`)."""
    rng = _rng(seed, "perceive")
    out: list[dict[str, Any]] = []
    for _seed_h, recs, behind in hidden_views(domain, rng, budget.hidden):
        out.append(
            observation_case(
                domain,
                f"obs{len(out) + 1:02d}/hidden/front",
                recs,
                domain.camera("front"),
                "front",
                int(rng.integers(SEED_SPACE)),
                unscored=(behind,),
            )
        )
    pool = iter(instances(domain, rng, budget.observations, scenes_only=True))
    named = envelope is None
    envelope = domain.camera_envelope if envelope is None else envelope
    while len(out) < budget.observations:
        drawn = composed_scene(domain, rng) if rng.random() < COMPOSED_SHARE else None
        if drawn is not None:
            kind, (side, recs) = "composed", drawn
        else:
            inst = next(pool, None)
            if inst is None:
                break
            side = "start" if rng.random() < 0.5 else "goal"
            kind, recs = "generated", records(inst.start if side == "start" else inst.goal)
        if rng.random() < NAMED_VIEW_SHARE and named:
            cam_name = str(rng.choice(list(domain.cameras)))
            true_camera = domain.camera(cam_name)
        else:
            cam_name = "drawn"
            try:
                true_camera = envelope.draw(rng, shows_points=_corners(domain, recs))
            except ValueError:
                continue
        size = f"{true_camera['width']}x{true_camera['height']}"
        out.append(
            observation_case(
                domain,
                f"obs{len(out) + 1:02d}/{kind}-{side}/{cam_name}-{size}",
                recs,
                true_camera,
                cam_name,
                int(rng.integers(SEED_SPACE)),
            )
        )
    return out


def build_cases(domain: Domain, function: str, budget: Budget, seed: int) -> dict[str, Any]:
    """The cases of `function`'s suite, drawn from case seed `seed`.

    - render: ``scenes``: {name, records, camera, image (compared with the simulator),
      reference (the simulator's rgb/depth/mask, for image cases)};
    - perceive: ``observations``: {name, observation (rgb, noisy depth, calibrated camera),
      camera, render_camera, truth (true records), reference (the simulator's clean view at
      `HALF_RES` and the full-size observation)};
    - relate: ``scenes``: {name, records, reference (relations)};
    - plan: ``instances``: {name, start, goal, start_relations, goal_relations, order_len}
      (the generator's, then the domain's composed ones), ``infeasible``: goals no plan
      reaches, with why.
    """
    if function not in FUNCTIONS:
        raise UsageError(f"unknown function '{function}'; known: {', '.join(FUNCTIONS)}")
    rng = _rng(seed, function)
    cases: dict[str, Any] = {"seed": seed}
    if function == "perceive":
        cases["observations"] = perceive_cases(domain, budget, seed)
        return cases
    # plan's cases are ones the robot its checks hold a plan to can carry out; where every draw
    # already was, a case seed names the same cases as before. `relate` and `render` are shown
    # scenes, so theirs are drawn with no construction order (searching one is most of a
    # draw's time) and a start no order reaches is one of their cases too.
    scenes_only = function != "plan"
    pool = instances(
        domain, rng, budget.instances, executable=not scenes_only, scenes_only=scenes_only
    )
    sides = ("start", "goal")

    def named(k: int, inst: domains.Instance) -> str:
        kind = "composed" if inst.name.startswith("composed/") else "generated"
        return f"case{k + 1:02d}/{kind}"

    if function == "relate":
        scenes = [(named(k, inst), inst) for k, inst in enumerate(pool)]
        scenes += [
            (named(len(pool) + k, inst), inst)
            for k, inst in enumerate(composed(domain, rng, budget.composed, scenes_only=True))
        ]
        cases["scenes"] = [
            {
                "name": f"{name}/{side}",
                "records": (recs := records(getattr(inst, side))),
                "reference": domain.reference_relations(recs),
            }
            for name, inst in scenes
            for side in sides
        ]
    elif function == "plan":
        pool = [*pool, *composed(domain, rng, budget.composed, executable=True)]
        cases["instances"] = [
            {
                "name": named(k, inst),
                "start": records(inst.start),
                "goal": records(inst.goal),
                "start_relations": domain.reference_relations(records(inst.start)),
                "goal_relations": domain.reference_relations(records(inst.goal)),
                "order_len": len(inst.order),
            }
            for k, inst in enumerate(pool)
        ]
        cases["infeasible"] = infeasible_cases(domain, pool, rng, budget.infeasible)
    elif function == "render":
        views: list[dict[str, Any]] = []
        for k, (i, side, cam) in enumerate(budget.render_cases):
            inst = pool[i % len(pool)]
            recs = records(getattr(inst, side))
            name = f"{named(i % len(pool), inst)}/{side}/{cam}"
            views.append(
                {
                    "name": name,
                    "records": recs,
                    "camera": camera(domain, cam, HALF_RES),
                    "camera_name": cam,
                    "image": True,
                    "reference": _observation(domain, recs, camera(domain, cam, HALF_RES)),
                }
            )
            if k == 0:  # a small view for the cheap properties
                views.insert(
                    0,
                    {
                        "name": f"{name}@1/{PROPERTY_RES}",
                        "records": recs,
                        "camera": camera(domain, cam, PROPERTY_RES),
                        "camera_name": cam,
                    },
                )
        cases["scenes"] = views
    return cases


INFEASIBLE_KINDS = ("floating", "overlap", "unsupported", "outside")


def infeasible_cases(
    domain: Domain, pool: list[domains.Instance], rng: np.random.Generator, n: int
) -> list[dict[str, Any]]:
    """`n` goals no plan can reach, drawn from the instances' goals: an object floating at a
    random height, an object sunk into a random partner by a random depth, a stack whose
    support is moved away, an object moved out of the reachable workspace — each kind in turn,
    each kept only when the geometry confirms it (`infeasible_goal`)."""
    out: list[dict[str, Any]] = []
    for _k in range(50 * max(n, 1)):
        if len(out) >= n:
            break
        inst = pool[int(rng.integers(len(pool)))]
        kind = INFEASIBLE_KINDS[len(out) % len(INFEASIBLE_KINDS)]
        got = infeasible_goal(domain, records(inst.goal), kind, rng)
        if got is None:
            continue
        goal, why = got
        start = records(inst.start)
        out.append(
            {
                "name": f"infeasible{len(out) + 1:02d}/{kind}",
                "start": start,
                "goal": goal,
                "start_relations": domain.reference_relations(start),
                "goal_relations": domain.reference_relations(goal),
                "why": why,
            }
        )
    return out


def infeasible_goal(
    domain: Domain, goal: list[dict], kind: str, rng: np.random.Generator
) -> tuple[list[dict], str] | None:
    """`goal` made unreachable the `kind` way (`INFEASIBLE_KINDS`) with drawn amounts, and why;
    None when this draw does not make it so (e.g. no stack to undermine)."""
    from domains.generation import geometric_problems
    from geometry import PLACEMENT

    g = [dict(r, pose=np.array(r["pose"], float)) for r in goal]
    ids = [r["id"] for r in g]
    graph = domain.reference_relations(g)
    on = [(e["source"], e["target"]) for e in graph["edges"] if e["type"] == "on"]
    if kind == "floating":
        k = int(rng.integers(len(g)))
        lift = float(rng.uniform(0.02, 0.12))
        g[k]["pose"][2, 3] += lift
        why = f"'{ids[k]}' floats {lift * 1000:.0f} mm above where it would rest"
        if geometric_problems(domain, domain.scene(g)):
            return None  # lifted into something else or out of reach: another kind's case
        return g, why
    if kind == "overlap":
        if len(g) < 2:
            return None
        a, b = (int(x) for x in rng.choice(len(g), 2, replace=False))
        frac = float(rng.uniform(0.0, 0.6))
        ang = float(rng.uniform(0, 2 * np.pi))
        size = float(np.min(domain.meshes()[g[b]["mesh"]].extents[:2]))
        g[a]["pose"] = g[b]["pose"].copy()
        g[a]["pose"][:2, 3] += frac * size * np.array([np.cos(ang), np.sin(ang)])
        problems = [
            p for p in geometric_problems(domain, domain.scene(g)) if "penetrates" in p.problem
        ]
        if not problems:
            return None
        return g, f"'{ids[a]}' and '{ids[b]}' overlap"
    if kind == "unsupported":
        carried = [(s, t) for s, t in on]
        if not carried:
            return None
        top, base = carried[int(rng.integers(len(carried)))]
        k = ids.index(base)
        for _ in range(20):
            x = float(rng.uniform(PLACEMENT.x[0], PLACEMENT.x[1]))
            y = float(rng.uniform(PLACEMENT.y[0], PLACEMENT.y[1]))
            moved = [dict(r, pose=r["pose"].copy()) for r in g]
            moved[k]["pose"][:2, 3] = (x, y)
            moved[k]["pose"][2, 3] = g[k]["pose"][2, 3] - _floor(domain, g[k])
            if not geometric_problems(domain, domain.scene(moved)) and top not in {
                e["source"] for e in domain.reference_relations(moved)["edges"] if e["type"] == "on"
            }:
                return moved, f"'{top}' is left with nothing under it ('{base}' moved away)"
        return None
    if kind == "outside":
        k = int(rng.integers(len(g)))
        ang = float(rng.uniform(-np.pi, np.pi))
        reach = float(rng.uniform(1.0, 1.4)) * domain.workspace.reach
        g[k]["pose"][:2, 3] = reach * np.array([np.cos(ang), np.sin(ang)])
        g[k]["pose"][2, 3] -= _floor(domain, g[k])
        if not any("outside" in p.problem for p in geometric_problems(domain, domain.scene(g))):
            return None
        return g, f"'{ids[k]}' is out of the robot's reach"
    raise ValueError(f"unknown infeasible kind {kind!r}")


def _floor(domain: Domain, rec: Mapping) -> float:
    """How far `rec`'s lowest point is above the table [m]."""
    mesh = domain.meshes()[rec["mesh"]]
    pose = np.asarray(rec["pose"], float)
    return float((mesh.vertices @ pose[:3, :3].T + pose[:3, 3])[:, 2].min())
