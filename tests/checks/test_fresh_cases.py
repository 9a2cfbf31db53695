"""Check cases are drawn afresh: from a seed, the same seed draws the same cases, each attempt of
an authoring run draws new ones, and nothing the feedback of failing attempts shows identifies
a case a later attempt is checked on (docs/checks.md, "What feedback shows")."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import domains
from checks import report_markdown
from checks.budget import Budget
from checks.inputs import build_cases, case_seed, infeasible_goal, instances, records
from domains.cameras import shows

from .conftest import CASES_SEED, deps_of

SMALL = Budget(name="small", observations=3, hidden=1)

# a perceive that finds the cubes' colours but puts every cube 3 cm off in x: wrong, and it
# prints nothing of its inputs but what the checks' feedback reflects back
SHIFTED = """
import numpy as np

from toolbox.errors import ToolboxError

_IDS = ("red", "green", "blue", "yellow", "purple", "cyan")


def perceive(observation, meshes, camera):
    out = []
    for k, oid in enumerate(_IDS):
        pose = np.eye(4)
        pose[:3, 3] = (0.40 + 0.05 * k, 0.03 * k - 0.08, 0.02)
        out.append({"id": oid, "mesh": "cube", "pose": pose})
    return out
"""


def _truth_xy(cases: dict) -> set[tuple[float, float]]:
    return {
        (round(float(r["pose"][0, 3]), 4), round(float(r["pose"][1, 3]), 4))
        for case in cases["observations"]
        for r in case["truth"]
    }


def _numbers(text: str) -> set[float]:
    return {round(float(x), 4) for x in re.findall(r"-?\d+\.\d+", text)}


def test_the_same_seed_draws_the_same_cases_and_attempts_draw_new_ones():
    dom = domains.load("cubes")
    a = build_cases(dom, "perceive", SMALL, seed=5)
    b = build_cases(dom, "perceive", SMALL, seed=5)
    assert [c["name"] for c in a["observations"]] == [c["name"] for c in b["observations"]]
    for x, y in zip(a["observations"], b["observations"], strict=True):
        assert np.array_equal(x["observation"]["rgb"], y["observation"]["rgb"])
        np.testing.assert_array_equal(x["camera"]["T_world_camera"], y["camera"]["T_world_camera"])
    seeds = {case_seed(99, "perceive", k) for k in range(1, 12)}
    assert len(seeds) == 11  # a new draw for every attempt
    other = build_cases(dom, "perceive", SMALL, seed=case_seed(99, "perceive", 2))
    assert not _truth_xy(a) & _truth_xy(other)


def test_perceive_is_called_as_the_trials_call_it():
    """The calibrated camera (not the true one), the observation's full resolution, hiding
    cases from the front camera and every other camera showing every object."""
    dom = domains.load("cubes")
    cases = build_cases(dom, "perceive", Budget(name="b", observations=8, hidden=1), seed=8)
    obs = cases["observations"]
    assert len(obs) == 8 and sum("/hidden/" in c["name"] for c in obs) == 1
    for c in obs:
        cam = c["observation"]["camera"]
        assert c["observation"]["rgb"].shape[:2] == (cam["height"], cam["width"])
        true_t = c["reference"]["full"]["camera"]["T_world_camera"]
        assert np.array_equal(cam["T_world_camera"], true_t)  # what the draft gets …
        if "/hidden/" not in c["name"]:
            corners = np.array([r["pose"][:3, 3] for r in c["truth"]])
            # … and the objects are in the frame (their centres, seen by the calibrated camera)
            assert shows(cam, corners, margin=0.0)
    drawn = [c for c in obs if "/drawn-" in c["name"]]
    assert drawn, "no camera drawn from the envelope"
    front = dom.camera("front")["T_world_camera"]
    for c in obs:
        if "/front-" in c["name"] or "/hidden/" in c["name"]:
            # the calibrated camera is off the true one by the trials' calibration error
            offset = np.linalg.norm(c["camera"]["T_world_camera"][:3, 3] - front[:3, 3])
            assert 0.0 < offset < 0.01


@pytest.mark.slow
def test_failing_feedback_never_identifies_a_later_attempts_case(executor, tmp_path):
    """Everything the feedback of 6 failing attempts shows (report JSON and the Markdown the
    model reads; a run makes 4 by default) holds none of the true positions of the next
    attempt's cases — nor of its own cases."""
    from checks import run_checks

    dom = domains.load("cubes")
    shown: set[float] = set()
    for attempt in range(1, 7):
        seed = case_seed(CASES_SEED, "perceive", attempt)
        report = run_checks(
            "cubes",
            "perceive",
            SHIFTED,
            deps=deps_of("perceive"),
            executor=executor,
            out_dir=tmp_path / str(attempt),
            budget=SMALL,
            cases_seed=seed,
        )
        assert not report["passed"] and report["cases_seed"] == seed
        text = json.dumps(report) + report_markdown(report)
        own = build_cases(dom, "perceive", SMALL, seed=seed)
        numbers = _numbers(text)
        mm = {round(v / 1000, 4) for v in numbers}
        for x, y in _truth_xy(own):
            assert not ({x, y} <= numbers or {x, y} <= mm), "a case's true position is shown"
        shown |= numbers | mm
    later = build_cases(dom, "perceive", SMALL, seed=case_seed(CASES_SEED, "perceive", 7))
    for x, y in _truth_xy(later):
        assert not {x, y} <= shown


