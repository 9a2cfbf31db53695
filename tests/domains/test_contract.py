"""One contract suite over every registered domain (dm_control `suite_test.py` style).

Each domain must have consistent files, meshes that are watertight with their convex parts
and symmetries, cameras that see the workspace, a deterministic generator, and a committed
benchmark of 60 physically valid instances whose construction orders are executable (valid
at every step, and by the robot: every step has a top-down grasp of the 2F-85).
"""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

import domains
from contracts import validate
from domains.benchmark import BENCHMARK_GOALS, BENCHMARK_STARTS, same
from sim.settle import check_order, check_scene, geometric_problems, physical_problems

NAMES = domains.names()


@pytest.fixture(scope="module", params=NAMES)
def domain(request):
    return domains.load(request.param)


def test_task_text(domain):
    assert len(domain.task) > 200
    assert domain.task.startswith("# ")


def test_catalogue_objects(domain):
    ids = domain.object_ids
    assert len(ids) == len(set(ids)) >= 6
    for o in domain.objects:
        assert o.mesh in domain.mesh_specs
        assert 0.005 < o.mass < 1.0
        assert 0.3 <= o.friction <= 1.5
        assert len(o.colour) == 4
    # colours must be told apart: every pair differs clearly in RGB
    rgb = np.array([o.colour[:3] for o in domain.objects])
    dist = np.linalg.norm(rgb[:, None] - rgb[None], axis=2) + np.eye(len(rgb))
    assert dist.min() > 0.25


def test_meshes_are_watertight_and_equal_their_convex_parts(domain):
    for key, spec in domain.mesh_specs.items():
        mesh = domain.mesh(key)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, key
        parts = domain.collision_meshes[key]
        assert all(p.is_convex for p in parts), key
        assert abs(sum(p.volume for p in parts) - mesh.volume) < 1e-3 * mesh.volume, key
        assert spec.frame, key


def test_mesh_files_match_their_script(domain):
    built = importlib.import_module(f"domains.{domain.name}.make_meshes").build()
    assert set(built) == set(domain.mesh_specs)
    for key, value in built.items():
        mesh, parts = value if isinstance(value, tuple) else (value, [value])
        assert np.allclose(mesh.vertices, domain.mesh(key).vertices, atol=1e-8), key
        assert np.array_equal(mesh.faces, domain.mesh(key).faces), key
        assert len(parts) == len(domain.collision_meshes[key]), key


def test_meshes_are_graspable_top_down(domain):
    # some horizontal pair of faces no wider than the 2F-85's 85 mm opening, with margin
    for key in domain.mesh_specs:
        v = np.asarray(domain.mesh(key).vertices)
        ext = v.max(axis=0) - v.min(axis=0)
        assert min(ext[0], ext[1]) <= 0.08, key
        assert 0.02 <= ext.max() <= 0.2, key


def test_symmetries_map_each_mesh_onto_itself(domain):
    for key, spec in domain.mesh_specs.items():
        v = np.asarray(domain.mesh(key).vertices)
        sym = domain.symmetries(key)
        assert np.allclose(sym[0], np.eye(4))
        assert all(np.isclose(np.linalg.det(s[:3, :3]), 1.0) for s in sym)
        moved = np.einsum("sij,nj->sni", sym[:, :3, :3], v) + sym[:, None, :3, 3]  # (s, n, 3)
        if spec.symmetry["kind"] == "revolution":
            # a body of revolution: compare (radius, height) about its axis through the centre
            c = np.asarray(spec.symmetry.get("centre", (0, 0, 0)))

            def feature(p, c=c):
                d = p - c
                return np.c_[np.linalg.norm(d[..., :2], axis=-1).ravel(), d[..., 2].ravel()]

            tree = cKDTree(feature(v))
            assert tree.query(feature(moved))[0].max() < 1e-6, key
        else:
            # polyhedral meshes: the symmetry permutes the vertices
            tree = cKDTree(v)
            assert tree.query(moved.reshape(-1, 3))[0].max() < 1e-6, key


def test_cameras(domain):
    assert tuple(domain.cameras) == ("front", "view1", "view2")
    for name in domain.cameras:
        cam = domain.camera(name)
        validate(
            "camera",
            {
                k: np.asarray(v).tolist() if k in ("K", "T_world_camera") else v
                for k, v in cam.items()
            },
        )
        assert (cam["width"], cam["height"]) == (1280, 720)
        # the centre of the workspace projects inside the image, in front of the camera
        p = np.linalg.inv(cam["T_world_camera"]) @ [0.5, 0.0, 0.0, 1.0]
        u, v, _ = cam["K"] @ (p[:3] / p[2])
        assert p[2] > 0.3 and 0 < u < 1280 and 0 < v < 720
        # cameras stand in front of the table, looking back toward the robot
        assert cam["T_world_camera"][0, 3] > 0.75 and cam["T_world_camera"][0, 2] < 0


