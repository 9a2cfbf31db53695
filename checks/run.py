"""Host side of the checks: build a suite's inputs, run it in the sandbox, add the image checks.

Design rule: the split follows what needs what. `contracts.checks` holds the suites that run
INSIDE the sandbox next to the draft (no simulator, no Docker, no files); this module runs on
the host and does what needs the simulator or the file system:
- inputs: instances from the domain's seeded generator, their reference relations, and
  simulator observations of them (RGB-D with the depth sensor's noise, several cameras);
- the sandbox job (`contracts.checks.suite:run` as the entry point, the draft and the frozen
  functions it depends on as modules);
- the checks that need ground truth the draft must never see: perception accuracy against the
  true scene, and the image checks — `render(true records)` against the simulator's view of the
  same scene, `render(perceive(I))` against `I` — with overlay PNGs written under `out_dir`;
- the report (`check_report.schema.json`).
Everything is seeded, so the same draft gets the same report (timings aside).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

import domains
from contracts.checks import images
from contracts.checks.report import FUNCTIONS, CheckResult, build_report, jsonable
from contracts.checks.suite import ENTRY
from contracts.checks.suites._common import scene_spec
from contracts.errors import RivetError, UsageError
from domains import Domain

HALF_RES = 2  # image checks render at 1/2 of the domain cameras' resolution
PROPERTY_RES = 4  # render's property checks at 1/4


@dataclass(frozen=True, kw_only=True)
class Budget:
    """How much checking one draft gets.

    Attributes:
        seed: seeds hypothesis (the instances have their own seeds).
        instance_seeds: generator seeds of the instances every suite draws from.
        observations: (instance index, "start" | "goal", camera name) perceived by `perceive`.
        render_cases: (instance index, side, camera) rendered by `render` for the images.
        examples: hypothesis examples per property family (beyond the explicit ones).
        call_timeout: per-call budget of each function [s].
        job_timeout: budget of the whole sandbox job [s].
    """

    name: str
    seed: int = 20250601
    instance_seeds: tuple[int, ...] = tuple(range(1, 9))
    observations: tuple[tuple[int, str, str], ...] = (
        (0, "start", "front"),
        (1, "goal", "view1"),
        (2, "start", "view2"),
        (3, "goal", "front"),
    )
    render_cases: tuple[tuple[int, str, str], ...] = (
        (0, "goal", "front"),
        (1, "start", "view1"),
        (2, "goal", "view2"),
    )
    examples: Mapping[str, int] = field(
        default_factory=lambda: {
            "plan": 12,
            "order": 12,
            "translation": 12,
            "determinism": 2,
            "identity": 3,
        }
    )
    call_timeout: Mapping[str, float] = field(
        default_factory=lambda: {"render": 10.0, "perceive": 10.0, "relate": 5.0, "plan": 10.0}
    )
    hard_observations: int = 1  # plus the most occluded views of `hard_seeds`' instances
    hard_seeds: tuple[int, ...] = tuple(range(1, 17))
    shrink_calls: int = 20
    job_timeout: float = 240.0

    def to_inputs(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "examples": dict(self.examples),
            "call_timeout": dict(self.call_timeout),
            "shrink_calls": self.shrink_calls,
        }


DEFAULT = Budget(name="default")
THOROUGH = Budget(
    name="thorough",
    instance_seeds=tuple(range(1, 25)),
    observations=tuple(
        (i, side, cam)
        for i, (side, cam) in enumerate(
            [(s, c) for s in ("start", "goal") for c in ("front", "view1", "view2")] * 2
        )
    ),
    render_cases=tuple(
        (i, side, cam)
        for i, (side, cam) in enumerate(
            [(s, c) for s in ("start", "goal") for c in ("front", "view1", "view2")]
        )
    ),
    examples={"plan": 60, "order": 50, "translation": 50, "determinism": 4, "identity": 8},
    hard_observations=3,
    hard_seeds=tuple(range(1, 41)),
    shrink_calls=60,
    job_timeout=600.0,
)


# -- inputs -----------------------------------------------------------------------------------


@lru_cache(maxsize=256)
def _instance(domain_name: str, seed: int) -> domains.Instance | None:
    try:
        return domains.load(domain_name).generate(seed, physics=False)
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


def _records(scene: Mapping) -> list[dict]:
    return [
        {"id": o["id"], "mesh": o["mesh"], "pose": np.asarray(o["pose"], float)}
        for o in scene["objects"]
    ]


def camera(domain: Domain, name: str, scale: int = 1) -> dict:
    """Camera `name` of the domain at 1/`scale` of its resolution (same view, centred)."""
    spec = domain.cameras[name]
    small = dataclasses.replace(spec, width=spec.width // scale, height=spec.height // scale)
    return small.to_camera()


def domain_spec(domain: Domain) -> dict[str, Any]:
    """The domain as the in-sandbox suites see it (`contracts.checks.suite.DomainSpec`)."""
    meshes = domain.meshes()
    tol = domain.tolerance
    ws = domain.workspace
    return {
        "domain": domain.name,
        "catalogue": [{"id": o.id, "mesh": o.mesh} for o in domain.objects],
        "meshes": {
            k: {"vertices": np.asarray(m.vertices, float), "faces": np.asarray(m.faces, np.int64)}
            for k, m in meshes.items()
        },
        "parts": {
            k: [np.asarray(p.vertices, float) for p in parts]
            for k, parts in domain.collision_meshes.items()
        },
        "centres": {k: np.asarray(m.center_mass, float) for k, m in meshes.items()},
        "symmetries": {k: np.asarray(domain.symmetries(k), float) for k in domain.mesh_specs},
        "tolerance": {"translation": tol.translation, "rotation": tol.rotation},
        "workspace": {"x": list(ws.x), "y": list(ws.y), "reach": ws.reach},
        "relations": dict(domain.RELATIONS),
    }


@lru_cache(maxsize=64)
def _observation(domain_name: str, seed: int, side: str, cam: str, scale: int) -> dict[str, Any]:
    """The simulator's clean view (rgb, depth, mask) of an instance's scene."""
    from sim.render import observe

    domain = domains.load(domain_name)
    inst = _instance(domain_name, seed)
    assert inst is not None
    scene = inst.start if side == "start" else inst.goal
    return observe(domain, scene, camera(domain, cam, scale), noise=None, mask=True)


def _noisy(view: Mapping[str, Any], seed: int) -> dict[str, Any]:
    """A clean view with the depth sensor's noise (seeded): what `perceive` gets."""
    from sim.render import apply_depth_noise

    return {**view, "depth": apply_depth_noise(view["depth"], np.random.default_rng(seed))}


