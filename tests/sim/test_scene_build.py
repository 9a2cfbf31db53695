"""Scene parsing and the MuJoCo world built from a scene spec."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import domains
from contracts.errors import ContractError
from domains.errors import UnknownObjectError
from sim import scene as sim_scene


def _cube(oid="red", x=0.5, y=0.0, z=0.02, mesh="cube"):
    pose = np.eye(4)
    pose[:3, 3] = (x, y, z)
    return {"id": oid, "mesh": mesh, "pose": pose.tolist()}


@pytest.fixture(scope="module")
def cubes():
    return domains.load("cubes")


def test_parse_scene_gives_arrays(cubes):
    s = sim_scene.parse_scene(cubes, {"domain": "cubes", "objects": [_cube()]})
    assert isinstance(s["objects"][0]["pose"], np.ndarray)


@pytest.mark.parametrize(
    ("objects", "error", "match"),
    [
        ([_cube("pink")], UnknownObjectError, "unknown object 'pink'; known: red"),
        ([_cube(mesh="ball")], UnknownObjectError, "unknown mesh 'ball'"),
        ([_cube(), _cube(x=0.6)], ContractError, "duplicate id 'red'"),
        ([{**_cube(), "pose": [[1, 0, 0], [0, 1, 0]]}], ContractError, r"objects\[0\]\.pose"),
        (
            [{**_cube(), "pose": np.diag([1.0, 1.0, -1.0, 1.0]).tolist()}],
            ContractError,
            "not proper",
        ),
        ([], ContractError, "at least one object"),
    ],
)
def test_parse_scene_refuses_bad_input(cubes, objects, error, match):
    with pytest.raises(error, match=match):
        sim_scene.parse_scene(cubes, {"domain": "cubes", "objects": objects})


def test_parse_scene_wrong_domain(cubes):
    with pytest.raises(ContractError, match="domain"):
        sim_scene.parse_scene(cubes, {"domain": "tangram", "objects": [_cube()]})


def test_spec_has_world_cameras_and_named_objects(cubes):
    s = sim_scene.parse_scene(
        cubes, {"domain": "cubes", "objects": [_cube(), _cube("blue", x=0.6)]}
    )
    spec = sim_scene.build_spec(cubes, s)
    assert isinstance(spec, mujoco.MjSpec)
    model = spec.compile()
    for name in ("front", "view1", "view2", sim_scene.RENDER_CAMERA):
        assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name) >= 0
    for oid in ("red", "blue"):
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, sim_scene.body_name(oid))
        assert b >= 0
        assert np.isclose(model.body_mass[b], cubes.object(oid).mass)
    assert model.vis.global_.offwidth >= 1280 and model.vis.global_.offheight >= 720
    # table top at z = 0
    t = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "table")
    assert np.isclose(model.geom_pos[t][2] + model.geom_size[t][2], 0.0)


def test_body_frame_is_the_mesh_frame(cubes):
    pose = np.eye(4)
    pose[:3, 3] = (0.45, 0.1, 0.02)
    sm = sim_scene.scene_model(
        cubes, {"domain": "cubes", "objects": [{"id": "red", "mesh": "cube", "pose": pose}]}
    )
    assert np.allclose(sm.poses()["red"], pose, atol=1e-9)
    g = mujoco.mj_name2id(sm.model, mujoco.mjtObj.mjOBJ_GEOM, "object/red/visual")
    assert np.allclose(sm.data.geom_xpos[g], pose[:3, 3], atol=1e-9)


def test_with_robot_calls_the_robot_hook(cubes, monkeypatch):
    import sys
    import types

    calls = []
    fake = types.ModuleType("sim.robot")
    fake.attach_robot = lambda spec, visuals: calls.append(spec)
    monkeypatch.setitem(sys.modules, "sim.robot", fake)
    s = sim_scene.parse_scene(cubes, {"domain": "cubes", "objects": [_cube()]})
    spec = sim_scene.build_spec(cubes, s, with_robot=True)
    assert calls == [spec]


def test_load_instance_by_benchmark_name():
    domain, inst = sim_scene.load_instance("cubes/goal01_start1")
    assert domain.name == "cubes" and inst.name == "goal01_start1" and inst.order
