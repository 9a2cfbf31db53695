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
from checks.registry import register, rules
from checks.report import CheckResult
from checks.rules import Rule
from checks.suites._common import (
    copy_records,
    raise_first,
    raised,
    same_value,
)
from contracts import se3
from contracts.errors import ContractError
from contracts.validate import validate
from sandbox import MESHES

PROPER_TOL = 1e-6  # a proper rotation: max |RᵀR − I| and |det R − 1| at most this


def perceived(ctx: SuiteContext, i: int) -> Any:
    key = ("perceive", i)
    if key not in ctx.cache:
        case = ctx.cases["observations"][i]
        ctx.cache[key] = ctx.call(case["observation"], MESHES, case["camera"], label=case["name"])
    return ctx.cache[key]


def where(ctx: SuiteContext, case: dict) -> dict[str, Any]:
    """How a failing observation is named: its drawn case and camera — never the true scene
    (docs/checks.md, "What feedback shows")."""
    out: dict[str, Any] = {"observation": case["name"], "camera": case["camera_name"]}
    if "camera" in case:
        out["image_size"] = [int(case["camera"]["width"]), int(case["camera"]["height"])]
    return out


def _valid(ctx: SuiteContext) -> dict[int, list[dict]]:
    """The records of every observation whose result passed the schema, by case index (what
    `schema.output` leaves for the checks after it)."""
    return ctx.outputs.setdefault("valid_records", {})


@register(
    "perceive",
    "schema.output",
    rule='`perceive` returns a list of records `{"id": str, "mesh": str, "pose": '
    "(4, 4) rigid transform T_world_object}` with unique ids.",
    expected="a list of {'id': str, 'mesh': str, 'pose': 4x4 rigid transform}, ids unique",
)
def schema(ctx: SuiteContext, r: CheckResult) -> None:
    cases = ctx.cases["observations"]
    valid = _valid(ctx)
    perceived_out = ctx.outputs.setdefault("perceived", {})
    found: list[Failure] = []
    for i, case in enumerate(cases):
        res = perceived(ctx, i)
        if not res.ok:
            found.append(raised(f"perceive on {case['name']}", res, where(ctx, case)))
            continue
        try:
            validate("records", res.value)
        except ContractError as e:
            found.append(
                Failure(
                    message=f"the records perceived in {case['name']} break the contract: {e}",
                    actual=str(e),
                    counterexample=where(ctx, case),
                )
            )
            continue
        valid[i] = copy_records(res.value)
        perceived_out[case["name"]] = [
            {"id": str(o["id"]), "mesh": str(o["mesh"]), "pose": np.asarray(o["pose"], float)}
            for o in res.value
        ]
    r.examples = len(cases)
    raise_first(r, found, "observations")


def _ids_problem(ctx: SuiteContext, case: dict, recs: list[dict]) -> Failure | None:
    catalogue = ctx.spec.catalogue
    for k, o in enumerate(recs):
        if o["id"] not in catalogue:
            return Failure(
                message=f"records[{k}].id '{o['id']}' is not an object of the catalogue",
                expected=sorted(catalogue),
                actual=o["id"],
                counterexample=where(ctx, case),
            )
        if o["mesh"] != catalogue[o["id"]]:
            return Failure(
                message=f"records[{k}]: '{o['id']}' has mesh '{catalogue[o['id']]}' "
                f"in the catalogue, not '{o['mesh']}'",
                expected=catalogue[o["id"]],
                actual=o["mesh"],
                counterexample=where(ctx, case),
            )
    truth = sorted(t["id"] for t in case["truth"])
    got = sorted(o["id"] for o in recs)
    if got != truth:
        hidden = sorted(set(truth) - set(got))
        return Failure(
            message=f"the scene in {case['name']} holds {truth}; perceive returned {got}"
            + (f" (missing: {hidden}; every object of the scene must be reported, also "
               "one the camera cannot see)" if hidden else ""),
            expected=truth,
            actual=got,
            counterexample=where(ctx, case),
        )  # fmt: skip
    return None