@pytest.mark.parametrize("kind", ["floating", "overlap", "unsupported", "outside"])
@pytest.mark.parametrize("name", domains.names())
def test_drawn_infeasible_goals_are_what_they_claim(name, kind):
    """Each kind of unreachable goal is drawn with varying amounts and partners, and the oracle
    geometry confirms what it claims (`infeasible_goal`)."""
    from domains.generation import geometric_problems

    dom = domains.load(name)
    rng = np.random.default_rng(4)
    pool = instances(dom, rng, 6)
    got = []
    for inst in pool * 4:
        g = infeasible_goal(dom, [dict(r) for r in inst.goal["objects"]], kind, rng)
        if g is not None:
            got.append(g)
    if kind == "unsupported" and name == "tangram":
        assert not got  # tangram pieces lie flat on the table: nothing to undermine
        return
    assert len(got) >= 2, f"{kind}: no draw in {len(pool) * 4}"
    reasons = {why for _, why in got}
    assert len(reasons) >= 2  # amounts or partners vary
    for goal, why in got:
        problems = geometric_problems(dom, dom.scene(goal))
        if kind == "overlap":
            assert any("penetrates" in p.problem for p in problems), why
        elif kind == "outside":
            assert any("outside" in p.problem for p in problems), why
        else:
            assert not problems, why  # it floats: nothing else is wrong with it
            edges = dom.reference_relations(goal)["edges"]
            assert edges is not None


def test_plan_cases_are_instances_the_checked_robot_can_carry_out():
    """The generator asks a grasp of the hand only; plan's checks also ask the arm to reach it.
    A drawn instance whose own reference order the arm cannot reach would fail every correct
    plan, so plan's cases leave it out (this seed's plain draw holds two, one composed)."""
    from checks.inputs import _rng, composed
    from checks.robot import robot_view

    cubes = domains.load("cubes")
    seed = case_seed(2, "plan", 4)
    reach = robot_view("cubes")

    def unreachable(pool):
        return [
            i.name
            for i in pool
            if reach.first_problem(records(i.start), list(i.order)).step is not None
        ]

    rng = _rng(seed, "plan")
    plain = [*instances(cubes, rng, 8), *composed(cubes, rng, 6)]
    assert unreachable(plain)  # what the filter is for: such draws exist
    rng = _rng(seed, "plan")
    kept = [*instances(cubes, rng, 8, executable=True), *composed(cubes, rng, 6, executable=True)]
    assert len(kept) == 14 and unreachable(kept) == []
    shown = build_cases(cubes, "plan", Budget(name="drawn"), seed)["instances"]
    assert [c["start"][0]["pose"].tolist() for c in shown] == [
        records(i.start)[0]["pose"].tolist() for i in kept
    ]


@pytest.mark.parametrize("name", domains.names())
def test_scene_cases_are_drawn_without_searching_an_order(name, monkeypatch):
    """`perceive`, `relate` and `render` are shown scenes: their generated cases are the
    generator's starts and goals (and `relate`'s composed ones the composer's), drawn with no
    construction order searched (the planners fail here if asked), valid scenes all, and the
    same scenes an ordered draw gives wherever that draw's first start has an order."""
    from checks.inputs import _instance
    from domains.generation import geometric_problems

    dom = domains.load(name)
    ordered = instances(dom, np.random.default_rng(6), 4)
    _instance.cache_clear()  # every draw below is made under the refusing planners

    def refuse(*args, **kwargs):
        raise AssertionError("a construction order was searched for a scene case")

    for planner in (dom.robot_reference_planner, dom.reference_planner):
        monkeypatch.setattr(type(planner), "order", refuse)
    drawn = instances(dom, np.random.default_rng(6), 4, scenes_only=True)
    assert len(drawn) == 4
    for inst in drawn:
        assert inst.order == ()
        for side in (inst.start, inst.goal):
            assert geometric_problems(dom, side) == []
    same = [
        a.seed == b.seed
        and all(
            np.array_equal(x["pose"], y["pose"])
            for x, y in zip(records(a.start), records(b.start), strict=True)
        )
        for a, b in zip(ordered, drawn, strict=True)
    ]
    assert same.count(True) >= 3, same
    small = Budget(name="b", observations=4, hidden=1, instances=3, composed=2)
    assert len(build_cases(dom, "perceive", small, seed=2)["observations"]) == 4
    composed = 2 if dom.composed_goals is not None else 0
    assert len(build_cases(dom, "relate", small, seed=2)["scenes"]) == 2 * (3 + composed)
    rendered = build_cases(dom, "render", small, seed=2)["scenes"]
    assert sum(bool(v.get("image")) for v in rendered) == len(small.render_cases)


def test_perceive_cases_can_be_drawn_through_one_side_of_the_envelope():
    """`perceive_cases(envelope=…)` (`benchmarks.perceive_draws --azimuth`): every camera is
    drawn from that slice of the envelope, none is a named view; a slice outside the domain's
    envelope is refused with its range."""
    import dataclasses
    import math

    from benchmarks.perceive_draws import main
    from checks.inputs import perceive_cases

    dom = domains.load("cubes")
    side = dataclasses.replace(dom.camera_envelope, azimuth=(40.0, 75.0))
    cases = perceive_cases(dom, Budget(name="b", observations=6, hidden=0), 3, envelope=side)
    assert len(cases) == 6
    for case in cases:
        assert case["camera_name"] == "drawn"
        axis = np.asarray(case["render_camera"]["T_world_camera"], float)[:3, 2]  # true camera
        assert 40.0 <= math.degrees(math.atan2(-axis[1], -axis[0])) <= 75.0
    with pytest.raises(SystemExit) as refused:
        main(["--domain", "cubes", "--azimuth", "60", "90"])
    assert refused.value.code == 2
