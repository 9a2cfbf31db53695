"""Scoring against ground truth: per-object errors, state accuracy, final success.

- Per-object errors: translation and rotation error modulo the mesh's symmetry group, and
  MSSD (BOP's maximum symmetry-aware surface distance over the mesh vertices).
- State accuracy of a perceived state: every object of the true scene is perceived, each
  pose is within the domain's tolerance modulo symmetry, and the domain's reference relation
  function gives the same graph on the perceived records as on the true ones. The reference
  function is applied to both sides, so the generated `relate`'s own vocabulary never needs
  to match ours.
- Final success of an executed scene: every object within tolerance of its goal pose modulo
  symmetry, released by the gripper, and at rest (simulated without the robot for 2 s, no
  point moves more than 2 mm).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from contracts import se3
from domains import Domain


@dataclass(frozen=True, kw_only=True)
class ObjectError:
    """Errors of one object's estimated pose against its true pose."""

    id: str
    translation: float  # [m], of the symmetric alternative closest in rotation
    rotation: float  # [rad]
    mssd: float  # [m]
    within: bool  # inside the domain's tolerance for some symmetric alternative

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "translation_m": self.translation,
            "rotation_deg": float(np.degrees(self.rotation)),
            "mssd_m": self.mssd,
            "within": self.within,
        }


@dataclass(frozen=True, kw_only=True)
class StateScore:
    """State accuracy of one perceived state."""

    correct: bool
    objects: list[ObjectError]
    missing: list[str]  # true objects not perceived
    extra: list[str]  # perceived ids not in the true scene
    relations_correct: bool
    missing_edges: list[tuple[str, str, str]] = field(default_factory=list)
    extra_edges: list[tuple[str, str, str]] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "correct": self.correct,
            "objects": [o.to_dict() for o in self.objects],
            "missing": self.missing,
            "extra": self.extra,
            "relations_correct": self.relations_correct,
            "missing_edges": [list(e) for e in self.missing_edges],
            "extra_edges": [list(e) for e in self.extra_edges],
        }


@dataclass(frozen=True, kw_only=True)
class FinalScore:
    """Final success of one executed scene."""

    success: bool
    objects: list[ObjectError]
    released: bool
    at_rest: bool
    motion: dict[str, float]  # displacement while checking rest [m]

    def to_dict(self) -> dict:
        return {
            "success": self.success,
            "objects": [o.to_dict() for o in self.objects],
            "released": self.released,
            "at_rest": self.at_rest,
            "motion_m": self.motion,
        }


def records_of(value: Any) -> list[Mapping]:
    """Records from a scene, a state ``{"objects", "relations"}`` or a list of records."""
    if isinstance(value, Mapping):
        return list(value["objects"])
    return list(value)


def object_error(
    domain: Domain, mesh: str, estimate: Any, truth: Any, *, object_id: str = ""
) -> ObjectError:
    """Errors of pose `estimate` against `truth` (both (4, 4)) for an object with `mesh`."""
    sym = list(domain.symmetries(mesh))
    est, gt = np.asarray(estimate, float), np.asarray(truth, float)
    tol = domain.tolerance
    if tol.rotation is None:  # orientation not scored: the closest alternative by translation
        t = min(float(np.linalg.norm(est[:3, 3] - (gt @ s)[:3, 3])) for s in sym)
        r = se3.pose_error(est, gt, sym)[1]
    else:
        t, r = se3.pose_error(est, gt, sym)
    within = se3.within_tolerance(
        est, gt, trans_tol=tol.translation, rot_tol=tol.rotation, symmetries=sym
    )
    vertices = np.asarray(domain.mesh(mesh).vertices)
    return ObjectError(
        id=object_id,
        translation=t,
        rotation=r,
        mssd=se3.mssd(est, gt, vertices, sym),
        within=within,
    )