@register(
    "perceive",
    "property.ids_match_catalogue",
    rule="Every record's id is an object of the catalogue and its `mesh` that object's "
    "catalogue mesh key, and the ids are exactly the objects the scene holds, those the "
    "camera cannot see included (see what the task text says about hidden objects).",
)
def ids_match_catalogue(ctx: SuiteContext, r: CheckResult) -> None:
    cases, valid = ctx.cases["observations"], _valid(ctx)
    found = [f for i, recs in valid.items() if (f := _ids_problem(ctx, cases[i], recs))]
    r.examples = len(valid)
    raise_first(r, found, "observations")


@register(
    "perceive",
    "property.proper_rotations",
    rule="Every pose's rotation is proper: orthonormal with determinant one, to within "
    "{checks.suites.perceive:PROPER_TOL}.",
)
def proper_rotations(ctx: SuiteContext, r: CheckResult) -> None:
    cases, valid = ctx.cases["observations"], _valid(ctx)
    for i, recs in valid.items():
        for k, o in enumerate(recs):
            R = o["pose"][:3, :3]
            if not se3.is_proper_rotation(R, tol=PROPER_TOL):
                ortho, det = se3.rotation_defect(R)
                raise Failure(
                    message=f"records[{k}] ('{o['id']}'): the rotation is not proper "
                    f"(max |RᵀR − I| = {ortho:.2e}, det = {det:.4f})",
                    counterexample=where(ctx, cases[i]),
                )
    r.examples = len(valid)


@register(
    "perceive",
    "property.deterministic",
    rule="Two calls on the same observation return identical records (same order, same poses).",
)
def deterministic(ctx: SuiteContext, r: CheckResult) -> None:
    cases = ctx.cases["observations"]
    k = min(len(cases), ctx.examples("determinism"))
    for i in range(k):
        case = cases[i]
        again = ctx.call(case["observation"], MESHES, case["camera"], label="again")
        first = perceived(ctx, i)
        if first.ok and again.ok and not same_value(first.value, again.value):
            raise Failure(
                message=f"perceive gave two different results for the same image ({case['name']})",
                counterexample=where(ctx, case),
            )
    r.examples = k


def object_feedback(
    ctx: SuiteContext,
    domain: Any,
    case: dict,
    records: list[dict],
    rendered: Mapping[str, Any] | None,
    out_dir: Any,
    name: str,
) -> tuple[list[dict], list[dict[str, str]]]:
    """Per object of an observation: the pose error against the tolerance and the observed
    silhouette against that of `render(perceive(I))`, as report rows and one grid image
    (wrong objects first). An object the case leaves unscored (hidden, holding nothing up) is
    shown as not scored."""
    from sim.score import object_errors

    tol = domain.tolerance
    unscored = set(case.get("unscored", ()))
    errors = {e.id: e for e in object_errors(domain, records, case["truth"])}
    ids = [o["id"] for o in case["truth"]]
    matches: dict[str, images.ObjectMatch] = {}
    if rendered is not None and "error" not in rendered:
        try:
            matches = {
                m.id: m for m in images.compare(rendered, rendered["ids"], case["reference"], ids)
            }
        except ValueError:
            matches = {}
    rows, tiles = [], []

    def fine(i: str) -> bool:
        return i in errors and (i in unscored or errors[i].within)

    for oid in sorted(ids, key=lambda i: (fine(i), ids.index(i))):
        e, m = errors.get(oid), matches.get(oid)
        row: dict[str, Any] = {
            "object": oid,
            "position_error_mm": None if e is None else round(1000 * e.translation, 1),
        }
        if tol.rotation is not None:
            row["rotation_error_deg"] = None if e is None else round(np.degrees(e.rotation), 1)
        row["within_tolerance"] = fine(oid)
        if oid in unscored:
            row["scored"] = False  # the image cannot say where it stands
        row["silhouette_iou"] = None if m is None else round(m.iou, 3)
        row["pixels_observed"] = None if m is None else m.area_reference
        row["pixels_rendered"] = None if m is None else m.area_candidate
        rows.append(row)
        if oid in unscored:
            first = "not perceived" if e is None else "hidden: not scored"
        elif e is None:
            first = "not perceived"
        else:
            first = f"{1000 * e.translation:.1f}/{1000 * tol.translation:g} mm" + (
                ""
                if tol.rotation is None
                else f" {np.degrees(e.rotation):.0f}/{np.degrees(tol.rotation):g} deg"
            )
        second = "" if m is None else f"IoU {m.iou:.2f}, {m.area_reference} px seen"
        tiles.append({"id": oid, "ok": row["within_tolerance"], "lines": [first, second]})
    pictures: list[dict[str, str]] = []
    if out_dir is not None:
        grid = images.object_tiles(
            case["reference"]["rgb"],
            case["reference"]["mask"],
            ids,
            None if not matches or rendered is None else rendered["mask"],
            [] if not matches or rendered is None else rendered["ids"],
            tiles,
        )
        pictures = images.write_png(
            out_dir,
            f"{name}_{case['name']}",
            grid,
            f"{case['name']}, per object (wrong ones first, red frame): the observed silhouette "
            "against render(perceive(I)) (white both, red only observed, blue only rendered); "
            "under each: position error / tolerance"
            + ("" if tol.rotation is None else ", rotation error / tolerance")
            + ", silhouette IoU and the pixels the object shows",
        )
    return rows, pictures