def _subsample(view: Mapping[str, Any], scale: int) -> dict[str, Any]:
    """Every `scale`-th pixel of a view: the view of the camera at 1/`scale` resolution, to a
    fraction of a pixel."""
    return {k: np.ascontiguousarray(view[k][::scale, ::scale]) for k in ("rgb", "depth", "mask")}


@dataclass(kw_only=True)
class HostCase:
    """What the host keeps of one image case: the truth and the simulator's view of it."""

    name: str
    truth: list[dict]
    camera_name: str
    reference: dict[str, Any]  # {"rgb", "depth" (clean), "mask"} at the comparison resolution


def build_inputs(
    domain: Domain, function: str, budget: Budget
) -> tuple[dict[str, Any], list[HostCase]]:
    """The sandbox job's inputs for `function`, and the host's side of the image cases."""
    pool = instances(domain, budget.instance_seeds)
    cases: dict[str, Any] = {}
    host: list[HostCase] = []

    def scene_of(i: int, side: str) -> list[dict]:
        return _records(pool[i].start if side == "start" else pool[i].goal)

    if function == "relate":
        cases["scenes"] = [
            {
                "name": f"{inst.name}/{side}",
                "records": scene_of(i, side),
                "reference": domain.relate(scene_of(i, side)),
            }
            for i, inst in enumerate(pool)
            for side in ("start", "goal")
        ]
    elif function == "plan":
        cases["instances"] = [
            {
                "name": inst.name,
                "start": scene_of(i, "start"),
                "goal": scene_of(i, "goal"),
                "start_relations": domain.relate(scene_of(i, "start")),
                "goal_relations": domain.relate(scene_of(i, "goal")),
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
                    "image": True,
                }
            )
            ref = _observation(domain.name, pool[i].seed, side, cam, HALF_RES)
            host.append(HostCase(name=name, truth=recs, camera_name=cam, reference=ref))
            if k == 0:  # a small view for the cheap properties
                scenes.insert(
                    0,
                    {
                        "name": f"{name}@1/{PROPERTY_RES}",
                        "records": recs,
                        "camera": camera(domain, cam, PROPERTY_RES),
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
            name = f"{pool[i].name}/{side}/{cam}"
            clean = _observation(domain.name, pool[i].seed, side, cam, 1)
            full = _noisy(clean, pool[i].seed or 0)
            obs.append(
                {
                    "name": name,
                    "rgb": full["rgb"],
                    "depth": full["depth"],
                    "camera": full["camera"],
                    "render_camera": camera(domain, cam, HALF_RES),
                    "truth": recs,
                    "truth_scene": scene_spec(domain.name, recs),
                }
            )
            ref = _subsample(clean, HALF_RES)
            host.append(
                HostCase(name=name, truth=recs, camera_name=cam, reference={**ref, "full": full})
            )
        cases["observations"] = obs
    else:
        raise UsageError(f"unknown function '{function}'; known: {', '.join(FUNCTIONS)}")
    inputs = {"spec": domain_spec(domain), "cases": cases, "budget": budget.to_inputs()}
    return inputs, host


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
            recs = _records(inst.start if side == "start" else inst.goal)
            graph = domain.relate(recs)
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
    start = _records(inst.start)
    goal = _records(inst.goal)
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
                "start_relations": domain.relate(start),
                "goal_relations": domain.relate(g),
                "why": why,
            }
        )
    return out


