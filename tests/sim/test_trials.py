"""Trials end to end in MuJoCo: the oracle succeeds; bad plans end a trial with a clear
execution failure naming the step, and the harness goes on."""

from __future__ import annotations

import numpy as np
import pytest

import domains
from experiments.evaluation import EvalConfig, run_eval, table
from sim.settle import physical_problems
from sim.trials import OraclePolicy, PolicyOutput, run_trial

pytestmark = pytest.mark.slow


class FixedPlan:
    """A test policy that writes its plan from the instance's ground truth, as the oracle does
    (so the executor's belief is the true start poses)."""

    name = "fixed"
    oracle = True

    def __init__(self, make):
        self.make = make

    def solve_from_truth(self, instance, domain=None):
        return PolicyOutput(plan=self.make(instance), start_state=None, goal_state=None)


def _first(instance):
    s = instance.order[0]
    return s["object"], np.asarray(s["target_pose"], float)


BAD_PLANS = {
    "unknown_object": lambda i: {
        "status": "ok",
        "steps": [{"object": "magenta", "target_pose": _first(i)[1]}],
    },
    "non_rigid_target": lambda i: {
        "status": "ok",
        "steps": [
            {"object": _first(i)[0], "target_pose": np.diag([1.0, 1.0, -1.0, 1.0]) @ _first(i)[1]}
        ],
    },
    "unreachable": lambda i: {
        "status": "ok",
        "steps": [
            {
                "object": _first(i)[0],
                "target_pose": np.eye(4) + np.array([[0, 0, 0, 2.5]] + [[0] * 4] * 3),
            }
        ],
    },
}


@pytest.fixture(scope="module")
def cubes():
    d = domains.load("cubes")
    return d, d.benchmark_instance(1, 1, physics=physical_problems)


def test_oracle_trial_succeeds_with_precise_placements(cubes):
    domain, instance = cubes
    r = run_trial(domain, instance, OraclePolicy())
    assert r.final_ok and r.plan_ok and r.state_ok, r.failure
    errors = [s["position_error"] for s in r.steps]
    assert len(errors) == len(instance.order)
    assert np.median(errors) < 0.003
    assert r.timings["execute_sim"] > 0


@pytest.mark.parametrize("kind", sorted(BAD_PLANS))
def test_bad_plan_is_a_clear_execution_failure(cubes, kind):
    domain, instance = cubes
    r = run_trial(domain, instance, FixedPlan(BAD_PLANS[kind]))
    assert not r.final_ok and not r.plan_ok
    assert r.execution_failure is not None
    assert r.execution_failure["step"] == 0
    expected = {"unknown_object": "unknown_object", "non_rigid_target": "non_rigid_target"}.get(
        kind
    )
    if expected:
        assert r.execution_failure["kind"] == expected
    assert r.execution_failure["reason"]


def test_a_plan_that_stops_short_says_so_without_naming_a_non_object(cubes):
    domain, instance = cubes
    assert len(instance.order) > 1
    short = FixedPlan(lambda i: {"status": "ok", "steps": [dict(i.order[0])]})
    r = run_trial(domain, instance, short)
    assert not r.plan_ok
    assert r.plan_failure.startswith("the plan does not reach the goal: "), r.plan_failure


def test_harness_goes_on_after_failures(cubes):
    _, instance = cubes
    bad = FixedPlan(BAD_PLANS["unknown_object"])
    config = EvalConfig(domain="cubes", policy=("oracle", None))
    from experiments import evaluation

    evaluation._init_worker(config)
    evaluation._WORKER["policy"] = bad
    results = [evaluation._run_one(instance.to_dict()) for _ in range(2)]
    summary = evaluation.summarise(config, results)
    assert summary["trials"] == 2 and summary["final_sr"] == 0.0
    assert summary["failures"] == {"planning": 2}
    assert "magenta" in table(summary)


def test_run_eval_reports_metrics(cubes):
    _, instance = cubes
    summary = run_eval(EvalConfig(domain="cubes", policy=("oracle", None)), [instance.to_dict()])
    assert (summary["state_ac"], summary["plan_sr"], summary["final_sr"]) == (1.0, 1.0, 1.0)
    assert summary["precision"]["median_position_error_mm"] < 3.0
    assert set(summary) >= {"domain", "trials", "state_ac", "plan_sr", "final_sr", "per_trial"}


def test_record_writes_a_video_and_the_three_images(cubes, tmp_path):
    from PIL import Image

    from sim.executor import ExecutorConfig

    domain, instance = cubes
    oid, target = _first(instance)
    plan = {"status": "ok", "steps": [{"object": oid, "target_pose": target.tolist()}]}
    r = run_trial(
        domain,
        instance,
        FixedPlan(lambda i: plan),
        record_dir=tmp_path,
        config=ExecutorConfig(record_fps=4.0),  # few frames: this tests the recording only
    )
    assert r.steps and r.execution_failure is None, r.failure
    for name in ("start.png", "goal.png", "final.png"):
        with Image.open(tmp_path / name) as image:
            assert image.size[0] > 0
    video = (tmp_path / "trial.mp4").read_bytes()
    assert video[4:8] == b"ftyp" and len(video) > 10_000  # an MP4 container with frames in it

    # trial.json replays the trial without running it: the final state scores as the trial did
    import json

    from sim.score import final_success

    doc = json.loads((tmp_path / "trial.json").read_text())
    assert [p["label"] for p in doc["poses"]] == [f"{oid} placed", "end"]
    assert doc["plan"]["steps"][0]["object"] == oid and doc["result"] == r.to_dict()
    assert doc["truth"]["goal"]["objects"] and doc["observation_seeds"]["start"] > 0
    end = doc["poses"][-1]
    scene = {
        "domain": "cubes",
        "objects": [
            {"id": o["id"], "mesh": o["mesh"], "pose": end["objects"][o["id"]]}
            for o in instance.start["objects"]
        ],
    }
    replayed = final_success(domain, scene, instance.goal)
    assert [e.within for e in replayed.objects] == [e["within"] for e in r.object_errors]