@register(
    "perceive",
    "property.accuracy",
    on="host",
    rule="The checks draw {checks.budget:DEFAULT.observations} observations afresh for every "
    "check (a new draw for each attempt): scenes of the domain's generator and scenes "
    "composed from the task's parts, starts and goals, the task text's hiding case where "
    "there is one, seen through the named views and through cameras drawn from this "
    "envelope: {domain.camera_envelope.description}. Each observation is what the trials "
    "give `perceive`: full resolution, sensor noise, the calibrated camera. "
    "On every one of them each object of the scene is found with its pose "
    "within {domain.tolerance.translation|mm}[? and {domain.tolerance.rotation|deg}?] of "
    "the true pose, modulo the object's symmetry, and the domain's reference relations "
    "computed on your records equal those of the true scene. An object the camera does "
    "not show at all that holds nothing up only has to be reported (the image cannot say "
    "where it stands). Nor is an object held to the tolerance where the image cannot tell "
    "your pose from the true one: the true scene drawn with that one object where you put "
    "it differs from the true scene's drawing in fewer than "
    "{checks.suites.perceive:TELL_PX|px} pixels at the image check's resolution (silhouette, "
    "or depth by more than {checks.suites.perceive:TELL_DEPTH|mm}), with the same "
    "relations — a part hidden under a round one, turned.",
)
def accuracy(
    ctx: SuiteContext,
    domain: Any,
    renders: Mapping[str, Any] | None = None,
    out_dir: Any = None,
) -> CheckResult:
    """Every object found and within tolerance of the truth, with the same reference relations.

    `renders` (the re-renders `image.perceive_rerender` judges) and `out_dir` give the failing
    observation's per-object rows and picture."""
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
        got_all = perceived_out[case["name"]]
        # once a failing case is shown, the others count only as wrong or right: their
        # scoring may stop at the first object the image does tell (`untellable(every=False)`)
        score, untold = reading_score(
            domain, ctx.spec.meshes, case, got_all, every=r.status == "passed"
        )
        # the error of every object the case scores, excused or not (the same however far
        # `untellable` looked): `score` itself where nothing was excused
        left_out = set(case.get("unscored", ()))
        every_scored = score
        if untold:
            every_scored = state_accuracy(
                domain,
                [o for o in got_all if o["id"] not in left_out],
                [o for o in case["truth"] if o["id"] not in left_out],
            )
        errors += [o.translation for o in every_scored.objects]
        if untold:  # shown like an object nothing shows: reported, its pose not scored
            case = {**case, "unscored": sorted({*case.get("unscored", ()), *untold})}
        recs = [o for o in got_all if o["id"] not in case.get("unscored", ())]
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
        r.objects, r.images = object_feedback(
            ctx,
            domain,
            case,
            perceived_out[case["name"]],
            (renders or {}).get(case["name"]),
            out_dir,
            "accuracy",
        )
        ctx.outputs["accuracy_shown"] = case["name"]
        r.fail(
            f"perceive is wrong on {case['name']}: " + "; ".join(parts),
            expected=None
            if shown is None
            else {"id": shown, "within_mm": round(tol.translation * 1000, 1)},
            actual=None
            if shown is None
            else {
                "id": shown,
                # how far off, not where the truth is (docs/checks.md, "What feedback shows")
                "off_by_mm": round(
                    1000
                    * float(
                        np.linalg.norm(
                            np.asarray(got[shown]["pose"])[:3, 3] - truth[shown]["pose"][:3, 3]
                        )
                    ),
                    1,
                ),
            },
            counterexample=where(ctx, case),
        )
    if wrong_cases and r.status == "failed":
        r.message += f" ({len(wrong_cases)} of {len(cases)} observations wrong)"
    if r.status == "failed":
        r.failures = len(wrong_cases) + len(cases) - len(scored)
        r.examples = len(cases)
    r.metrics = {
        "states_correct": float(len(scored) - len(wrong_cases)),
        "translation_error_median_m": float(np.median(errors)) if errors else None,
        "translation_error_max_m": float(np.max(errors)) if errors else None,
    }
    r.duration_s = time.perf_counter() - t0
    return r


