"""What a check suite works with: the domain as the checks see it, the cases, the draft's calls.

Design rule: everything here lives in the judge's process (the host). The draft is reachable
only through `DraftCalls` (its sandbox session); the domain's ground truth — true scenes, the
simulator's images, reference relations — is in `cases` and `DomainSpec` and never crosses to
the draft, which receives only each call's arguments (observations, records, states, cameras,
meshes).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from checks.budget import WALL_FACTOR, Budget
from checks.calls import CallResult, DraftCalls
from checks.report import CheckResult
from contracts.functions import SIGNATURES
from geometry import Geometry, Workspace


@dataclass(kw_only=True)
class DomainSpec:
    """What the checks know of a domain."""

    name: str
    catalogue: dict[str, str]  # object id → mesh key
    meshes: dict[str, Any]  # mesh key → trimesh.Trimesh (the judge's copies)
    geometry: Geometry
    symmetries: dict[str, list[np.ndarray]]  # mesh key → (4, 4) transforms
    trans_tol: float  # [m]
    rot_tol: float | None  # [rad]
    workspace: Workspace
    relations: dict[str, str]  # the domain's reference vocabulary

    @staticmethod
    def of(domain: Any) -> DomainSpec:
        meshes = domain.meshes()
        ws = domain.workspace
        return DomainSpec(
            name=domain.name,
            catalogue={o.id: o.mesh for o in domain.objects},
            meshes=meshes,
            geometry=domain.shapes,
            symmetries={k: list(domain.symmetries(k)) for k in domain.mesh_specs},
            trans_tol=float(domain.tolerance.translation),
            rot_tol=None if domain.tolerance.rotation is None else float(domain.tolerance.rotation),
            workspace=ws,
            relations=dict(domain.REFERENCE_RELATIONS),
        )


@dataclass(kw_only=True)
class SuiteContext:
    """Everything one suite run needs: the draft's calls, the domain, the cases, the budget.

    Attributes:
        outputs: what the suite leaves for the checks that run after it (the perceived
            records for the accuracy and image checks, the renders for the image check).
        cache: draft results shared between checks (keyed by what was asked).
    """

    function: str
    spec: DomainSpec
    cases: Mapping[str, Any]
    budget: Budget
    draft: DraftCalls
    hand: Any = None  # checks.robot.RobotView: the executor's hand and arm, for plan steps
    out_dir: Any = None  # where the checks' images go (`checks.images.write_png`); None: none
    outputs: dict[str, Any] = field(default_factory=dict)
    cache: dict[Any, Any] = field(default_factory=dict)

    @property
    def seed(self) -> int:
        return int(self.budget.seed)

    def examples(self, key: str) -> int:
        return int(self.budget.examples[key])

    def call(self, *args: Any, label: str = "", derived: bool = False) -> CallResult:
        """The judged function on `args` (`sandbox.MESHES` stands for the domain's meshes).

        Args:
            derived: the arguments are a case already sent, reordered or moved (for an
                invariance property): `interface.fast_enough` does not count the call's time.
        """
        if derived:
            self.draft.timings.mark_derived(args)
        return self.draft(*args, label=label)


# -- interface checks ---------------------------------------------------------------------------


def check_import(function: str, load: CallResult, load_budget: float) -> CheckResult:
    r = CheckResult(name="interface.import", category="interface", examples=1)
    if load.ok:
        return r
    if load.timed_out:
        return r.fail(
            f"the module did not finish importing within {load_budget:g} s (work at import "
            "time counts; keep it small)"
        )
    r.status = "error"
    r.message = f"the module does not import: {load.describe()}"
    r.traceback = load.traceback
    return r


def check_signature(function: str, described: CallResult) -> CheckResult:
    """The draft defines the function with the contract's signature."""
    want = SIGNATURES[function].params
    r = CheckResult(
        name="interface.signature",
        category="interface",
        expected=f"def {function}({', '.join(want)})",
        examples=1,
    )
    info = described.value if described.ok and isinstance(described.value, dict) else None
    if info is None:
        return r.fail(f"the module's `{function}` could not be inspected: {described.describe()}")
    if info.get("callable") is not True:
        functions = [str(f) for f in info.get("functions") or []][:20]
        return r.fail(
            f"the module defines no function `{function}`",
            actual=f"public functions: {', '.join(functions) or '(none)'}",
        )
    params = info.get("params")
    if params is None:
        return r  # a builtin or C function: nothing to compare
    try:
        positional = [
            p for p in params if p["kind"] in ("POSITIONAL_ONLY", "POSITIONAL_OR_KEYWORD")
        ]
        names = tuple(str(p["name"]) for p in positional[: len(want)])
        extra = [p["name"] for p in positional[len(want) :] if not p["default"]]
        kwonly = [p["name"] for p in params if p["kind"] == "KEYWORD_ONLY" and not p["default"]]
    except (KeyError, TypeError):
        return r.fail(f"the module's `{function}` could not be inspected")
    if names != want or extra or kwonly:
        shown = ", ".join(str(p.get("name")) for p in params if isinstance(p, dict))
        return r.fail(
            f"`{function}` must take exactly ({', '.join(want)}) (further parameters need "
            "defaults)",
            actual=f"def {function}({shown})",
        )
    return r


def check_runs(draft: DraftCalls) -> CheckResult:
    """No call killed the draft's process (a crash, running out of memory)."""
    r = CheckResult(name="interface.runs", category="interface", examples=draft.calls)
    dead = [(label, c) for label, c in draft.failures if c.verdict in ("crashed", "oom")]
    if dead:
        label, c = dead[0]
        r.status = "error"
        r.message = f"the process running the function died on {label}: it {c.describe()}"
    return r


def check_in_time(function: str, draft: DraftCalls) -> CheckResult:
    """Every call returned within the per-call budget (enforced outside the draft)."""
    r = CheckResult(
        name="interface.returns_in_time",
        category="interface",
        expected=f"every call returns within {draft.budget:g} s",
        examples=draft.calls,
    )
    late = [label for label, c in draft.failures if c.timed_out]
    if late:
        r.fail(
            f"a call of `{function}` did not return within {draft.budget:g} s, on {late[0]}; "
            "later calls were not run",
            actual=f"{len(late)} timeout(s)",
        )
    return r


def check_fast_enough(
    function: str, draft: DraftCalls, budget: float, wall_factor: float = WALL_FACTOR
) -> CheckResult:
    """The function's calls on inputs new to its session keep, in the median, within its
    online budget of CPU time and `wall_factor` times it of wall time (`checks.timing`).

    Only the first call on each input counts: the checks repeat inputs (determinism, shared
    cases) and a draft may remember answers, but online every scene is new. CPU time is what
    a call needs on one core whatever else the machine does; wall time is bounded too, less
    the time the call waited for a CPU (a busy machine's share), so that a call that sleeps
    or blocks is not free.
    """
    wall_budget = wall_factor * budget
    r = CheckResult(
        name="interface.fast_enough",
        category="interface",
        expected=f"over the calls on inputs new to the session: median CPU time per call <= "
        f"{budget:g} s (the online budget of `{function}`) and median wall time, less the "
        f"wait for a CPU, <= {wall_factor:g} x {budget:g} s = {wall_budget:.3g} s",
    )
    speed = draft.timings.speed()
    if speed is None:
        r.status, r.message = "skipped", "skipped: no call of the function returned"
        return r
    r.examples = speed.fresh
    r.metrics = {
        "median_s": speed.cpu_median_s,
        "max_s": speed.cpu_max_s,
        "wall_median_s": speed.wall_median_s,
        "wall_max_s": speed.wall_max_s,
        "wall_ready_median_s": speed.ready_median_s,
        "wall_ready_max_s": speed.ready_max_s,
        "calls": float(speed.fresh),
        "calls_not_counted": float(speed.calls - speed.fresh),
    }
    counted = f"the median of {speed.fresh} calls on inputs new to it"
    if speed.cpu_median_s > budget:
        r.fail(
            f"`{function}` takes {speed.cpu_median_s:.3f} s of CPU per call ({counted}; slowest "
            f"{speed.cpu_max_s:.3f} s on {speed.cpu_max_label}), over its online budget of "
            f"{budget:g} s",
            actual=f"median {speed.cpu_median_s:.3f} s of CPU",
        )
    elif speed.ready_median_s > wall_budget:
        r.fail(
            f"`{function}` takes {speed.cpu_median_s:.3f} s of CPU per call but a median "
            f"{speed.ready_median_s:.3f} s of wall time not spent waiting for a CPU ({counted}; "
            f"slowest {speed.ready_max_s:.3f} s on {speed.ready_max_label}), over "
            f"{wall_factor:g} times its online budget of {budget:g} s: time spent sleeping or "
            "blocked counts too",
            actual=f"median {speed.ready_median_s:.3f} s of wall time",
        )
    return r
