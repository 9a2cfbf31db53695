"""The dev and test splits: dev unchanged, test goals from families the dev split never
uses (checked structurally), test instances valid, deterministic and committed."""

from __future__ import annotations

import json

import networkx as nx
import numpy as np
import pytest

import domains
from contracts import validate
from domains.benchmark import (
    BENCHMARK_GOALS,
    BENCHMARK_STARTS,
    SPLITS,
    benchmark_keys,
    benchmark_name,
    same,
)
from domains.generation import geometric_problems
from geometry import bodies_of, yaw_of
from geometry import resting_on as supports
from sim.settle import check_order

NAMES = domains.names()


@pytest.fixture(scope="module", params=NAMES)
def domain(request):
    return domains.load(request.param)


@pytest.fixture(scope="module")
def test_set(domain):
    return domain.benchmark("test")


# -- the dev split is what it was ----------------------------------------------------------


@pytest.mark.parametrize(("goal", "start"), [(1, 1), (2, 2), (13, 3)])
def test_dev_instances_regenerate_identically(domain, goal, start):
    # the default split is dev, and it draws exactly the committed instances (geometry and
    # grasps; these draws were not rejected by the MuJoCo check, so it is not needed here)
    committed = json.loads(domain.benchmark_path(goal, start).read_text())
    assert same(committed, domain.benchmark_instance(goal, start, grasps=True).to_dict())
    explicit = domain.benchmark_instance(goal, start, grasps=True, split="dev")
    assert same(committed, explicit.to_dict())


def test_dev_paths_and_names_are_unchanged(domain):
    assert domain.benchmark_dir == domain.root / "benchmark"
    assert domain.benchmark_dir_of("dev") == domain.benchmark_dir
    assert domain.benchmark_path(3, 2) == domain.benchmark_dir / "goal03_start2.json"
    assert domain.benchmark_dir_of("test") == domain.benchmark_dir / "test"
    assert domain.benchmark_path(3, 2, "test") == domain.benchmark_dir / "test/goal03_start2.json"
    assert [i.name for i in domain.benchmark()[:2]] == ["goal01_start1", "goal01_start2"]
    assert benchmark_name(3, 2, "test") == "test/goal03_start2"


def test_unknown_split_is_refused(domain):
    with pytest.raises(ValueError, match="unknown split"):
        domain.benchmark_instance(1, 1, split="train")
    with pytest.raises(ValueError, match="unknown split"):
        domain.benchmark("train")
    assert SPLITS == ("dev", "test")


# -- the committed test set --------------------------------------------------------------


def test_committed_test_files(domain, test_set):
    assert len(test_set) == BENCHMARK_GOALS * BENCHMARK_STARTS == 60
    assert [i.name for i in test_set] == [benchmark_name(g, s, "test") for g, s in benchmark_keys()]
    for path in sorted(domain.benchmark_dir_of("test").glob("*.json")):
        validate("instance", json.loads(path.read_text()))
    goals = [json.dumps(domains.scene_to_json(i.goal)) for i in test_set]
    for g in range(BENCHMARK_GOALS):
        assert len(set(goals[3 * g : 3 * g + 3])) == 1
    assert len(set(goals)) == BENCHMARK_GOALS
    dev_goals = {json.dumps(domains.scene_to_json(i.goal)) for i in domain.benchmark()}
    assert not dev_goals & set(goals)


def test_test_instances_are_valid(domain, test_set):
    for inst in test_set:
        assert geometric_problems(domain, inst.start) == [], inst.name
        assert geometric_problems(domain, inst.goal) == [], inst.name
        assert check_order(domain, inst.start, inst.order, inst.goal, physics=False) == [], (
            inst.name
        )


def test_test_orders_have_a_grasp_at_every_step(domain, test_set):
    for inst in test_set[::BENCHMARK_STARTS]:  # start 1 of every goal (all: at generation)
        bad = domain.grasps.first_infeasible(inst.start["objects"], inst.order)
        assert bad is None, f"{inst.name}: {bad}"


