"""The in-sandbox entry point: run one function's check suite on a draft and its inputs.

Design rule: this module runs INSIDE the sandbox, in the same process as the draft (the
sandbox's "entry" mode calls `run(ctx)` after loading the draft and the frozen functions it
depends on). It imports only what the sandbox image holds (contracts, toolbox, numpy, scipy,
trimesh, networkx, hypothesis), does no I/O, and never raises: whatever the draft does becomes a
failing check. Its inputs (the domain's geometry, generated instances, observations) are built
on the host by `sim.checking`, which also runs the checks that need the simulator (images,
perception accuracy) on the outputs returned here under ``"outputs"``.

Because the draft shares this process, a draft written to do so could patch this module at
import time and forge its own report; the sandbox keeps such a draft away from the host, and the
host recomputes the perception and image checks from raw outputs, but the property verdicts are
only as trustworthy as the draft's import-time code.
"""

from __future__ import annotations

import inspect
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

from contracts.checks._calls import CallResult, call
from contracts.checks.physics import Geometry, Workspace
from contracts.checks.report import FUNCTIONS, CheckResult

ENTRY = "contracts.checks.suite:run"
SIGNATURES: dict[str, tuple[str, ...]] = {
    "render": ("records", "meshes", "camera"),
    "perceive": ("observation", "meshes", "camera"),
    "relate": ("records", "meshes"),
    "plan": ("start_state", "goal_state"),
}


@dataclass(kw_only=True)
class DomainSpec:
    """What the checks know of a domain, decoded from the job's inputs."""

    name: str
    catalogue: dict[str, str]  # object id → mesh key
    meshes: dict[str, Any]  # mesh key → trimesh.Trimesh
    geometry: Geometry
    symmetries: dict[str, list[np.ndarray]]  # mesh key → (4, 4) transforms
    trans_tol: float  # [m]
    rot_tol: float | None  # [rad]
    workspace: Workspace
    relations: dict[str, str]  # the domain's reference vocabulary

    @staticmethod
    def from_inputs(d: Mapping[str, Any]) -> DomainSpec:
        import trimesh

        meshes = {
            k: trimesh.Trimesh(
                vertices=np.asarray(m["vertices"], float),
                faces=np.asarray(m["faces"], np.int64),
                process=False,
            )
            for k, m in d["meshes"].items()
        }
        return DomainSpec(
            name=d["domain"],
            catalogue={o["id"]: o["mesh"] for o in d["catalogue"]},
            meshes=meshes,
            geometry=Geometry(
                {k: [np.asarray(p, float) for p in ps] for k, ps in d["parts"].items()},
                {k: np.asarray(c, float) for k, c in d.get("centres", {}).items()},
            ),
            symmetries={k: [np.asarray(s, float) for s in v] for k, v in d["symmetries"].items()},
            trans_tol=float(d["tolerance"]["translation"]),
            rot_tol=None
            if d["tolerance"]["rotation"] is None
            else float(d["tolerance"]["rotation"]),
            workspace=Workspace.from_dict(d["workspace"]),
            relations=dict(d.get("relations", {})),
        )

    def fresh_meshes(self) -> dict[str, Any]:
        """Copies of the meshes (a draft may modify what it is given)."""
        return {k: m.copy() for k, m in self.meshes.items()}


@dataclass(kw_only=True)
class SuiteContext:
    """Everything one suite run needs: the draft, its dependencies, the domain, the cases."""

    function: str
    modules: Mapping[str, ModuleType]
    spec: DomainSpec
    cases: Mapping[str, Any]
    budget: Mapping[str, Any]
    outputs: dict[str, Any] = field(default_factory=dict)  # returned to the host
    cache: dict[Any, Any] = field(default_factory=dict)  # results shared between checks
    slowest: tuple[float, str] = (0.0, "")
    timeouts: list[str] = field(default_factory=list)

    @property
    def draft(self) -> ModuleType:
        return self.modules[self.function]

    @property
    def fn(self) -> Callable:
        return getattr(self.draft, self.function)

    @property
    def seed(self) -> int:
        return int(self.budget["seed"])

    def examples(self, key: str) -> int:
        return int(self.budget["examples"][key])

    @property
    def files(self) -> tuple[str, ...]:
        return tuple(f"{name}.py" for name in self.modules)

    def call(self, *args: Any, fn: Callable | None = None, label: str = "") -> CallResult:
        """Call the draft (or `fn`) on copies of `args` within the per-call time budget."""
        timeout = float(self.budget["call_timeout"][self.function])
        if self.timeouts and fn is None:
            # once the draft overran, later calls fail at once: a draft that never returns
            # must not hold the whole job for calls x budget seconds
            self.timeouts.append(label)
            return CallResult(timed_out=True, seconds=timeout)
        result = call(fn or self.fn, *args, timeout=timeout, files=self.files)
        if result.timed_out:
            self.timeouts.append(label)
        elif result.seconds > self.slowest[0]:
            self.slowest = (result.seconds, label)
        return result

    def dependency(self, name: str) -> Callable | None:
        """The frozen function `name` when the job carries it, else None."""
        module = self.modules.get(name) if name != self.function else None
        fn = getattr(module, name, None) if module is not None else None
        return fn if callable(fn) else None


