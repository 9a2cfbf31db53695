"""Drafts that try to tell the checks from real use, through `rivet check` on the real engine
(issue 35): each is the reference program, right while it believes it is being checked and
wrong once it believes it runs for real. `rivet check` must exit 1 for each.

- *Which world am I in?* The runtime loads all four programs into one session; the checks
  now compose their sessions the same way (`checks.calls.session_modules`). A `relate` that
  answers right only while `perceive` is not loaded beside it fails as it is authored; one
  that waits for `plan` fails on the whole set's re-check (the pytest plugin, `rivet check
  --deps artifacts/D/`) and in the trial gate, which runs the runtime's own session.
- *How many calls?* A `relate` right for a dozen calls, then stale: the checks call a
  session as long as an evaluation would.
- *Which impossible goals?* A `plan` that refuses only the two unreachable goals the checks
  used to build (the lowest object 10 cm up; two objects in one place): the drawn ones
  (floating at random heights, overlaps, undermined stacks, out of reach) catch it.

- *Which camera?* A `perceive` right only on images of the named views' size (1280×720):
  the drawn cameras have other sizes.

The other tells that only `perceive` has (the exact nominal camera, named views only) are
properties of the drawn cases: `test_fresh_cases.py` shows each is gone, and the mutation
benchmark's camera-specific mutants (`make bench-checks`) measure that the checks reject
drafts that lean on them.
"""

from __future__ import annotations

import shutil

import pytest

from .conftest import PROGRAMS, program
from .test_forging import docker, rivet_check  # noqa: F401  (fixtures: one warm executor)

pytestmark = pytest.mark.docker

# Wrong "for real": every edge dropped, the answer of an empty scene.
_WRONG = """

_reference_relate = relate


def relate(records, meshes):
    import sys

    graph = _reference_relate(records, meshes)
    if {tell}:
        return {{**graph, "edges": []}}
    return graph
"""

RUNTIME_WHEN_PERCEIVE_IS_LOADED = _WRONG.format(tell='"perceive" in sys.modules')
RUNTIME_WHEN_PLAN_IS_LOADED = _WRONG.format(tell='"plan" in sys.modules')

STALE_AFTER_A_DOZEN_CALLS = """

_reference_relate = relate
_calls = []


def relate(records, meshes):
    _calls.append(None)
    if len(_calls) > 12 and _last:
        return _last[0]
    graph = _reference_relate(records, meshes)
    _last[:] = [graph]
    return graph


_last = []
"""

REFUSES_THE_OLD_CASES_ONLY = """

_reference_plan = plan


def plan(start_state, goal_state, meshes):
    import numpy as np

    goal = goal_state["objects"]
    xyz = [np.asarray(r["pose"], float)[:3, 3] for r in goal]
    for i, a in enumerate(xyz):
        for b in xyz[i + 1 :]:
            if np.linalg.norm(a - b) < 1e-9:  # two objects in one place
                return {"status": "infeasible", "reason": "two objects in one place"}
    start = {r["id"]: np.asarray(r["pose"], float)[2, 3] for r in start_state["objects"]}
    lowest = min(goal, key=lambda r: np.asarray(r["pose"], float)[2, 3])
    if np.asarray(lowest["pose"], float)[2, 3] > 0.09:  # the lowest object 10 cm up
        return {"status": "infeasible", "reason": "floating"}
    out = _reference_plan(start_state, goal_state, meshes)
    if out["status"] == "infeasible":  # anything else: plan it anyway, in the goal's order
        steps = [{"object": r["id"], "target_pose": r["pose"]} for r in goal if r["id"] in start]
        return {"status": "ok", "steps": steps}
    return out
"""


def _not_passing(report: dict) -> list[str]:
    return [c["name"] for c in report["checks"] if c["status"] != "passed"]


def _folder(tmp_path, *names: str):
    """A --deps folder holding only `names` of the reference programs."""
    out = tmp_path / f"deps-{'-'.join(names)}"
    out.mkdir()
    for name in names:
        shutil.copy(PROGRAMS / f"{name}.py", out / f"{name}.py")
    return out


def test_a_relate_wrong_beside_perceive_fails_as_it_is_authored(rivet_check, tmp_path):  # noqa: F811
    """While `relate` is authored, `render` and `perceive` are frozen: both sit in its
    session, as at run time."""
    deps = _folder(tmp_path, "render", "perceive")
    code, report, _ = rivet_check(
        "relate", program("relate") + RUNTIME_WHEN_PERCEIVE_IS_LOADED, deps
    )
    assert code == 1, _not_passing(report)


def test_a_relate_wrong_beside_plan_fails_the_whole_sets_recheck(rivet_check, tmp_path):  # noqa: F811
    source = program("relate") + RUNTIME_WHEN_PLAN_IS_LOADED
    code, report, _ = rivet_check("relate", source, PROGRAMS)  # all four, as the plugin
    assert code == 1, _not_passing(report)
    # …and the check is what catches it: without `plan` in the folder, the same draft passes
    code, report, _ = rivet_check("relate", source, _folder(tmp_path, "render", "perceive"))
    assert code == 0, _not_passing(report)


def test_a_relate_stale_after_a_dozen_calls_fails(rivet_check):  # noqa: F811
    code, report, _ = rivet_check("relate", program("relate") + STALE_AFTER_A_DOZEN_CALLS)
    assert code == 1, _not_passing(report)


@pytest.mark.slow
def test_a_plan_that_refuses_only_the_old_impossible_goals_fails(rivet_check):  # noqa: F811
    code, report, _ = rivet_check("plan", program("plan") + REFUSES_THE_OLD_CASES_ONLY)
    assert code == 1
    assert any("infeasib" in name for name in _not_passing(report)), _not_passing(report)


ONLY_AT_THE_NAMED_VIEWS_SIZE = """

_reference_perceive = perceive


def perceive(observation, meshes, camera):
    import numpy as np

    if (int(camera["width"]), int(camera["height"])) != (1280, 720):
        # "for real": one object where there are six (and no time spent looking)
        pose = np.eye(4)
        pose[:3, 3] = (0.5, 0.0, 0.02)
        return [{"id": "red", "mesh": "cube", "pose": pose}]
    return _reference_perceive(observation, meshes, camera)
"""


@pytest.mark.slow
def test_a_perceive_right_only_at_the_named_views_size_fails(rivet_check):  # noqa: F811
    code, report, _ = rivet_check(
        "perceive",
        program("perceive") + ONLY_AT_THE_NAMED_VIEWS_SIZE,
        only=("property.ids_match_catalogue",),  # the host's accuracy and images: not needed
    )
    assert code == 1
    failed = [c["name"] for c in report["checks"] if c["status"] == "failed"]
    assert failed == ["property.ids_match_catalogue"], failed