class PerceivedWrong:
    """A policy that perceives the truth except for one object, shifted by `shift` metres, and
    plans the reference order: what a perception error of that size does to a trial."""

    name = "perceived-wrong"
    oracle = False

    def __init__(self, instance, shift):
        self.instance, self.shift = instance, np.asarray(shift, float)

    def solve(self, domain, start_obs, goal_obs):
        start = {"objects": [dict(o) for o in self.instance.start["objects"]], "relations": []}
        moved = start["objects"][
            [o["id"] for o in start["objects"]].index(self.instance.order[0]["object"])
        ]
        moved["pose"] = np.asarray(moved["pose"], float) + np.pad(
            self.shift[:, None], ((0, 1), (3, 0))
        )
        steps = [
            {"object": s["object"], "target_pose": s["target_pose"]} for s in self.instance.order
        ]
        return PolicyOutput(
            plan={"status": "ok", "steps": steps},
            start_state=start,
            goal_state={"objects": self.instance.goal["objects"], "relations": []},
        )


@pytest.mark.parametrize("track", [False, True], ids=["honest", "ground-truth-tracker"])
def test_the_executor_grasps_where_perception_says(cubes, track):
    # perception put the first object 3 cm off: under the honest protocol the grasp misses (the
    # executor acts on the perceived start state); the ground-truth tracker, a protocol option,
    # hides the error
    from dataclasses import replace

    from sim.trials import HONEST

    domain, instance = cubes
    policy = PerceivedWrong(instance, [0.0, 0.03, 0.0])
    r = run_trial(domain, instance, policy, protocol=replace(HONEST, track_objects=track))
    assert not r.state_ok and r.failure["stage"] == "perception"  # the first stage that failed
    if track:
        assert r.final_ok and r.execution_failure is None, r.execution_failure
    else:
        assert not r.final_ok
        assert r.execution_failure is not None and r.execution_failure["step"] == 0
        assert r.execution_failure["kind"] in {"grasp_failed", "dropped"}


def test_the_oracle_opens_tangram_gaps_and_leaves_stacks_alone():
    tangram = domains.load("tangram")
    inst = tangram.benchmark()[0]
    plain = OraclePolicy().solve_from_truth(inst).plan["steps"]
    spread = OraclePolicy().solve_from_truth(inst, tangram).plan["steps"]
    moved = [
        np.asarray(b["target_pose"])[:3, 3] - np.asarray(a["target_pose"])[:3, 3]
        for a, b in zip(plain, spread, strict=True)
    ]
    _, shift = tangram.placement_spread
    assert max(np.linalg.norm(m) for m in moved) <= shift + 1e-6  # within the scoring tolerance
    assert max(np.linalg.norm(m) for m in moved) > 1e-4  # the benchmark's pieces touch
    assert all(abs(m[2]) < 1e-12 for m in moved)  # flat: only sideways
    for a, b in zip(plain, spread, strict=True):  # no turn
        assert np.allclose(
            np.asarray(a["target_pose"])[:3, :3], np.asarray(b["target_pose"])[:3, :3]
        )

    cubes = domains.load("cubes")
    inst = cubes.benchmark()[0]
    same = OraclePolicy().solve_from_truth(inst, cubes).plan["steps"]
    for a, b in zip(OraclePolicy().solve_from_truth(inst).plan["steps"], same, strict=True):
        assert np.array_equal(np.asarray(a["target_pose"]), np.asarray(b["target_pose"]))


def test_the_oracle_spreads_every_goal_place_even_a_symmetric_one():
    """A reference step may put a piece at a symmetric equivalent of its goal pose (the square
    turned a quarter); it is a goal place too and must get the spread, or it is aimed into a
    pocket its spread neighbours have narrowed (dev goal04_start1: 0.26 mm left)."""
    from toolbox.packing import footprint, polygon_gap

    tangram = domains.load("tangram")
    gap, _ = tangram.placement_spread
    turned = 0
    for inst in tangram.benchmark()[::3]:  # one start per goal
        goal = {r["id"]: r for r in inst.goal["objects"]}
        steps = OraclePolicy().solve_from_truth(inst, tangram).plan["steps"]
        final = {s["object"]: np.asarray(s["target_pose"], dtype=float) for s in steps}
        for s in inst.order:  # goal places given as a symmetric equivalent of the goal pose
            T, G = np.asarray(s["target_pose"]), np.asarray(goal[s["object"]]["pose"])
            turned += bool(np.allclose(T[:3, 3], G[:3, 3]) and not np.allclose(T, G))
        outline = {oid: footprint(tangram.mesh(goal[oid]["mesh"]), T) for oid, T in final.items()}
        ids = sorted(outline)
        for k, a in enumerate(ids):
            for b in ids[k + 1 :]:
                g, _ = polygon_gap(outline[a], outline[b])
                assert g > gap - 2e-4, (inst.name, a, b, g)
    assert turned > 0  # the case this test is about occurs in the benchmark
