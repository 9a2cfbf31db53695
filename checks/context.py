"""What a check suite works with: the domain as the checks see it, the cases, the draft's calls.

Design rule: everything here lives in the judge's process (the host). The draft is reachable
only through `DraftCalls` (its sandbox session); the domain's ground truth — true scenes, the
simulator's images, reference relations — is in `cases` and `DomainSpec` and never crosses to
the draft, which receives only each call's arguments (observations, records, states, cameras,
meshes).
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from checks.budget import Budget
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

    def call(self, *args: Any, label: str = "") -> CallResult:
        """The judged function on `args` (`sandbox.MESHES` stands for the domain's meshes)."""
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


def check_fast_enough(function: str, draft: DraftCalls, budget: float) -> CheckResult:
    """The median CPU time of the function's calls over the suite stays within its online
    budget (CPU time: what a call needs on one core, not what a busy machine makes of it)."""
    times = [s for _, s in draft.seconds]
    r = CheckResult(
        name="interface.fast_enough",
        category="interface",
        expected=f"median CPU time per call <= {budget:g} s (the online budget of `{function}`)",
        examples=len(times),
    )
    if not times:
        r.status, r.message = "skipped", "skipped: no call of the function returned"
        return r
    median = statistics.median(times)
    slowest = max(draft.seconds, key=lambda t: t[1])
    r.metrics = {
        "median_s": median,
        "max_s": slowest[1],
        "calls": float(len(times)),
    }
    if median > budget:
        r.fail(
            f"`{function}` takes {median:.3f} s of CPU per call (median of {len(times)} calls; "
            f"slowest {slowest[1]:.3f} s on {slowest[0]}), over its online budget of {budget:g} s",
            actual=f"median {median:.3f} s",
        )
    return r