# -- running ------------------------------------------------------------------------------------


class CheckMachineryError(RivetError):
    """The checks could not run (not the draft's fault): say how to fix it."""


def run_checks(
    domain: str,
    function: str,
    source: str,
    *,
    deps: Mapping[str, str],
    thorough: bool = False,
    executor: Any = None,
    out_dir: Path | None = None,
) -> dict[str, Any]:
    """Run `function`'s full checks on a draft; see `contracts.checks.run_checks`."""
    import sandbox

    if function not in FUNCTIONS:
        raise UsageError(f"unknown function '{function}'; known: {', '.join(FUNCTIONS)}")
    dom = domains.load(domain)
    budget = THOROUGH if thorough else DEFAULT
    t0 = time.perf_counter()
    inputs, host = build_inputs(dom, function, budget)
    own = executor is None
    ex = sandbox.open_executor("docker") if own else executor
    try:
        job = sandbox.Job(
            source=source,
            function=function,
            module_name=function,
            modules=dict(deps),
            entry=ENTRY,
            inputs=inputs,
            timeout_s=budget.job_timeout,
            memory_mb=4096,
        )
        result = ex.run(job)
    finally:
        if own:
            ex.close()
    checks = _job_checks(result, budget)
    if result.verdict == "ok":
        outputs = result.output.get("outputs", {})
        if function == "render":
            checks.append(_render_images(dom, host, outputs, out_dir))
        elif function == "perceive":
            checks.append(_perceive_accuracy(dom, host, outputs))
            checks.append(_perceive_images(dom, host, outputs, out_dir))
    return build_report(
        domain=domain,
        function=function,
        source=source,
        checks=checks,
        duration_s=time.perf_counter() - t0,
    )


def _job_checks(result: Any, budget: Budget) -> list[Any]:
    """The suite's checks, or the interface failure that explains why there are none."""
    if result.verdict == "ok":
        out = result.output
        if not isinstance(out, dict) or not isinstance(out.get("checks"), list):
            raise CheckMachineryError("the check suite returned no checks (sandbox image stale?)")
        return [dict(c) for c in out["checks"]]
    exc = result.exception
    if result.verdict == "exception" and exc is not None:
        if "contracts.checks" in exc.message or "contracts.checks" in exc.traceback:
            raise CheckMachineryError(
                f"the sandbox cannot run the check suite ({exc.type}: {exc.message}); the "
                "sandbox image is probably older than contracts/checks: run `make sandbox-image`"
            )
        return [
            CheckResult(
                name="interface.import",
                category="interface",
                status="error",
                message=f"the module does not import: {exc.type}: {exc.message}",
                traceback=exc.traceback,
            )
        ]
    if result.verdict == "timeout":
        return [
            CheckResult(
                name="interface.returns_in_time",
                category="interface",
                status="failed",
                message=f"the checks did not finish within {budget.job_timeout:g} s: a call of "
                "the function is far too slow or never returns",
            )
        ]
    return [
        CheckResult(
            name="interface.runs",
            category="interface",
            status="error",
            message=f"the process running the function died ({result.verdict}: {result.detail})",
            actual=result.stderr_tail[-1000:] or None,
        )
    ]