def pose_within(domain: Domain, estimate: Any, truth: Any, mesh: str) -> bool:
    """Whether `estimate` is within the domain's tolerance of `truth`, modulo symmetry."""
    return se3.within_tolerance(
        np.asarray(estimate, float),
        np.asarray(truth, float),
        trans_tol=domain.tolerance.translation,
        rot_tol=domain.tolerance.rotation,
        symmetries=list(domain.symmetries(mesh)),
    )


def object_errors(domain: Domain, estimate: Any, truth: Any) -> list[ObjectError]:
    """Per-object errors of the estimated records against the true ones, matched by id.

    Objects missing from `estimate` are left out (see `state_accuracy` for them).
    """
    est = {r["id"]: r for r in records_of(estimate)}
    out = []
    for t in records_of(truth):
        if t["id"] in est:
            out.append(
                object_error(domain, t["mesh"], est[t["id"]]["pose"], t["pose"], object_id=t["id"])
            )
    return out


def reference_edges(domain: Domain, records: Any) -> set[tuple[str, str, str]]:
    """The domain's reference relations of `records` as (source, target, type) triples."""
    graph = domain.reference_relations(records)
    return {(str(e["source"]), str(e["target"]), str(e.get("type", ""))) for e in graph["edges"]}


def state_accuracy(domain: Domain, perceived: Any, truth: Any) -> StateScore:
    """State accuracy of a perceived state (or records) against the true scene."""
    est = records_of(perceived)
    true = records_of(truth)
    ids = {r["id"] for r in true}
    est_ids = [r["id"] for r in est]
    missing = sorted(ids - set(est_ids))
    extra = sorted(set(est_ids) - ids) + sorted({i for i in est_ids if est_ids.count(i) > 1})
    errors = object_errors(domain, est, true)
    valid_est = [r for r in est if r["id"] in ids and r["mesh"] == domain.object(r["id"]).mesh]
    if len(valid_est) != len(est):
        extra += sorted({r["id"] for r in est if r not in valid_est and r["id"] in ids})
    g_true = reference_edges(domain, true)
    g_est = reference_edges(domain, valid_est) if valid_est else set()
    rel_ok = g_true == g_est
    correct = not missing and not extra and rel_ok and all(e.within for e in errors)
    return StateScore(
        correct=correct,
        objects=errors,
        missing=missing,
        extra=extra,
        relations_correct=rel_ok,
        missing_edges=sorted(g_true - g_est),
        extra_edges=sorted(g_est - g_true),
    )


def final_success(
    domain: Domain, final: Any, goal: Any, *, released: bool = True, check_rest: bool = True
) -> FinalScore:
    """Final success of an executed scene against the goal scene.

    Args:
        final: the scene (or records) after execution, object poses from the simulator.
        released: whether the gripper let go of every object (the executor knows).
        check_rest: simulate the final poses without the robot and require them at rest.
    """
    from sim.settle import MOTION, settle

    recs = records_of(final)
    errors = object_errors(domain, recs, goal)
    motion: dict[str, float] = {}
    at_rest = True
    if check_rest:
        result = settle(domain, {"domain": domain.name, "objects": recs})
        motion = result.motion
        at_rest = all(m <= MOTION for m in motion.values())
    complete = {e.id for e in errors} == {r["id"] for r in records_of(goal)}
    success = complete and released and at_rest and all(e.within for e in errors)
    return FinalScore(
        success=success, objects=errors, released=released, at_rest=at_rest, motion=motion
    )


def summary(scores: Sequence[StateScore | FinalScore]) -> float:
    """Fraction of correct states / successful finals."""
    if not scores:
        return 0.0
    ok = [s.correct if isinstance(s, StateScore) else s.success for s in scores]
    return float(np.mean(ok))


__all__ = [
    "FinalScore",
    "ObjectError",
    "StateScore",
    "final_success",
    "object_error",
    "object_errors",
    "pose_within",
    "state_accuracy",
    "summary",
]
