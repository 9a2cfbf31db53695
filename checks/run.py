"""Running one draft's checks: the judge on the host, the draft in a sandbox session.

Design rule: the verdict is computed here, in the caller's process, from the values the draft's
calls return; the draft runs in a sandbox session that holds nothing but the draft and the
frozen modules it imports (so it cannot reach, patch or import any of the check code, and no
ground truth is ever among its arguments). Frozen dependencies the judge itself needs — the
relations `plan` gets its states with, the renderer that redraws what `perceive` found — run in
sessions of their own, before or after the draft's, never beside it.

    report = run_checks("cubes", "plan", source, deps={"relate": relate_src}, executor=ex)

Everything is seeded, so the same draft gets the same report (timings aside).
"""

from __future__ import annotations

import time
from collections.abc import Collection, Mapping
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

import domains
from checks import properties, suites
from checks.budget import DEFAULT, THOROUGH, Budget
from checks.calls import CallResult, DraftCalls, frozen_up_to, session_modules
from checks.context import (
    DomainSpec,
    SuiteContext,
    check_fast_enough,
    check_import,
    check_in_time,
    check_runs,
    check_signature,
)
from checks.inputs import build_cases, fresh_seed
from checks.report import CheckResult, build_report
from checks.robot import robot_view
from checks.rulebook import rule_map
from checks.suites import perceive as perceive_suite
from checks.suites import render as render_suite
from checks.suites._common import if_selected, selected, selecting
from checks.suites.plan import Unrelated
from contracts.errors import UsageError
from contracts.functions import FUNCTIONS
from sandbox import MESHES, Executor, Program


def run_checks(
    domain: str,
    function: str,
    source: str,
    *,
    deps: Mapping[str, str],
    thorough: bool = False,
    executor: Executor | None = None,
    out_dir: Path | None = None,
    budget: Budget | None = None,
    cases_seed: int | None = None,
    only: Collection[str] | None = None,
) -> dict[str, Any]:
    """Run one draft's full checks and return its check report.

    Args:
        domain: a registered domain name (e.g. "cubes").
        function: "render", "perceive", "relate" or "plan".
        source: the draft module's source; it must define `function`.
        deps: the set's frozen programs, by function name (e.g. {"render": src, "perceive":
            src, "relate": src} for `plan`). The draft's session holds all of them, as the
            runtime's one session does (`checks.calls.session_modules`); the draft imports
            them by these names. Where a function the judge needs is absent the domain's
            ground truth stands in for it (reference relations for `plan`, the toolbox
            renderer to redraw what `perceive` found).
        thorough: more instances, observations and hypothesis examples (`THOROUGH`).
        executor: a `sandbox.Executor` to run the sessions in; None opens (and closes) the
            Docker backend, and fails loudly when Docker is unavailable.
        out_dir: where the overlay PNGs go (referenced by path in the report); None: no images.
        budget: overrides `thorough` (tests and benchmarks).
        cases_seed: the seed the cases are drawn from (`checks.inputs`); None draws a fresh
            one. The report records it: the same seed draws the same cases.
        only: check names (`rivet check --only`): only these run, with the interface and
            schema checks they rest on; the others are reported skipped (and pass).

    Raises:
        UsageError: an unknown function, or an `only` name no check of it has.

    Returns:
        A dict valid against `check_report.schema.json`.
    """
    import sandbox

    if function not in FUNCTIONS:
        raise UsageError(f"unknown function '{function}'; known: {', '.join(FUNCTIONS)}")
    dom = domains.load(domain)
    rules = known_checks(dom, function, only)
    budget = budget or (THOROUGH if thorough else DEFAULT)
    t0 = time.perf_counter()
    spec = DomainSpec.of(dom)
    seed = fresh_seed() if cases_seed is None else int(cases_seed)
    cases = build_cases(dom, function, budget, seed)
    deps = {k: v for k, v in deps.items() if k in FUNCTIONS and k != function}
    own = executor is None
    ex: sandbox.Executor = sandbox.open_executor("docker") if executor is None else executor
    try:
        with selecting(only):
            if function == "plan" and "relate" in deps:
                _relate_states(ex, deps, cases, spec, budget)
            checks, ctx = _draft_checks(
                ex, dom, spec, function, source, deps, cases, budget, out_dir
            )
            if ctx is not None and function == "perceive":
                checks += _perceive_on_host(ex, dom, deps, ctx, spec, budget, out_dir)
    finally:
        if own:
            ex.close()
    report = build_report(
        domain=domain,
        function=function,
        source=source,
        checks=checks,
        duration_s=time.perf_counter() - t0,
        rules=rules,
    )
    report["cases_seed"] = seed
    return report


def known_checks(dom: Any, function: str, only: Collection[str] | None = None) -> dict[str, Any]:
    """The rules of `function`'s checks in `dom` by check name; `UsageError` when `only` names
    a check the function does not have (listing those it has)."""
    rules = rule_map(dom, function)
    unknown = sorted(set(only or ()) - set(rules))
    if unknown:
        raise UsageError(
            f"no {function} check is named {', '.join(unknown)}; its checks: {', '.join(rules)}"
        )
    return rules