MIN_VISIBLE_SHARE = 0.3  # an object showing less of its own silhouette is not scored by IoU
TELL_PX = 20  # [px] at the image check's resolution: fewer pixels changed cannot be told apart
TELL_DEPTH = 0.004  # [m] a depth change that counts as a changed pixel


def reading_score(
    domain: Any, meshes: Mapping, case: dict, records: list[dict], *, every: bool = True
) -> tuple:
    """(`sim.score.state_accuracy` of `records` on observation `case`, the ids left out of it
    because the image cannot tell their poses (`untellable`)) — how `property.accuracy` scores
    one reading. Objects the case leaves unscored (nothing shows them, they hold nothing up)
    are reported (`property.ids_match_catalogue`), never placed. `every=False`: stop at the
    first object the image does tell (the reading is wrong then, whatever the others are);
    the ids left out are those found before it."""
    from sim.score import state_accuracy

    left_out = set(case.get("unscored", ()))
    recs = [o for o in records if o["id"] not in left_out]
    truth = [o for o in case["truth"] if o["id"] not in left_out]
    score = state_accuracy(domain, recs, truth)
    untold = untellable(domain, meshes, case, recs, score, every=every)
    if untold:
        recs = [o for o in recs if o["id"] not in untold]
        truth = [o for o in truth if o["id"] not in untold]
        score = state_accuracy(domain, recs, truth)
    return score, untold


def untellable(
    domain: Any, meshes: Mapping, case: dict, recs: list[dict], score: Any, *, every: bool = True
) -> set:
    """The objects `score` finds off whose pose the observation cannot tell from the true one:
    the true scene drawn with that one object where `recs` put it differs from the true
    scene's drawing in fewer than `TELL_PX` pixels at the image check's resolution (the
    silhouettes, or the depth by more than `TELL_DEPTH`), and has the same reference relations
    (so it holds up what it holds up). An object the true drawing shows nowhere that holds
    nothing up, there or where `recs` put it, keeps only the others' relations: what it rests
    on or stands beside is where it stands, which the image cannot say (the rule text). Only
    for a reading with every object reported once. `every=False`: return at the first object
    the image tells (each costs a drawing)."""
    from toolbox import render_scene

    if score.correct or score.missing or score.extra or "reference_camera" not in case:
        return set()
    got = {o["id"]: o for o in recs}
    truth = list(case["truth"])
    camera = case["reference_camera"]
    base = None
    out = set()
    for e in score.objects:
        if e.within or e.id not in got:
            continue
        moved = [dict(o, pose=got[o["id"]]["pose"]) if o["id"] == e.id else o for o in truth]
        base = base or render_scene(truth, meshes, camera)
        unseen = not (base["mask"] == [o["id"] for o in truth].index(e.id)).any()
        told = not _relations_kept(domain, moved, truth, e.id if unseen else None)
        if not told:
            drawn = render_scene(moved, meshes, camera)
            both = (base["mask"] >= 0) & (drawn["mask"] >= 0)
            changed = (base["mask"] != drawn["mask"]) | (
                both & (np.abs(base["depth"] - drawn["depth"]) > TELL_DEPTH)
            )
            told = int(changed.sum()) >= TELL_PX
        if not told:
            out.add(e.id)
        elif not every:
            break
    return out


