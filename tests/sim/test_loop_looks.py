"""`benchmarks.loop_looks`: the scenes a closed loop looks at, each read twice and scored."""

from __future__ import annotations

import numpy as np

import domains
from benchmarks.loop_looks import misreads, scenes_of
from contracts import se3


def test_the_scenes_run_from_the_start_to_the_goal():
    dom = domains.load("cubes")
    inst = dom.benchmark("dev")[0]
    scenes = scenes_of(inst)
    assert len(scenes) == len(inst.order) + 1
    poses = lambda scene: {o["id"]: o["pose"] for o in scene["objects"]}  # noqa: E731
    start, end = poses(scenes[0]), poses(scenes[-1])
    for o in inst.start["objects"]:
        assert np.allclose(start[o["id"]], o["pose"])
    for o in inst.goal["objects"]:
        t, _ = se3.pose_error(end[o["id"]], np.asarray(o["pose"], float))
        assert t < 1e-6, o["id"]


def test_a_perceive_that_sees_nothing_is_wrong_on_every_look():
    dom = domains.load("cubes")
    inst = dom.benchmark("dev")[0]
    blind = "def perceive(observation, meshes, camera):\n    return []\n"
    rows, totals = misreads("cubes", {"perceive": blind}, "front", [inst])
    n = len(inst.order) + 1
    assert totals == {"scenes": n, "looks": 2 * n, "looks_wrong": 2 * n, "scenes_wrong_twice": n}
    assert {(r["scene"], r["look"]) for r in rows} == {
        (k, look) for k in range(n) for look in (0, 1)
    }
    assert all(sorted(r["missing"]) == sorted(o["id"] for o in inst.start["objects"]) for r in rows)