@pytest.mark.parametrize(("goal", "start"), [(1, 1), (12, 3)])
def test_test_instances_regenerate_identically(domain, goal, start):
    # `rivet scene benchmark DOMAIN --split test --check` checks all 60 with MuJoCo; these
    # draws were not rejected by the MuJoCo check, so geometry and grasps redraw them
    committed = json.loads(domain.benchmark_path(goal, start, "test").read_text())
    inst = domain.benchmark_instance(goal, start, grasps=True, split="test")
    assert same(committed, inst.to_dict())


def test_test_generation_is_deterministic(domain, test_set):
    a = domain.benchmark_instance(4, 2, split="test")
    b = domain.benchmark_instance(4, 2, split="test")
    assert same(a.to_dict(), b.to_dict())
    assert a.name == "test/goal04_start2"
    # the goal is the committed one (goals are drawn before any start, with geometry only
    # deciding; every committed test goal passed the MuJoCo check at its first draw)
    assert same(domains.scene_to_json(a.goal), domains.scene_to_json(test_set[10].goal))
    free = domain.generate(7, split="test")
    assert free.name == "test/seed7"
    assert same(free.to_dict(), domain.generate(7, split="test").to_dict())
    assert not same(free.to_dict(), domain.generate(7).to_dict())


# -- test goals are not dev goals: structural signatures ---------------------------------


def _footprints(domain, r) -> list[np.ndarray]:
    """The object's convex parts seen from above: convex polygons (k, 2), counter-clockwise."""
    from scipy.spatial import ConvexHull

    pose = np.asarray(r["pose"], float)
    out = []
    for piece in domain.parts[r["mesh"]]:
        xy = (piece.vertices @ pose[:3, :3].T + pose[:3, 3])[:, :2]
        out.append(xy[ConvexHull(xy).vertices])
    return out


def _overlap(a: np.ndarray, b: np.ndarray, depth: float = 0.002) -> bool:
    """Two convex polygons overlap by more than `depth` [m] (separating axis test)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        for n in np.stack([edges[:, 1], -edges[:, 0]], axis=1):
            n = n / np.linalg.norm(n)
            pa, pb = a @ n, b @ n
            if min(pa.max(), pb.max()) - max(pa.min(), pb.min()) < depth:
                return False
    return True


def _graph(domain, records) -> nx.MultiDiGraph:
    """The goal's reference relations (on, adjacent) and what stands over what without
    resting on it (`over`: above it, their footprints overlapping), each node labelled by
    its mesh."""
    data = domain.reference_relations(records)
    g = nx.MultiDiGraph()
    mesh = {r["id"]: r["mesh"] for r in records}
    for n in data["nodes"]:
        g.add_node(n["id"], mesh=mesh[n["id"]])
    for e in data["edges"]:
        g.add_edge(e["source"], e["target"], type=e["type"])
    on = {(e["source"], e["target"]) for e in data["edges"] if e["type"] == "on"}
    bodies = {b.id: b for b in bodies_of(records, domain.parts)}
    feet = {r["id"]: _footprints(domain, r) for r in records}
    for a in bodies:
        for b in bodies:
            if a == b or (a, b) in on or bodies[a].lowest < bodies[b].highest - 0.001:
                continue
            if any(_overlap(p, q) for p in feet[a] for q in feet[b]):
                g.add_edge(a, b, type="over")
    return g


def _same_structure(a: nx.MultiDiGraph, b: nx.MultiDiGraph) -> bool:
    """Equal up to relabelling objects of the same mesh (support, adjacency, over)."""
    return nx.is_isomorphic(
        a,
        b,
        node_match=lambda x, y: x["mesh"] == y["mesh"],
        edge_match=nx.algorithms.isomorphism.categorical_multiedge_match("type", None),
    )


def _dev_catalogue(domain) -> list:
    """One goal of every entry of the dev split's catalogue (free dev draws use the same)."""
    if domain.name == "cubes":
        from domains.cubes import COMPOSITIONS

        n = len(COMPOSITIONS) + 1  # goal 1, the reference pyramid, then every composition
    else:
        from domains.assembly import GOALS

        n = len(GOALS)
    rng = np.random.default_rng(0)
    return [domain.make_goal(rng, index) for index in range(1, n + 1)]


