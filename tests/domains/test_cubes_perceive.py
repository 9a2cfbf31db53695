"""The reference cubes `perceive` on a scene the benchmark never shows: a cube the camera cannot
see at all that holds nothing up (it stands behind a tower). The task text says `perceive`
reports all six cubes; it must still do so, and put the unseen one where the image allows it:
clear of the others and hidden from the camera."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import domains
from sim.observation import observe_with_truth

HALF = 0.02
PERCEIVE = Path(domains.__file__).parent / "cubes" / "programs" / "perceive.py"


@pytest.fixture(scope="module")
def perceive():
    spec = importlib.util.spec_from_file_location("cubes_reference_perceive", PERCEIVE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.perceive


def _scene(domain, behind: float):
    def rec(oid, x, y, z):
        T = np.eye(4)
        T[:3, 3] = (x, y, z)
        return domain.record(oid, T)

    x0 = 0.55  # a tower of three; the yellow cube stands behind it, seen from the front camera
    return domain.scene(
        [
            rec("red", x0, 0.0, HALF),
            rec("green", x0, 0.0, 3 * HALF),
            rec("blue", x0, 0.0, 5 * HALF),
            rec("yellow", x0 - 2 * HALF - behind, 0.0, HALF),
            rec("purple", 0.45, 0.2, HALF),
            rec("cyan", 0.45, -0.2, HALF),
        ]
    )


@pytest.mark.parametrize("seed", [1, 2])
def test_a_cube_hidden_behind_a_tower_is_reported_where_the_camera_cannot_see_it(perceive, seed):
    domain = domains.load("cubes")
    scene = _scene(domain, behind=0.006)
    obs, _ = observe_with_truth(domain, scene, "front", seed=seed, realism="default", mask=True)
    ids = [o["id"] for o in scene["objects"]]
    assert not (obs["mask"] == ids.index("yellow")).any(), "the scene must hide the yellow cube"

    records = perceive(
        {"rgb": obs["rgb"], "depth": obs["depth"], "camera": obs["camera"]},
        domain.meshes(),
        obs["camera"],
    )
    got = {r["id"]: np.asarray(r["pose"], float) for r in records}
    assert sorted(got) == sorted(ids)

    yellow = got["yellow"][:3, 3]
    assert yellow[2] == pytest.approx(HALF, abs=1e-3)  # on the table: it holds nothing up
    for oid, T in got.items():  # clear of every other cube
        if oid != "yellow" and abs(T[2, 3] - yellow[2]) < 2 * HALF:
            assert np.abs(T[:2, 3] - yellow[:2]).max() >= 2 * HALF - 1e-3, oid
    # hidden: the perceived state seen from the true camera shows no yellow pixel
    seen, _ = observe_with_truth(
        domain,
        domain.scene([domain.record(oid, T) for oid, T in got.items()]),
        "front",
        mask=True,
    )
    order = list(got)
    assert (seen["mask"] == order.index("yellow")).sum() <= 20
    # the nearest hidden place is where it stands here (right behind the tower)
    truth = next(o for o in scene["objects"] if o["id"] == "yellow")
    assert np.linalg.norm(yellow[:2] - np.asarray(truth["pose"])[:2, 3]) < 0.01


def test_the_occlusion_benchmark_draws_valid_scenes_with_a_cube_behind_a_tower():
    """`benchmarks.occlusion_bench`: each drawn scene passes the scene checks, stands a tower
    of two or three cubes and puts the named cube behind it, farther from the front camera."""
    from benchmarks.occlusion_bench import draw

    domain = domains.load("cubes")
    drawn = [d for d in (draw(domain, seed) for seed in range(100, 110)) if d is not None]
    assert len(drawn) >= 8
    for scene, behind in drawn:
        at = {o["id"]: np.asarray(o["pose"], float)[:3, 3] for o in scene["objects"]}
        tower = [p for p in at.values() if p[2] > 2 * HALF]
        assert tower, "no tower"
        base = min(
            (p for p in at.values() if p[2] < 2 * HALF),
            key=lambda p: np.linalg.norm(p[:2] - tower[0][:2]),
        )
        assert at[behind][2] == pytest.approx(HALF)
        assert 0.04 < base[0] - at[behind][0] < 0.08  # behind: less x than the tower (camera +x)


# Goals composed from the task text's structures (`Cubes.composed_instance`, dev-side seeds):
# 2017 and 2059, a cube half hidden behind a tower slid away from it (12 mm from its row
# neighbour: not adjacent); 2068, a sliver of a top face fitted 45° turned (its corner then
# touches the cube beside it: an 'on' instead of 'adjacent'); 2083, an unseen cube in a row
# guessed 25 mm off its place one pitch beside its neighbour.
@pytest.mark.parametrize("seed", [2017, 2059, 2068, 2083])
def test_composed_goals_are_perceived_with_their_relations(perceive, seed):
    from sim.score import state_accuracy
    from sim.trials import HONEST, observations

    domain = domains.load("cubes")
    instance = domain.composed_instance(seed)
    _, goal = observations(domain, instance, "front", HONEST)
    records = perceive(goal, domain.meshes(), goal["camera"])
    score = state_accuracy(domain, records, instance.goal)
    assert score.correct, (score.missing_edges, score.extra_edges, score.objects)


def test_a_view_that_shows_no_cube_still_reports_six_apart_in_the_placement_region(perceive):
    """No cube's colour anywhere in the image (a grey picture of the table): the six cubes are
    still reported, on the table, inside the region the task's scenes keep to and apart from
    one another (before, all six went to the robot's base at the origin)."""
    from toolbox.robot import PLACEMENT

    domain = domains.load("cubes")
    obs, _ = observe_with_truth(domain, _scene(domain, behind=0.006), "front", realism="default")
    grey = np.full_like(obs["rgb"], 128)
    records = perceive({**obs, "rgb": grey}, domain.meshes(), obs["camera"])
    at = {r["id"]: np.asarray(r["pose"], float)[:3, 3] for r in records}
    assert len(at) == 6
    for oid, p in at.items():
        assert PLACEMENT.x[0] <= p[0] <= PLACEMENT.x[1] and PLACEMENT.y[0] <= p[1] <= PLACEMENT.y[1]
        assert p[2] == pytest.approx(HALF, abs=1e-3), oid
    ids = sorted(at)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            assert np.abs(at[a][:2] - at[b][:2]).max() >= 2 * HALF - 1e-3, (a, b)
