"""The `perceive` suite: record schema, catalogue ids, proper rotations, determinism.

Observations are simulator RGB-D images (with the depth sensor's noise) of generated scenes
from several cameras; the draft gets the image and the camera only, never the scene. Each is
perceived once; the valid records are left in ``outputs["perceived"]`` for the checks that
compare them with the truth (`property.accuracy`) and re-render them against the image
(`image.perceive_rerender`, with the frozen `render` in a session of its own).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from checks import images
from checks.context import SuiteContext
from checks.hypo import Failure
from checks.report import CheckResult
from checks.suites._common import copy_records, raised, run_check, same_value, scene_spec
from contracts import se3
from contracts.errors import ContractError
from contracts.validate import validate
from sandbox import MESHES


def perceived(ctx: SuiteContext, i: int) -> Any:
    key = ("perceive", i)
    if key not in ctx.cache:
        case = ctx.cases["observations"][i]
        ctx.cache[key] = ctx.call(case["observation"], MESHES, case["camera"], label=case["name"])
    return ctx.cache[key]


def where(ctx: SuiteContext, case: dict) -> dict[str, Any]:
    """How a failing observation is shown: its name, camera and the true scene (host only)."""
    return {
        "observation": case["name"],
        "camera": case["camera_name"],
        "scene": scene_spec(ctx.spec.name, case["truth"]),
    }


def checks(ctx: SuiteContext) -> list[CheckResult]:
    cases = ctx.cases["observations"]
    spec = ctx.spec
    out: list[CheckResult] = []
    ctx.outputs["perceived"] = perceived_out = {}
    valid: dict[int, list[dict]] = {}

    def schema(r: CheckResult) -> None:
        first: Failure | None = None
        for i, case in enumerate(cases):
            res = perceived(ctx, i)
            if not res.ok:
                first = first or raised(f"perceive on {case['name']}", res, where(ctx, case))
                continue
            try:
                validate("records", res.value)
            except ContractError as e:
                first = first or Failure(
                    message=f"the records perceived in {case['name']} break the contract: {e}",
                    actual=str(e),
                    counterexample=where(ctx, case),
                )
                continue
            valid[i] = copy_records(res.value)
            perceived_out[case["name"]] = [
                {"id": str(o["id"]), "mesh": str(o["mesh"]), "pose": np.asarray(o["pose"], float)}
                for o in res.value
            ]
        r.examples = len(cases)
        if first:
            raise first

    out.append(
        run_check(
            "schema.output",
            "schema",
            schema,
            expected="a list of {'id': str, 'mesh': str, 'pose': 4x4 rigid transform}, ids unique",
        )
    )

    def ids(r: CheckResult) -> None:
        for i, recs in valid.items():
            case = cases[i]
            for k, o in enumerate(recs):
                if o["id"] not in spec.catalogue:
                    raise Failure(
                        message=f"records[{k}].id '{o['id']}' is not an object of the catalogue",
                        expected=sorted(spec.catalogue),
                        actual=o["id"],
                        counterexample=where(ctx, case),
                    )
                if o["mesh"] != spec.catalogue[o["id"]]:
                    raise Failure(
                        message=f"records[{k}]: '{o['id']}' has mesh '{spec.catalogue[o['id']]}' "
                        f"in the catalogue, not '{o['mesh']}'",
                        expected=spec.catalogue[o["id"]],
                        actual=o["mesh"],
                        counterexample=where(ctx, case),
                    )
            truth = sorted(t["id"] for t in case["truth"])
            got = sorted(o["id"] for o in recs)
            if got != truth:
                raise Failure(
                    message=f"the scene in {case['name']} holds {truth}; perceive returned {got}",
                    expected=truth,
                    actual=got,
                    counterexample=where(ctx, case),
                )
        r.examples = len(valid)

    out.append(run_check("property.ids_match_catalogue", "property", ids))

    def rotations(r: CheckResult) -> None:
        for i, recs in valid.items():
            for k, o in enumerate(recs):
                R = o["pose"][:3, :3]
                if not se3.is_proper_rotation(R, tol=1e-6):
                    ortho, det = se3.rotation_defect(R)
                    raise Failure(
                        message=f"records[{k}] ('{o['id']}'): the rotation is not proper "
                        f"(max |RᵀR − I| = {ortho:.2e}, det = {det:.4f})",
                        counterexample=where(ctx, cases[i]),
                    )
        r.examples = len(valid)

    out.append(run_check("property.proper_rotations", "property", rotations))

    def deterministic(r: CheckResult) -> None:
        k = min(len(cases), ctx.examples("determinism"))
        for i in range(k):
            case = cases[i]
            again = ctx.call(case["observation"], MESHES, case["camera"], label="again")
            first = perceived(ctx, i)
            if first.ok and again.ok and not same_value(first.value, again.value):
                raise Failure(
                    message=f"perceive gave two different results for the same image "
                    f"({case['name']})",
                    counterexample=where(ctx, case),
                )
        r.examples = k

    out.append(run_check("property.deterministic", "property", deterministic))

    return out


def accuracy(ctx: SuiteContext, domain: Any) -> CheckResult:
    """Every object found and within tolerance of the truth, with the same reference relations."""
    from sim.score import state_accuracy

    t0 = time.perf_counter()
    tol = domain.tolerance
    r = CheckResult(
        name="property.accuracy",
        category="property",
        expected=f"every object found, each within {tol.translation * 1000:.0f} mm"
        + ("" if tol.rotation is None else f" and {np.degrees(tol.rotation):.0f}°")
        + " of the truth (modulo symmetry), and the same reference relations",
    )
    cases = ctx.cases["observations"]
    perceived_out = ctx.outputs.get("perceived", {})
    scored = [c for c in cases if c["name"] in perceived_out]
    r.examples = len(scored)
    if len(scored) < len(cases):  # schema.output reports why; a state not scored is not right
        missing = [c["name"] for c in cases if c["name"] not in perceived_out]
        r.fail(
            f"{len(missing)} of {len(cases)} observations gave no valid records (first: "
            f"{missing[0]}), so their accuracy cannot be established",
            counterexample=where(ctx, next(c for c in cases if c["name"] == missing[0])),
        )
    errors: list[float] = []
    wrong_cases: list[str] = []
    for case in scored:
        recs = perceived_out[case["name"]]
        score = state_accuracy(domain, recs, case["truth"])
        errors += [o.translation for o in score.objects]
        if score.correct:
            continue
        wrong_cases.append(case["name"])
        if r.status != "passed":
            continue
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
        truth = {o["id"]: o for o in case["truth"]}
        got = {o["id"]: o for o in recs}
        shown = wrong[0].id if wrong else None
        r.fail(
            f"perceive is wrong on {case['name']}: " + "; ".join(parts),
            expected=None
            if shown is None
            else {"id": shown, "position_m": np.round(truth[shown]["pose"][:3, 3], 4).tolist()},
            actual=None
            if shown is None
            else {
                "id": shown,
                "position_m": np.round(np.asarray(got[shown]["pose"])[:3, 3], 4).tolist(),
            },
            counterexample=where(ctx, case),
        )
    if wrong_cases and r.status == "failed":
        r.message += f" ({len(wrong_cases)} of {len(cases)} observations wrong)"
    r.metrics = {
        "states_correct": float(len(scored) - len(wrong_cases)),
        "translation_error_median_m": float(np.median(errors)) if errors else None,
        "translation_error_max_m": float(np.max(errors)) if errors else None,
    }
    r.duration_s = time.perf_counter() - t0
    return r


def rerender(ctx: SuiteContext, renders: Mapping[str, Any], out_dir: Any) -> CheckResult:
    """`render(perceive(I))` against `I`, per object: `renders` are the frozen render's (or the
    toolbox renderer's) images of the perceived records, by observation name."""
    t0 = time.perf_counter()
    r = CheckResult(
        name="image.perceive_rerender",
        category="image",
        expected=f"render(perceive(I)) against I, per object: silhouette IoU >= {images.IOU_MIN}, "
        f"mean >= {images.IOU_MEAN_MIN}, median depth error <= "
        f"{images.DEPTH_MEDIAN_MAX * 1000:.0f} mm (objects under {images.MIN_AREA} px are not "
        "scored)",
    )
    cases = ctx.cases["observations"]
    worst: tuple[float, dict, Any, list] | None = None
    first_problem: tuple[dict, list[str], list] | None = None
    judged = 0
    for case in cases:
        got = renders.get(case["name"])
        if got is None:
            continue
        judged += 1
        ids = [o["id"] for o in case["truth"]]
        if "error" in got:
            first_problem = first_problem or (case, [got["error"]], [])
            continue
        try:
            matches = images.compare(got, got["ids"], case["reference"], ids)
        except ValueError as e:
            first_problem = first_problem or (case, [f"the re-render: {e}"], [])
            continue
        problems = images.judge(matches)
        score = images.summary(matches)["iou_mean"] or 0.0
        if worst is None or score < worst[0]:
            worst = (score, case, got, matches)
        if problems and first_problem is None:
            first_problem = (case, problems, matches)
    r.examples = judged
    if judged < len(cases):
        r.status, r.message = "skipped", "skipped: some observations gave no valid records"
        return r
    if worst is not None:
        _, case, got, matches = worst
        r.metrics = images.summary(matches)
        panel = images.overlay(
            case["reference"]["full"]["rgb"],
            case["reference"]["mask"],
            None,
            got["mask"],
            got["ids"],
            [o["id"] for o in case["truth"]],
        )
        r.images = images.write_png(
            out_dir,
            f"perceive_rerender_{case['name']}",
            panel,
            f"{case['name']}: observation | perceived objects re-rendered over it | silhouettes "
            "(white agree, red only observed, blue only perceived)",
        )
    if first_problem is not None:
        case, problems, matches = first_problem
        r.fail(
            f"render(perceive(I)) does not match I for {case['name']}: " + "; ".join(problems[:3]),
            actual=[m.to_dict() for m in matches] or problems,
            counterexample=where(ctx, case),
        )
    r.duration_s = time.perf_counter() - t0
    return r