@pytest.mark.parametrize("name", ["cubes", "assembly"])
def test_test_structures_are_not_dev_structures(name):
    domain = domains.load(name)
    dev = [_graph(domain, g) for g in _dev_catalogue(domain)]
    # the catalogue's signatures do not depend on the layout drawn
    rng = np.random.default_rng(1)
    again = [_graph(domain, domain.make_goal(rng, k)) for k in range(1, len(dev) + 1)]
    assert all(_same_structure(a, b) for a, b in zip(dev, again, strict=True))
    test = [_graph(domain, i.goal["objects"]) for i in domain.benchmark("test")[::3]]
    for k, t in enumerate(test, start=1):
        assert not any(_same_structure(t, d) for d in dev), f"test goal {k} is a dev structure"
    # and the same holds for free test draws
    for seed in range(3):
        goal = domain.make_goal(np.random.default_rng(seed), None, split="test")
        assert not any(_same_structure(_graph(domain, goal), d) for d in dev)


def test_test_figures_are_not_dev_figures():
    from domains.tangram.figures import SILHOUETTES, TEST_FAMILIES, TEST_SILHOUETTES, shape_key

    tangram = domains.load("tangram")
    dev = {shape_key(p) for p in SILHOUETTES.values()}  # all 30: free dev draws use any
    test = {n: shape_key(p) for n, p in TEST_SILHOUETTES.items()}
    assert len(test) == BENCHMARK_GOALS and len(set(test.values())) == len(test)
    assert not dev & set(test.values())  # even turned by any angle, or mirrored
    assert not set(SILHOUETTES) & set(TEST_SILHOUETTES)
    assert list(tangram.test_figures) == list(TEST_SILHOUETTES)
    assert sorted(n for f in TEST_FAMILIES.values() for n in f) == sorted(TEST_SILHOUETTES)
    # the key sees what it should: a mirrored or turned figure is the same figure
    house = SILHOUETTES["house"][0]
    assert shape_key([[(-x, y) for x, y in house]]) == shape_key([house])
    assert shape_key([[(-y, x) for x, y in house]]) == shape_key([house])
    # test goal k is test figure k, up to where and how it is turned on the table
    names = list(TEST_SILHOUETTES)
    for k, inst in enumerate(tangram.benchmark("test")[::3]):
        assert _same_figure(tangram, inst.goal["objects"], names[k]), inst.name


def _same_figure(tangram, records, name) -> bool:
    built = {r["id"]: np.asarray(r["pose"], float) for r in tangram.figure_records(name, np.eye(4))}
    goal = {r["id"]: np.asarray(r["pose"], float) for r in records}
    ref = "large_1"
    return all(
        np.allclose(
            np.linalg.inv(goal[ref]) @ goal[i], np.linalg.inv(built[ref]) @ built[i], atol=1e-6
        )
        for i in built
    )


# -- what the test families add ------------------------------------------------------------


def _depth(sup: dict[str, set[str]]) -> int:
    def d(i: str) -> int:
        return 1 + max((d(s) for s in sup[i]), default=0)

    return max(d(i) for i in sup)


def _sides(records) -> list[int]:
    """Per cube whose neighbours (at its level, ≤ 12 mm away) stand on two axes at right
    angles, how many sides they occupy: 2 for a corner, 3 for a junction, 4 for a cross.
    A cube in a row or a pyramid has its neighbours on one axis and is not counted."""
    pose = {r["id"]: np.asarray(r["pose"], float)[:3, 3] for r in records}
    out = []
    for i, p in pose.items():
        sides = set()
        for j, q in pose.items():
            d = q - p
            if j != i and abs(d[2]) < 0.005 and np.linalg.norm(d[:2]) < 0.04 + 0.012:
                sides.add(round(float(np.degrees(np.arctan2(d[1], d[0]))) / 90) % 4)
        if {k % 2 for k in sides} == {0, 1}:
            out.append(len(sides))
    return out


