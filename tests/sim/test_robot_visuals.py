"""The robot without its visual meshes has the full robot's physics and kinematics, to the
last bit (`sim.robot.attach_robot(visuals=False)`): the trials simulate it and the IK plans on
it, while only the recordings draw the full one."""

from __future__ import annotations

import mujoco
import numpy as np

from domains.registry import load
from sim import ik, robot
from sim.scene import build_spec


def _world(visuals: robot.Visuals) -> mujoco.MjModel:
    domain = load("assembly")
    instance = domain.benchmark("dev")[2]
    return build_spec(domain, instance.start, with_robot=True, robot_visuals=visuals).compile()


def test_the_stripped_robot_has_no_visual_mesh_and_the_same_bodies():
    full, lite, coarse = _world(True), _world(False), _world("coarse")
    assert lite.nmeshvert < full.nmeshvert / 5
    # the drawing robot: every visual mesh kept, merged on a millimetre grid
    assert coarse.ngeom == full.ngeom and coarse.nmeshface < full.nmeshface / 2
    assert coarse.nbuffer < full.nbuffer / 2
    for model in (lite, coarse):
        assert [full.body(b).name for b in range(full.nbody)] == [
            model.body(b).name for b in range(model.nbody)
        ]
        for field in ("body_mass", "body_ipos", "body_iquat", "body_inertia", "dof_M0"):
            np.testing.assert_array_equal(getattr(full, field), getattr(model, field), field)
        assert full.stat.meaninertia == model.stat.meaninertia


def test_the_stripped_world_steps_exactly_as_the_full_one():
    full, lite = _world(True), _world(False)
    datas = [mujoco.MjData(m) for m in (full, lite)]
    for m, d in zip((full, lite), datas, strict=True):
        mujoco.mj_resetDataKeyframe(m, d, m.key(robot.PARK_KEY).id)
    rng = np.random.default_rng(0)
    index = robot.RobotIndex.from_model(full)
    ctrl = datas[0].ctrl.copy()
    for _ in range(1500):
        ctrl += rng.normal(0.0, 0.002, full.nu)
        for m, d in zip((full, lite), datas, strict=True):
            d.ctrl[:] = ctrl
            mujoco.mj_step(m, d)
    np.testing.assert_array_equal(datas[0].qpos, datas[1].qpos)
    np.testing.assert_array_equal(datas[0].qvel, datas[1].qvel)
    assert np.abs(datas[0].qpos[index.arm_qpos] - robot.PARK_QPOS).max() > 1e-3  # it moved


def test_the_ik_on_the_stripped_robot_is_the_full_robots(monkeypatch):
    lite = ik.ArmIK()
    assert lite.model.nmeshvert < 100_000  # the IK's own model is the stripped one
    full_model = robot.build_robot_spec(visuals=True).compile()
    monkeypatch.setattr(ik, "ik_model", lambda: full_model)
    full = ik.ArmIK()
    rng = np.random.default_rng(1)
    for _ in range(60):
        q = robot.READY_QPOS + rng.normal(0.0, 0.2, len(robot.ARM_JOINTS))
        np.testing.assert_array_equal(full.fk(q), lite.fk(q))
        target = full.fk(q)
        target[:3, 3] += rng.normal(0.0, 0.02, 3)
        np.testing.assert_array_equal(full.step(q, target, 0.02), lite.step(q, target, 0.02))


def test_a_recording_draws_the_trial_state_with_the_robots_meshes(tmp_path):
    """The recorder draws the physics model's state (joints copied by name) on a world with the
    robot's visual meshes (merged on a millimetre grid), whose objects come in another order
    than the trial's: the frame is the full robot's but for a few edge pixels."""
    from sim import trials
    from sim.observation import Renderer

    domain = load("cubes")
    instance, other = domain.benchmark("dev")[0], domain.benchmark("dev")[4]
    assert [o["id"] for o in instance.start["objects"]] != [o["id"] for o in other.start["objects"]]
    model, data = trials._world(domain, instance)
    index = robot.RobotIndex.from_model(model)
    arm = ik.ArmIK()
    target = arm.fk(robot.READY_QPOS)
    target[:3, 3] = [0.45, 0.0, 0.12]  # the hand low over the workspace, in view
    data.qpos[index.arm_qpos] = arm.solve(target, robot.READY_QPOS).q
    mujoco.mj_forward(model, data)
    recorder = trials._Recorder(
        model,
        trials._twin(domain, [o["id"] for o in other.start["objects"]]),
        domain.camera("front"),
        tmp_path / "t.mp4",
    )
    recorder(model, data)
    recorder.close()
    frame = recorder.last_rgb().astype(int)

    full = build_spec(domain, instance.start, with_robot=True).compile()
    full.vis.quality.offsamples = 0
    reference = Renderer(full, recorder.camera["width"], recorder.camera["height"])
    full_data = mujoco.MjData(full)
    for qpos in (data.qpos, None):
        if qpos is None:  # the arm parked, out of view
            mujoco.mj_resetDataKeyframe(full, full_data, full.key(robot.PARK_KEY).id)
        else:
            full_data.qpos[:] = qpos
        mujoco.mj_forward(full, full_data)
        image = reference.render(full_data, recorder.camera, depth=False, quick=True)["rgb"]
        difference = np.abs(frame - image.astype(int)).mean()
        if qpos is None:
            assert difference > 3.0  # the frame shows the arm
        else:
            assert difference < 0.1  # the same picture (0.02 here: a few edge pixels)
    reference.close()


def test_a_recording_worker_keeps_no_mesh_cache():
    """The IK's model and a recorded trial's world compile outside MuJoCo's global mesh cache,
    which would keep the robot's collision meshes (about 23 MB) in a worker whose peak memory
    has a target; an unrecorded trial's world still uses it (a faster next compile)."""
    from sim import trials

    domain = load("cubes")
    instance = domain.benchmark("dev")[0]
    cache = mujoco.mj_getCache()
    mujoco.mj_clearCache(cache)
    ik.ik_model.cache_clear()
    ik.ik_model()
    trials._world(domain, instance, mesh_cache=False)
    assert mujoco.mj_getCacheSize(cache) == 0
    trials._world(domain, instance)
    assert mujoco.mj_getCacheSize(cache) > 10 << 20