def _relations_kept(domain: Any, moved: list[dict], truth: list[dict], free: str | None) -> bool:
    """Whether `moved` has the reference relations of `truth`; with `free` (an object nothing
    shows), those of `free` itself are left out where it holds nothing up in either."""
    from sim.score import reference_edges

    before, after = reference_edges(domain, truth), reference_edges(domain, moved)
    if before == after:
        return True
    holds = any(t == free and kind == "on" for _, t, kind in before | after)
    return free is not None and not holds and all(free in (a, b) for a, b, _ in before ^ after)


def calibration_pixels(case: Mapping[str, Any]) -> int:
    """How far [px], at the image check's resolution, the trials' calibration error can move
    the image of the scene: its rotation plus its translation seen at the scene's depth."""
    from sim.realism import DEFAULT as REALISM

    cam = case["render_camera"]
    t = np.asarray(cam["T_world_camera"], float)
    centre = np.mean([np.asarray(o["pose"], float)[:3, 3] for o in case["truth"]], axis=0)
    depth = max(float((centre - t[:3, 3]) @ t[:3, 2]), 0.1)
    angle = REALISM.calib_rotation + REALISM.calib_translation / depth
    return int(np.ceil(angle * float(np.asarray(cam["K"])[1, 1])))


def aligned(ctx: SuiteContext, renders: Mapping[str, Any]) -> dict[str, Any]:
    """Each re-render shifted, as a whole, by the image translation of at most
    `calibration_pixels` that makes the most pixels agree with the observed objects: a draft
    judged on poses in a miscalibrated camera's world is not held to the calibration error
    (its poses are, by `property.accuracy`, as in the trials)."""
    out = dict(renders)
    for case in ctx.cases["observations"]:
        got = renders.get(case["name"])
        if got is None or "error" in got:
            continue
        ids = [o["id"] for o in case["truth"]]
        ref = np.asarray(case["reference"]["mask"])
        index = {oid: k for k, oid in enumerate(ids)}
        mask = np.asarray(got["mask"])
        if mask.shape != ref.shape:
            continue  # `image.perceive_rerender` says so
        lut = np.array([index.get(str(i), -2) for i in got["ids"]] + [-1], dtype=np.int64)
        same = lut[np.where(mask >= 0, mask, len(got["ids"]))]  # candidate in reference ids
        shift = best_shift(same, ref, calibration_pixels(case))
        if shift != (0, 0):
            out[case["name"]] = dict(
                got,
                mask=_shift(mask, *shift, -1),
                depth=_shift(np.asarray(got["depth"]), *shift, 0.0),
                shift_px=shift,
            )
    return out


def best_shift(same: np.ndarray, ref: np.ndarray, k: int) -> tuple[int, int]:
    """The image translation (dy, dx), each within ±`k`, under which the most pixels of the
    observed objects (`ref >= 0`) show the same object in `same` moved by it
    (`_shift(same, dy, dx, -1) == ref`); of equal scores the smallest shift (|dy| + |dx|),
    then the first in row order. Scored on the object pixels only."""
    ys, xs = np.nonzero(ref >= 0)
    want = ref[ys, xs]
    h, w = same.shape
    best, shift = -1, (0, 0)
    for dy in range(-k, k + 1):
        for dx in range(-k, k + 1):
            sy, sx = ys - dy, xs - dx
            inside = (sy >= 0) & (sy < h) & (sx >= 0) & (sx < w)
            score = int((same[sy[inside], sx[inside]] == want[inside]).sum())
            if score > best or (score == best and abs(dy) + abs(dx) < sum(map(abs, shift))):
                best, shift = score, (dy, dx)
    return shift