# -- host-side checks ---------------------------------------------------------------------------


def _write_png(out_dir: Path | None, name: str, rgb: np.ndarray) -> list[dict[str, str]]:
    import cv2

    if out_dir is None:
        return []
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / name
    cv2.imwrite(str(path), cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))
    return [{"path": str(path)}]


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def _render_images(dom: Domain, host: list[HostCase], outputs: Mapping, out_dir) -> CheckResult:
    t0 = time.perf_counter()
    r = CheckResult(
        name="image.render_vs_simulator",
        category="image",
        expected=f"per object: silhouette IoU >= {images.IOU_MIN}, mean >= "
        f"{images.IOU_MEAN_MIN}, median depth error <= {images.DEPTH_MEDIAN_MAX * 1000:.0f} mm",
    )
    renders = outputs.get("renders", {})
    worst: tuple[float, HostCase, Any, list] | None = None
    first_problem: tuple[HostCase, list[str], list] | None = None
    for case in host:
        got = renders.get(case.name)
        if got is None:
            r.status, r.message = "skipped", "skipped: the renders did not pass the schema check"
            r.duration_s = time.perf_counter() - t0
            return r
        ids = [o["id"] for o in case.truth]
        matches = images.compare(got, ids, case.reference, ids)
        problems = images.judge(matches)
        score = images.summary(matches)["iou_mean"] or 0.0
        if worst is None or score < worst[0]:
            worst = (score, case, got, matches)
        if problems and first_problem is None:
            first_problem = (case, problems, matches)
    assert worst is not None
    _, case, got, matches = worst
    r.metrics = images.summary(matches)
    r.examples = len(host)
    panel = images.overlay(
        case.reference["rgb"],
        case.reference["mask"],
        got["rgb"],
        got["mask"],
        [o["id"] for o in case.truth],
        [o["id"] for o in case.truth],
    )
    r.images = [
        dict(
            i,
            caption=f"{case.name}: simulator | render(true records) | silhouettes "
            "(white agree, red only simulator, blue only render)",
        )
        for i in _write_png(out_dir, f"render_vs_simulator_{_safe(case.name)}.png", panel)
    ]
    if first_problem is not None:
        case, problems, matches = first_problem
        r.fail(
            f"render(true records) does not match the simulator's image of {case.name}: "
            + "; ".join(problems[:3]),
            actual=[m.to_dict() for m in matches],
            counterexample={
                "scene": scene_spec(dom.name, case.truth),
                "camera": jsonable(camera(dom, case.camera_name, HALF_RES)),
            },
        )
    r.duration_s = time.perf_counter() - t0
    return r