def _draft_checks(
    ex: Executor,
    dom: Any,
    spec: DomainSpec,
    function: str,
    source: str,
    deps: Mapping[str, str],
    cases: dict[str, Any],
    budget: Budget,
    out_dir: Path | None,
) -> tuple[list[CheckResult], SuiteContext | None]:
    """The draft's own session: interface, schema, property and domain checks."""
    program = Program(modules=session_modules(function, source, deps), meshes=spec.meshes)
    with ex.open_session(program, memory_mb=4096, load_timeout_s=budget.load_timeout) as session:
        load = CallResult.of(session.load, budget.load_timeout)
        checks = [check_import(function, load, budget.load_timeout)]
        if not load.ok:
            return checks, None
        draft = DraftCalls(
            session=session,
            module=function,
            budget=float(budget.call_timeout[function]),
            objects=len(spec.catalogue),
        )
        checks.append(check_signature(function, draft.signature()))
        if checks[-1].failing:
            return checks, None
        ctx = SuiteContext(
            function=function,
            spec=spec,
            cases=cases,
            budget=budget,
            draft=draft,
            hand=robot_view(dom.name) if function == "plan" else None,
            out_dir=out_dir,
        )
        checks += suites.SUITES[function](ctx)
        for prop in properties.properties_for(dom, function):
            checks.append(
                if_selected(
                    prop.check_name, "domain", partial(properties.run_property_check, prop, ctx)
                )
            )
    if function == "render":
        checks.append(
            if_selected(
                "image.render_vs_simulator",
                "image",
                lambda: render_suite.render_vs_simulator(ctx, out_dir),
            )
        )
    checks += [
        check_runs(draft),
        check_in_time(function, draft),
        check_fast_enough(function, draft, float(budget.online[function])),
    ]
    return checks, ctx


def _perceive_on_host(
    ex: Executor,
    dom: Any,
    deps: Mapping[str, str],
    ctx: SuiteContext,
    spec: DomainSpec,
    budget: Budget,
    out_dir: Path | None,
) -> list[CheckResult]:
    """`perceive`'s accuracy against the truth and its re-render against the observations,
    judged on the host from what the suite left in ``ctx.outputs``."""
    wanted = selected("property.accuracy") or selected("image.perceive_rerender")
    renders = perceive_suite.aligned(ctx, _rerender(ex, deps, ctx, spec, budget)) if wanted else {}
    return [
        if_selected(
            "property.accuracy",
            "property",
            lambda: perceive_suite.accuracy(ctx, dom, renders, out_dir),
        ),
        if_selected(
            "image.perceive_rerender",
            "image",
            lambda: perceive_suite.rerender(ctx, renders, out_dir),
        ),
    ]


def _relate_states(
    ex: Executor,
    deps: Mapping[str, str],
    cases: dict[str, Any],
    spec: DomainSpec,
    budget: Budget,
) -> None:
    """The relations of every state `plan` is checked on, from the frozen `relate` in a
    session of its own (replacing the reference relations in `cases`)."""
    modules = session_modules("relate", deps["relate"], frozen_up_to("relate", deps))
    timeout = float(budget.call_timeout["relate"])
    program = Program(modules=modules, meshes=spec.meshes)
    with ex.open_session(program, load_timeout_s=budget.load_timeout) as session:
        why = "" if session.load.ok else f"did not load ({session.load.verdict})"
        for case in [*cases["instances"], *cases["infeasible"]]:
            for side in ("start", "goal"):
                if why:
                    case[f"{side}_relations"] = Unrelated(why=why)
                    continue
                got = CallResult.of(
                    session.call("relate", "relate", case[side], MESHES, timeout_s=timeout),
                    timeout,
                ).bounded("relate", len(spec.catalogue))
                case[f"{side}_relations"] = (
                    got.value
                    if got.ok and isinstance(got.value, dict)
                    else Unrelated(why=got.describe(), traceback=got.traceback)
                )


def _rerender(
    ex: Executor,
    deps: Mapping[str, str],
    ctx: SuiteContext,
    spec: DomainSpec,
    budget: Budget,
) -> dict[str, Any]:
    """What `render` draws of each observation's valid perceived records, at the image
    check's resolution: the frozen `render` in a session of its own, else the toolbox's."""
    perceived = ctx.outputs.get("perceived", {})
    cases = [c for c in ctx.cases["observations"] if c["name"] in perceived]
    out: dict[str, Any] = {}
    jobs = []
    for case in cases:
        known = [o for o in perceived[case["name"]] if o["mesh"] in spec.meshes]
        jobs.append((case, known))
    if "render" not in deps:
        from toolbox import render_scene

        for case, known in jobs:
            got = render_scene(known, spec.meshes, case["render_camera"])
            out[case["name"]] = _rendered(known, got)
        return out
    timeout = float(budget.call_timeout["render"])
    modules = session_modules("render", deps["render"], frozen_up_to("render", deps))
    program = Program(modules=modules, meshes=spec.meshes)
    with ex.open_session(program, load_timeout_s=budget.load_timeout) as session:
        for case, known in jobs:
            if not session.load.ok:
                out[case["name"]] = {"error": f"the frozen render did not load ({session.load})"}
                continue
            call = CallResult.of(
                session.call(
                    "render", "render", known, MESHES, case["render_camera"], timeout_s=timeout
                ),
                timeout,
            )
            out[case["name"]] = (
                _rendered(known, call.value)
                if call.ok
                else {"error": f"the frozen render {call.describe()}"}
            )
    return out


def _rendered(known: list[dict], got: Any) -> dict[str, Any]:
    if not (isinstance(got, dict) and "mask" in got and "depth" in got):
        return {"error": "the renderer returned no mask and depth"}
    try:
        return {
            "ids": [o["id"] for o in known],
            "mask": np.asarray(got["mask"], np.int32),
            "depth": np.asarray(got["depth"], np.float32),
        }
    except (TypeError, ValueError) as e:
        return {"error": f"the renderer's images are unreadable ({e})"}


__all__ = ["DEFAULT", "THOROUGH", "Budget", "run_checks"]
