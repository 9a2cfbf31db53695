"""Drafts that game the speed gate or the pixel properties, through `rivet check` on the real
engine (issue 35): each is the reference program with one trick added, so the check that the
trick targets is the one that fails.

- a `relate` that works for 0.5 s of CPU on every scene it has not seen, remembering scenes in
  any order and wherever they stand: the suite repeats inputs and sends reordered and moved
  copies, so the old gate (the median over every call) saw mostly remembered answers;
- a `relate` that sleeps 0.45 s on every scene new to it: CPU time alone did not see it;
- a `render` whose mask has a hole in every 3×3 block: every object pixel is then within a
  pixel of a silhouette edge, where the pixel properties do not judge, so they judged nothing.
"""

from __future__ import annotations

import pytest

from .conftest import program
from .test_forging import docker, rivet_check  # noqa: F401  (fixtures: one warm executor)

pytestmark = pytest.mark.docker

# a scene's key, wherever it stands and in whatever order its records come
_SCENE_KEY = """

_reference_relate = relate
_seen = set()


def _scene(records):
    import numpy as np

    recs = sorted(records, key=lambda r: r["id"])
    xyz = np.array([np.asarray(r["pose"], float)[:3, 3] for r in recs])
    xyz[:, :2] -= xyz[:, :2].mean(axis=0)  # wherever the scene stands, in whatever order
    return tuple(r["id"] for r in recs), tuple(np.round(xyz, 6).ravel())
"""

REMEMBERS_SCENES = (
    _SCENE_KEY
    + """

def relate(records, meshes):
    import time

    key = _scene(records)
    if key not in _seen:
        t0 = time.process_time()
        while time.process_time() - t0 < 0.5:  # the work a new scene costs
            pass
        _seen.add(key)
    return _reference_relate(records, meshes)
"""
)

SLEEPS = (
    _SCENE_KEY
    + """

def relate(records, meshes):
    import time

    key = _scene(records)
    if key not in _seen:  # every call on a new scene sleeps; the gate counts only those
        time.sleep(0.45)
        _seen.add(key)
    return _reference_relate(records, meshes)
"""
)

HOLEY_MASK = """

_reference_render = render


def render(records, meshes, camera):
    import numpy as np

    out = _reference_render(records, meshes, camera)
    mask = np.array(out["mask"])
    mask[1::3, 1::3] = -1  # a hole in every 3x3 block: every object pixel is an edge pixel
    return {**out, "mask": mask}
"""


def _not_passing(report: dict) -> list[str]:
    return [c["name"] for c in report["checks"] if c["status"] != "passed"]


def _check(report: dict, name: str) -> dict:
    return next(c for c in report["checks"] if c["name"] == name)


def test_a_draft_that_remembers_scenes_fails_the_speed_gate(rivet_check):  # noqa: F811
    code, report, _ = rivet_check("relate", program("relate") + REMEMBERS_SCENES)
    assert code == 1 and _not_passing(report) == ["interface.fast_enough"], _not_passing(report)
    gate = _check(report, "interface.fast_enough")
    assert "s of CPU per call" in gate["message"], gate
    assert gate["metrics"]["median_s"] >= 0.45
    assert gate["metrics"]["calls_not_counted"] > 0  # repeats and moved or reordered copies


def test_a_draft_that_sleeps_fails_the_speed_gate(rivet_check):  # noqa: F811
    code, report, _ = rivet_check("relate", program("relate") + SLEEPS)
    assert code == 1 and _not_passing(report) == ["interface.fast_enough"], _not_passing(report)
    gate = _check(report, "interface.fast_enough")
    assert "wall time" in gate["message"], gate
    assert gate["metrics"]["median_s"] < 0.2 <= gate["metrics"]["wall_median_s"]


def test_a_render_with_a_holey_mask_fails_the_pixel_properties(rivet_check):  # noqa: F811
    code, report, _ = rivet_check("render", program("render") + HOLEY_MASK)
    assert code == 1
    for name in ("property.depth_where_visible", "property.mask_follows_record_order"):
        check = _check(report, name)
        assert check["status"] == "failed", check
        assert "too few pixels" in check["message"], check