def run(ctx: Any) -> dict[str, Any]:
    """Sandbox entry point (`ENTRY`): `ctx` is a `sandbox.harness.context.EntryContext`."""
    return run_suite(ctx.function, dict(ctx.modules), ctx.inputs)


def run_suite(function: str, modules: Mapping[str, ModuleType], inputs: Mapping[str, Any]) -> dict:
    """Run `function`'s suite; returns ``{"checks": [check dicts], "outputs": {...}}``."""
    checks: list[CheckResult] = []
    outputs: dict[str, Any] = {}
    try:
        if function not in FUNCTIONS:
            raise ValueError(f"unknown function {function!r}; known: {', '.join(FUNCTIONS)}")
        ctx = SuiteContext(
            function=function,
            modules=modules,
            spec=DomainSpec.from_inputs(inputs["spec"]),
            cases=inputs["cases"],
            budget=inputs["budget"],
            outputs=outputs,
        )
        checks.append(check_defines(ctx))
        if checks[-1].failing:
            return {"checks": [c.to_dict() for c in checks], "outputs": outputs}
        from contracts.checks import domain_properties, suites

        checks += suites.SUITES[function](ctx)
        for prop in domain_properties.properties_for(ctx.spec.name, function):
            checks.append(_guarded(prop, ctx))
        checks.append(check_in_time(ctx))
    except BaseException as e:  # a bug of the suite itself: say so, never crash the job
        checks.append(
            CheckResult(
                name="interface.suite",
                category="interface",
                status="error",
                message=f"the check suite itself failed ({type(e).__name__}: {e}); this is "
                "not the draft's fault unless the draft changed the checks' modules",
                traceback=traceback.format_exc(),
            )
        )
    return {"checks": [c.to_dict() for c in checks], "outputs": outputs}


def _guarded(prop: Callable[[SuiteContext], CheckResult], ctx: SuiteContext) -> CheckResult:
    t0 = time.perf_counter()
    try:
        result = prop(ctx)
    except Exception as e:
        result = CheckResult(
            name=f"domain.{getattr(prop, '__name__', 'property')}",
            category="domain",
            status="error",
            message=f"the domain property crashed: {type(e).__name__}: {e}",
            traceback=traceback.format_exc(),
        )
    result.duration_s = time.perf_counter() - t0
    return result


def check_defines(ctx: SuiteContext) -> CheckResult:
    """The draft defines the function with the contract's signature."""
    want = SIGNATURES[ctx.function]
    r = CheckResult(
        name="interface.signature",
        category="interface",
        expected=f"def {ctx.function}({', '.join(want)})",
    )
    fn = getattr(ctx.draft, ctx.function, None)
    if not callable(fn):
        defined = sorted(
            n for n, v in vars(ctx.draft).items() if inspect.isfunction(v) and not n.startswith("_")
        )
        return r.fail(
            f"the module defines no function `{ctx.function}`",
            actual=f"public functions: {', '.join(defined) or '(none)'}",
        )
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return r  # a builtin or C function: nothing to compare
    params = [
        p for p in sig.parameters.values() if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
    ]
    names = tuple(p.name for p in params[: len(want)])
    extra = [p.name for p in params[len(want) :] if p.default is p.empty]
    kwonly = [
        p.name for p in sig.parameters.values() if p.kind == p.KEYWORD_ONLY and p.default is p.empty
    ]
    if names != want or extra or kwonly:
        return r.fail(
            f"`{ctx.function}` must take exactly ({', '.join(want)}) (further parameters need "
            "defaults)",
            actual=f"def {ctx.function}{sig}",
        )
    return r


def check_in_time(ctx: SuiteContext) -> CheckResult:
    """Every call returned within the per-call budget."""
    budget = float(ctx.budget["call_timeout"][ctx.function])
    r = CheckResult(
        name="interface.returns_in_time",
        category="interface",
        expected=f"every call returns within {budget:g} s",
    )
    if ctx.timeouts:
        r.fail(
            f"{len(ctx.timeouts)} call(s) of `{ctx.function}` did not return within {budget:g} s, "
            f"first on {ctx.timeouts[0]}",
            actual=f"{len(ctx.timeouts)} timeouts",
        )
    return r
