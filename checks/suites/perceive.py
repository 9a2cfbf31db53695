"""The `perceive` suite: record schema, catalogue ids, proper rotations, determinism, and the
re-render of what was perceived.

Observations are simulator RGB-D images (with the depth sensor's noise) of generated scenes
from several cameras, made on the host. Here each is perceived once; the records and their
re-render — by the frozen `render` when the job carries it, else by the toolbox renderer
standing in for it — go back to the host under ``outputs``, where the accuracy against ground
truth and the image comparison with the observation are computed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from contracts import se3
from contracts.checks._hypo import Failure
from contracts.checks.report import CheckResult
from contracts.checks.suite import SuiteContext
from contracts.checks.suites._common import copy_records, raised, run_check, same_value
from contracts.errors import ContractError
from contracts.validate import validate


def _observation(case: dict) -> dict[str, Any]:
    return {"rgb": case["rgb"], "depth": case["depth"], "camera": case["camera"]}


def perceived(ctx: SuiteContext, i: int) -> Any:
    key = ("perceive", i)
    if key not in ctx.cache:
        case = ctx.cases["observations"][i]
        ctx.cache[key] = ctx.call(
            _observation(case), ctx.spec.fresh_meshes(), case["camera"], label=case["name"]
        )
    return ctx.cache[key]


def _where(case: dict) -> dict[str, Any]:
    return {"observation": case["name"], "scene": case["truth_scene"]}


def checks(ctx: SuiteContext) -> list[CheckResult]:
    cases = ctx.cases["observations"]
    spec = ctx.spec
    out: list[CheckResult] = []
    ctx.outputs["perceived"] = perceived_out = {}
    ctx.outputs["rerender"] = rerender_out = {}
    valid: dict[int, list[dict]] = {}

    def schema(r: CheckResult) -> None:
        first: Failure | None = None
        for i, case in enumerate(cases):
            res = perceived(ctx, i)
            if not res.ok:
                first = first or raised(f"perceive on {case['name']}", res, _where(case))
                continue
            try:
                validate("records", res.value)
            except ContractError as e:
                first = first or Failure(
                    message=f"the records perceived in {case['name']} break the contract: {e}",
                    actual=str(e),
                    counterexample=_where(case),
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
                        counterexample=_where(case),
                    )
                if o["mesh"] != spec.catalogue[o["id"]]:
                    raise Failure(
                        message=f"records[{k}]: '{o['id']}' has mesh '{spec.catalogue[o['id']]}' "
                        f"in the catalogue, not '{o['mesh']}'",
                        expected=spec.catalogue[o["id"]],
                        actual=o["mesh"],
                        counterexample=_where(case),
                    )
            truth = sorted(t["id"] for t in case["truth"])
            got = sorted(o["id"] for o in recs)
            if got != truth:
                raise Failure(
                    message=f"the scene in {case['name']} holds {truth}; perceive returned {got}",
                    expected=truth,
                    actual=got,
                    counterexample=_where(case),
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
                        counterexample=_where(cases[i]),
                    )
        r.examples = len(valid)

    out.append(run_check("property.proper_rotations", "property", rotations))

    def deterministic(r: CheckResult) -> None:
        k = min(len(cases), ctx.examples("determinism"))
        for i in range(k):
            case = cases[i]
            again = ctx.call(_observation(case), spec.fresh_meshes(), case["camera"], label="again")
            first = perceived(ctx, i)
            if first.ok and again.ok and not same_value(first.value, again.value):
                raise Failure(
                    message=f"perceive gave two different results for the same image "
                    f"({case['name']})",
                    counterexample=_where(case),
                )
        r.examples = k

    out.append(run_check("property.deterministic", "property", deterministic))

    # the re-render for the host's image check: frozen render, else the toolbox renderer
    render = ctx.dependency("render")
    if render is None:
        from toolbox import render_scene

        render = render_scene
    for i, recs in valid.items():
        case = cases[i]
        known = [o for o in recs if o["mesh"] in spec.meshes]
        res = ctx.call(known, spec.fresh_meshes(), case["render_camera"], fn=render, label="render")
        if res.ok and isinstance(res.value, dict) and "mask" in res.value and "depth" in res.value:
            rerender_out[case["name"]] = {
                "ids": [o["id"] for o in known],
                "mask": np.asarray(res.value["mask"], np.int32),
                "depth": np.asarray(res.value["depth"], np.float32),
            }
        else:
            rerender_out[case["name"]] = {"error": f"the renderer {res.describe()}"}
    return out