def test_tolerances(domain):
    expected = {"cubes": (0.01, None), "tangram": (0.005, 5.0), "assembly": (0.01, 10.0)}
    t, r = expected[domain.name]
    assert domain.tolerance.translation == t
    assert (
        (domain.tolerance.rotation is None)
        if r is None
        else np.isclose(np.degrees(domain.tolerance.rotation), r)
    )


def test_same_seed_same_instance(domain):
    a = domain.generate(7).to_dict()
    b = domain.generate(7).to_dict()
    c = domain.generate(8).to_dict()
    assert a == b
    assert a != c
    validate("instance", a)


def test_generated_instance_is_physically_valid(domain):
    inst = domain.generate(11, physics=physical_problems)
    assert check_scene(domain, inst.start) == []
    assert check_scene(domain, inst.goal) == []
    assert check_order(domain, inst.start, inst.order, inst.goal) == []


@pytest.fixture(scope="module")
def benchmark(domain):
    return domain.benchmark()


def test_benchmark_files(domain, benchmark):
    assert len(benchmark) == BENCHMARK_GOALS * BENCHMARK_STARTS
    for path in sorted(domain.benchmark_dir.glob("*.json")):
        validate("instance", json.loads(path.read_text()))
    # the three starts of a goal share it; goals differ
    goals = [json.dumps(domains.scene_to_json(i.goal)) for i in benchmark]
    for g in range(BENCHMARK_GOALS):
        assert len(set(goals[3 * g : 3 * g + 3])) == 1
    assert len(set(goals)) == BENCHMARK_GOALS
    assert all(i.order for i in benchmark)


def test_benchmark_is_geometrically_valid_with_executable_orders(domain, benchmark):
    for inst in benchmark:
        assert geometric_problems(domain, inst.start) == [], inst.name
        assert geometric_problems(domain, inst.goal) == [], inst.name
        assert check_order(domain, inst.start, inst.order, inst.goal, physics=False) == [], (
            inst.name
        )


def test_benchmark_orders_have_a_grasp_at_every_step(domain, benchmark):
    # the robot's predicate (geometry.grasps.plan_grasps, every other object a neighbour at both
    # ends), geometry only, no physics
    for inst in benchmark:
        bad = domain.grasps.first_infeasible(inst.start["objects"], inst.order)
        assert bad is None, f"{inst.name}: {bad}"


def test_generated_orders_have_a_grasp_at_every_step(domain):
    inst = domain.generate(11, grasps=True)
    assert domain.grasps.first_infeasible(inst.start["objects"], inst.order) is None
    assert check_order(domain, inst.start, inst.order, inst.goal, physics=False) == []


@pytest.mark.slow
def test_benchmark_is_physically_valid(domain, benchmark):
    from sim.settle import physical_problems

    for inst in benchmark:
        assert physical_problems(domain, inst.start) == [], inst.name
        if inst.name.endswith("start1"):
            assert physical_problems(domain, inst.goal) == [], inst.name


@pytest.mark.slow
def test_reference_orders_are_physically_executable(domain, benchmark):
    for inst in benchmark[:BENCHMARK_STARTS]:
        assert check_order(domain, inst.start, inst.order, inst.goal) == [], inst.name


@pytest.mark.slow
@pytest.mark.parametrize("goal", [1, 2, 13])
def test_benchmark_regenerates_identically(domain, goal):
    for start in range(1, BENCHMARK_STARTS + 1):
        inst = domain.benchmark_instance(goal, start, physics=physical_problems)
        committed = json.loads(domain.benchmark_path(goal, start).read_text())
        assert same(committed, inst.to_dict()), inst.name


def test_reference_relations_are_a_node_link_multigraph(domain, benchmark):
    ref = benchmark[0]
    graph = domain.reference_relations(ref.goal["objects"])
    validate("relations", graph)
    assert {n["id"] for n in graph["nodes"]} == set(domain.object_ids)
    assert {e["type"] for e in graph["edges"]} <= set(domain.REFERENCE_RELATIONS)
    assert graph["edges"], "the reference goal has relations"
    # invariant under a common translation and under record order
    shift = np.eye(4)
    shift[:3, 3] = (0.01, 0.02, 0.0)
    moved = [{**r, "pose": shift @ r["pose"]} for r in ref.goal["objects"]]
    key = lambda g: sorted((e["source"], e["target"], e["type"]) for e in g["edges"])  # noqa: E731
    assert key(domain.reference_relations(moved)) == key(graph)
    assert key(domain.reference_relations(ref.goal["objects"][::-1])) == key(graph)