def _bridged_depth(sup: dict[str, set[str]]) -> int:
    """The longest support chain (objects, bottom to top) through an object that rests on
    two or more."""

    def up(i: str) -> int:  # objects from the table to i
        return 1 + max((up(s) for s in sup[i]), default=0)

    above: dict[str, set[str]] = {i: set() for i in sup}
    for i, ss in sup.items():
        for s in ss:
            above[s].add(i)

    def down(i: str) -> int:  # objects from i to the top
        return 1 + max((down(a) for a in above[i]), default=0)

    return max((up(i) + down(i) - 1 for i in sup if len(sup[i]) >= 2), default=0)


def test_cubes_test_families_add_neighbours_depth_and_clutter():
    cubes = domains.load("cubes")
    dev = [supports(bodies_of(g, cubes.parts)) for g in _dev_catalogue(cubes)]
    assert not any(_sides(g) for g in _dev_catalogue(cubes))  # dev: rows and pyramids
    assert max(_bridged_depth(s) for s in dev) == 3  # the 3-2-1 pyramid
    test = cubes.benchmark("test")
    test_goals = [i.goal["objects"] for i in test[::3]]
    assert {2, 3, 4} <= {n for g in test_goals for n in _sides(g)}  # corner, junction, cross
    depth = [_bridged_depth(supports(bodies_of(g, cubes.parts))) for g in test_goals]
    assert max(depth) == 5 and depth.count(4) >= 3  # a spire, gates
    for inst in test:  # stacked clutter: a stack of three or more, at most three on the table
        sup = supports(bodies_of(inst.start["objects"], cubes.parts))
        assert _depth(sup) >= 3, inst.name
        assert sum(not s for s in sup.values()) <= 3, inst.name


def test_tangram_test_starts_turn_every_piece_far():
    from domains.tangram import TEST_TURNS

    tangram = domains.load("tangram")
    for inst in tangram.benchmark("test"):
        goal = {r["id"]: r for r in inst.goal["objects"]}
        for r in inst.start["objects"]:
            g = goal[r["id"]]
            fold = {"square": 4, "parallelogram": 2}.get(r["mesh"], 1)
            turn = abs(yaw_of(r["pose"]) - yaw_of(g["pose"])) % (2 * np.pi / fold)
            turn = min(turn, 2 * np.pi / fold - turn)
            assert turn >= TEST_TURNS[r["mesh"]][0] - 1e-6, (inst.name, r["id"])
    # the spread-out figures are turned away from upright (dev: within ±20°)
    fam = {n: f["family"] for n, f in tangram.test_figures.items()}
    names = list(tangram.test_figures)
    for k, inst in enumerate(tangram.benchmark("test")[::3]):
        ref = next(r for r in inst.goal["objects"] if r["id"] == "large_1")
        built = tangram.figure_records(names[k], np.eye(4))[0]["pose"]
        away = (yaw_of(ref["pose"]) - yaw_of(built) - np.pi / 2 + np.pi) % (2 * np.pi) - np.pi
        assert (abs(away) > 0.5) == (fam[names[k]] == "limbs"), inst.name


def test_assembly_test_starts_stack_three_deep():
    assembly = domains.load("assembly")
    for inst in assembly.benchmark("test"):
        sup = supports(bodies_of(inst.start["objects"], assembly.parts))
        assert _depth(sup) >= 3, inst.name
    depth = [
        _depth(supports(bodies_of(i.goal["objects"], assembly.parts)))
        for i in assembly.benchmark("test")[::3]
    ]
    assert max(depth) == 5  # the beacon: pillars, beam, cylinder, block, roof
