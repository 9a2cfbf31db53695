"""Scoring: errors modulo symmetry, MSSD, state accuracy, final success."""

from __future__ import annotations

import numpy as np
import pytest

import domains
from contracts.se3 import rotation_about as rotation
from sim.score import final_success, object_error, object_errors, state_accuracy


def _moved(pose, dx=0.0, dy=0.0, dz=0.0, yaw=0.0):
    out = np.asarray(pose, float).copy()
    r = np.eye(4)
    r[:3, :3] = rotation([0, 0, 1], yaw)
    out = out @ r
    out[:3, 3] += (dx, dy, dz)
    return out


@pytest.fixture(scope="module", params=domains.names())
def reference(request):
    d = domains.load(request.param)
    return d, d.benchmark()[0]


def test_truth_scores_perfectly(reference):
    d, inst = reference
    s = state_accuracy(d, {"objects": inst.goal["objects"], "relations": {}}, inst.goal)
    assert s.correct and s.relations_correct and not s.missing and not s.extra
    assert all(e.translation < 1e-9 and e.mssd < 1e-9 for e in s.objects)


def test_symmetric_equivalents_are_correct(reference):
    d, inst = reference
    recs = []
    for r in inst.goal["objects"]:
        sym = d.symmetries(r["mesh"])
        recs.append({**r, "pose": r["pose"] @ sym[-1]})
    s = state_accuracy(d, recs, inst.goal)
    assert s.correct
    assert max(e.mssd for e in s.objects) < 1e-6


def test_a_pose_outside_tolerance_fails(reference):
    d, inst = reference
    recs = [dict(r) for r in inst.goal["objects"]]
    # move an object that nothing rests on, so only its pose is wrong
    top = max(range(len(recs)), key=lambda k: recs[k]["pose"][2, 3])
    recs[top] = {**recs[top], "pose": _moved(recs[top]["pose"], dx=1.5 * d.tolerance.translation)}
    s = state_accuracy(d, recs, inst.goal)
    assert not s.correct
    bad = [e for e in s.objects if not e.within]
    assert [e.id for e in bad] == [recs[top]["id"]]
    assert np.isclose(bad[0].translation, 1.5 * d.tolerance.translation)
    assert bad[0].mssd >= bad[0].translation - 1e-9


def test_rotation_tolerance():
    for name in ("tangram", "assembly"):
        d = domains.load(name)
        r = d.benchmark()[0].goal["objects"][0]
        tol = d.tolerance.rotation
        small = object_error(d, r["mesh"], _moved(r["pose"], yaw=0.8 * tol), r["pose"])
        large = object_error(d, r["mesh"], _moved(r["pose"], yaw=1.5 * tol), r["pose"])
        assert small.within and not large.within
        assert np.isclose(large.rotation, 1.5 * tol, atol=1e-6)


def test_cube_orientation_is_not_scored():
    d = domains.load("cubes")
    r = d.benchmark()[0].goal["objects"][0]
    e = object_error(d, r["mesh"], _moved(r["pose"], yaw=0.3), r["pose"])
    assert e.within and e.translation < 1e-9


def test_missing_and_extra_objects(reference):
    d, inst = reference
    recs = list(inst.goal["objects"][1:])
    s = state_accuracy(d, recs, inst.goal)
    assert not s.correct and s.missing == [inst.goal["objects"][0]["id"]]
    assert len(object_errors(d, recs, inst.goal)) == len(recs)


def test_relation_mismatch_is_reported():
    d = domains.load("cubes")
    goal = d.benchmark()[0].goal  # a pyramid: lifting a base cube by 8 mm breaks 'on' edges
    recs = [dict(r) for r in goal["objects"]]
    recs[0] = {**recs[0], "pose": _moved(recs[0]["pose"], dz=-0.009)}
    s = state_accuracy(d, recs, goal)
    assert s.objects[0].within and not s.relations_correct and not s.correct


def test_final_success(reference):
    d, inst = reference
    ok = final_success(d, inst.goal, inst.goal)
    assert ok.success and ok.at_rest and ok.released
    assert not final_success(d, inst.goal, inst.goal, released=False).success
    assert not final_success(d, inst.start, inst.goal).success