def _shift(a: np.ndarray, dy: int, dx: int, fill: Any) -> np.ndarray:
    out = np.full_like(a, fill)
    h, w = a.shape[:2]
    ys, yd = (slice(0, h - dy), slice(dy, h)) if dy >= 0 else (slice(-dy, h), slice(0, h + dy))
    xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
    out[yd, xd] = a[ys, xs]
    return out


def mostly_hidden(ctx: SuiteContext, case: dict, m: images.ObjectMatch) -> bool:
    """Whether an object the image check would fail shows less than `MIN_VISIBLE_SHARE` of the
    silhouette it has alone in the view: the sliver of a mostly hidden object moves its IoU
    and depth by more than any pose within tolerance would (its pose is judged by
    `property.accuracy` all the same). Asked only of objects that fail, so it costs a render
    only then."""
    if m.area_reference < images.MIN_AREA:
        return False  # not scored anyway
    if not images.judge([m]):
        return False
    from toolbox import render_scene

    truth = next((o for o in case["truth"] if o["id"] == m.id), None)
    if truth is None or "reference_camera" not in case:
        return False
    alone = render_scene([truth], ctx.spec.meshes, case["reference_camera"])["mask"]
    return m.area_reference < MIN_VISIBLE_SHARE * int((alone == 0).sum())


@register(
    "perceive",
    "image.perceive_rerender",
    on="host",
    rule="The frozen `render` of your records is compared, per object, with the "
    "simulator's silhouettes and depth of the observed scene (at a resolution where a pixel "
    "covers at most {checks.inputs:IMAGE_PIXEL_MAX|mm} at the scene: half the "
    "observation's, or finer for a far or wide camera; an object showing less than "
    "{checks.suites.perceive:MIN_VISIBLE_SHARE|pct} of its own silhouette is judged by "
    "`property.accuracy` only; the whole re-render may be shifted by what the calibration "
    "error can move the image by): silhouette IoU at "
    "least {checks.images:IOU_MIN}, mean IoU at least {checks.images:IOU_MEAN_MIN}, median "
    "depth error at most {checks.images:DEPTH_MEDIAN_MAX|mm} where both show the object, "
    "pixels within {checks.images:DEPTH_EDGE_PX|px} of either outline left out while "
    "{checks.images:DEPTH_MIN_PX|px} remain (objects shown with fewer than {checks.images:MIN_AREA|px} are not scored). An object "
    "the camera does not show at all that holds nothing up must be drawn with fewer than "
    "{checks.images:MIN_AREA|px} too: it stands where the camera cannot see it.",
)
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
    judged = bad = 0
    for case in cases:
        got = renders.get(case["name"])
        if got is None:
            continue
        judged += 1
        ids = [o["id"] for o in case["truth"]]
        if "error" in got:
            first_problem = first_problem or (case, [got["error"]], [])
            bad += 1
            continue
        try:
            matches = images.compare(got, got["ids"], case["reference"], ids)
        except ValueError as e:
            first_problem = first_problem or (case, [f"the re-render: {e}"], [])
            bad += 1
            continue
        matches = [m for m in matches if not mostly_hidden(ctx, case, m)]
        problems = images.judge(matches)
        unshown = set(case.get("unscored", ()))
        problems += [
            f"'{m.id}': drawn with {m.area_candidate} px where the image shows none of it (an "
            "object the camera does not show must stand where the camera would not see it)"
            for m in matches
            if m.id in unshown and m.area_candidate >= images.MIN_AREA
        ]
        bad += bool(problems)
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
            failures=bad,
        )
        recs = ctx.outputs.get("perceived", {}).get(case["name"])
        if recs is not None and matches:
            import domains

            shown_already = ctx.outputs.get("accuracy_shown") == case["name"]
            r.objects, grid = object_feedback(
                ctx,
                domains.load(ctx.spec.name),
                case,
                recs,
                renders.get(case["name"]),
                None if shown_already else out_dir,
                "perceive_rerender_objects",
            )
            r.images = grid + r.images
    r.duration_s = time.perf_counter() - t0
    return r


RULES: tuple[Rule, ...] = rules("perceive")