def _perceive_accuracy(dom: Domain, host: list[HostCase], outputs: Mapping) -> CheckResult:
    from sim.score import state_accuracy

    t0 = time.perf_counter()
    tol = dom.tolerance
    r = CheckResult(
        name="property.accuracy",
        category="property",
        expected=f"every object found, each within {tol.translation * 1000:.0f} mm"
        + ("" if tol.rotation is None else f" and {np.degrees(tol.rotation):.0f}°")
        + " of the truth (modulo symmetry), and the same reference relations",
    )
    perceived = outputs.get("perceived", {})
    errors: list[float] = []
    correct = 0
    for case in host:
        recs = perceived.get(case.name)
        if recs is None:
            continue  # the schema check reports it
        score = state_accuracy(dom, recs, case.truth)
        errors += [o.translation for o in score.objects]
        correct += score.correct
        if not score.correct and r.status == "passed":
            wrong = [o for o in score.objects if not o.within]
            parts = []
            if score.missing:
                parts.append(f"missing {score.missing}")
            if score.extra:
                parts.append(f"unexpected {score.extra}")
            parts += [f"'{o.id}' is {o.translation * 1000:.1f} mm off" for o in wrong[:3]]
            if score.missing_edges or score.extra_edges:
                parts.append(
                    f"relations differ (missing {score.missing_edges[:3]}, extra "
                    f"{score.extra_edges[:3]})"
                )
            truth = {o["id"]: o for o in case.truth}
            got = {o["id"]: o for o in recs}
            shown = wrong[0].id if wrong else None
            r.fail(
                f"perceive is wrong on {case.name}: " + "; ".join(parts),
                expected=None
                if shown is None
                else {"id": shown, "position_m": np.round(truth[shown]["pose"][:3, 3], 4).tolist()},
                actual=None
                if shown is None
                else {
                    "id": shown,
                    "position_m": np.round(np.asarray(got[shown]["pose"])[:3, 3], 4).tolist(),
                },
                counterexample={
                    "observation": case.name,
                    "camera": case.camera_name,
                    "scene": scene_spec(dom.name, case.truth),
                },
            )
    r.examples = len(host)
    r.metrics = {
        "states_correct": float(correct),
        "translation_error_median_m": float(np.median(errors)) if errors else None,
        "translation_error_max_m": float(np.max(errors)) if errors else None,
    }
    r.duration_s = time.perf_counter() - t0
    return r


def _perceive_images(dom: Domain, host: list[HostCase], outputs: Mapping, out_dir) -> CheckResult:
    t0 = time.perf_counter()
    r = CheckResult(
        name="image.perceive_rerender",
        category="image",
        expected=f"render(perceive(I)) against I, per object: silhouette IoU >= {images.IOU_MIN}, "
        f"mean >= {images.IOU_MEAN_MIN}, median depth error <= "
        f"{images.DEPTH_MEDIAN_MAX * 1000:.0f} mm",
    )
    rerender = outputs.get("rerender", {})
    worst: tuple[float, HostCase, Any, list] | None = None
    first_problem: tuple[HostCase, list[str], list] | None = None
    for case in host:
        got = rerender.get(case.name)
        if got is None:
            continue
        ids = [o["id"] for o in case.truth]
        if "error" in got:
            if first_problem is None:
                first_problem = (case, [got["error"]], [])
            continue
        matches = images.compare(got, got["ids"], case.reference, ids)
        problems = images.judge(matches)
        score = images.summary(matches)["iou_mean"] or 0.0
        if worst is None or score < worst[0]:
            worst = (score, case, got, matches)
        if problems and first_problem is None:
            first_problem = (case, problems, matches)
    if worst is None and first_problem is None:
        r.status, r.message = "skipped", "skipped: no perceived records passed the schema check"
        r.duration_s = time.perf_counter() - t0
        return r
    r.examples = len(host)
    if worst is not None:
        _, case, got, matches = worst
        r.metrics = images.summary(matches)
        panel = images.overlay(
            case.reference["full"]["rgb"],
            case.reference["mask"],
            None,
            got["mask"],
            got["ids"],
            [o["id"] for o in case.truth],
        )
        r.images = [
            dict(
                i,
                caption=f"{case.name}: observation | perceived objects re-rendered over it | "
                "silhouettes (white agree, red only observed, blue only perceived)",
            )
            for i in _write_png(out_dir, f"perceive_rerender_{_safe(case.name)}.png", panel)
        ]
    if first_problem is not None:
        case, problems, matches = first_problem
        r.fail(
            f"render(perceive(I)) does not match I for {case.name}: " + "; ".join(problems[:3]),
            actual=[m.to_dict() for m in matches] or problems,
            counterexample={
                "observation": case.name,
                "camera": case.camera_name,
                "scene": scene_spec(dom.name, case.truth),
            },
        )
    r.duration_s = time.perf_counter() - t0
    return r


__all__ = ["DEFAULT", "THOROUGH", "Budget", "CheckMachineryError", "build_inputs", "run_checks"]
