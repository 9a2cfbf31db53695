"""The robot model (sim.robot) and its IK (sim.ik)."""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np
import pytest

_SHARED = Path(__file__).resolve().parents[3] / "shared" / "menagerie"
if _SHARED.is_dir():  # the Makefile exports MENAGERIE_ROOT; plain pytest runs get the same
    os.environ.setdefault("MENAGERIE_ROOT", str(_SHARED))

from contracts import se3  # noqa: E402
from sim import robot  # noqa: E402
from sim.ik import POSITION_TOL, ROTATION_TOL, ArmIK  # noqa: E402

# The domains' cameras: in front of the table, elevated, looking back at the workspace.
CAMERAS = {
    "front": ([1.05, 0.0, 0.55], [0.5, 0.0, 0.03]),
    "left": ([0.9, 0.45, 0.45], [0.5, 0.0, 0.03]),
    "right": ([0.92, -0.40, 0.65], [0.5, 0.0, 0.03]),
    "far": ([1.3, 0.0, 0.9], [0.5, 0.0, 0.0]),
}


def _scene_with_objects_after_robot() -> mujoco.MjModel:
    spec = mujoco.MjSpec()
    spec.worldbody.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.65, 0.75, 0.025],
        pos=[0.35, 0, -0.025],
    )
    robot.attach_robot(spec)
    body = spec.worldbody.add_body(name="cube", pos=[0.5, 0.0, 0.02])
    body.add_freejoint()
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02] * 3, mass=0.05)
    return spec.compile()


def test_robot_compiles_with_the_options_attaching_drops():
    model = robot.build_robot_spec().compile()
    assert model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert model.opt.impratio == pytest.approx(10.0)
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    index = robot.RobotIndex.from_model(model)
    assert len(index.arm_qpos) == 7
    assert index.weld >= 0 and not model.eq_active0[index.weld]
    # The 2F-85's joint ranges are radians (driver 0 … 0.8), not degrees.
    driver = model.joint(robot.GRIPPER_DRIVER_JOINTS[0]).id
    assert model.jnt_range[driver] == pytest.approx([0.0, 0.8])
    assert all(model.body_gravcomp[b] == 1.0 for b in index.robot_bodies)


def test_park_keyframe_holds_still_and_stays_out_of_the_cameras():
    model = _scene_with_objects_after_robot()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(robot.PARK_KEY).id)
    index = robot.RobotIndex.from_model(model)
    cube = model.body("cube").id
    mujoco.mj_forward(model, data)
    assert data.xpos[cube] == pytest.approx([0.5, 0.0, 0.02])  # objects keep their places
    for _ in range(500):
        mujoco.mj_step(model, data)
    assert np.max(np.abs(data.qpos[index.arm_qpos] - robot.PARK_QPOS)) < 2e-3
    # Every vertex of the moving links (link2 onwards) lies outside each camera's image.
    first = model.body(f"{robot.PREFIX}fr3_link2").id
    points = []
    for g in range(model.ngeom):
        if model.geom_bodyid[g] < first or model.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH:
            continue
        if model.geom_bodyid[g] not in index.robot_bodies:
            continue
        mid = model.geom_dataid[g]
        v = model.mesh_vert[
            model.mesh_vertadr[mid] : model.mesh_vertadr[mid] + model.mesh_vertnum[mid]
        ]
        points.append(v @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g])
    P = np.concatenate(points)
    for name, (pos, target) in CAMERAS.items():
        assert not _in_view(P, np.array(pos), np.array(target)).any(), name


def _in_view(P, pos, target, fovy=44.0, width=1280, height=720):
    z = (target - pos) / np.linalg.norm(target - pos)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pc = (P - pos) @ np.stack([x, y, z]).T
    f = height / 2 / np.tan(np.radians(fovy / 2))
    u = f * pc[:, 0] / pc[:, 2] + width / 2
    v = f * pc[:, 1] / pc[:, 2] + height / 2
    return (pc[:, 2] > 0) & (u >= 0) & (u < width) & (v >= 0) & (v < height)


def test_park_helper_sets_only_robot_joints():
    model = _scene_with_objects_after_robot()
    data = mujoco.MjData(model)
    data.qpos[-7:-4] = [0.4, 0.1, 0.02]
    robot.park(model, data)
    index = robot.RobotIndex.from_model(model)
    assert data.qpos[index.arm_qpos] == pytest.approx(robot.PARK_QPOS)
    assert data.qpos[-7:-4] == pytest.approx([0.4, 0.1, 0.02])


def test_missing_robot_is_named():
    spec = mujoco.MjSpec()
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.1])
    with pytest.raises(robot.RobotModelError, match="attach_robot"):
        robot.RobotIndex.from_model(spec.compile())


def test_the_hand_model_stroke_is_the_menagerie_grippers():
    """The description's stroke (what the executor, the checks and the programs use) is what
    the menagerie 2F-85 does in simulation, to 0.05 mm."""
    from geometry.robot import STROKE

    measured = robot.measure_stroke()
    np.testing.assert_allclose(STROKE.ctrl, measured.ctrl)
    np.testing.assert_allclose(STROKE.gap, measured.gap, atol=5e-5)
    np.testing.assert_allclose(STROKE.tip, measured.tip, atol=5e-5)


def test_the_description_states_the_joint_ranges_of_the_menagerie_model():
    """The description's joint ranges (what the simulator and the IK keep to) are the
    menagerie FR3's own, so describing them changed nothing."""
    from geometry.robot import ROBOT

    spec = robot._load_spec(*ROBOT.arm.model)
    menagerie = {j.name: list(j.range) for j in spec.joints}
    for name, rng in zip(ROBOT.arm.joints, ROBOT.arm.joint_ranges, strict=True):
        np.testing.assert_allclose(rng, menagerie[name], atol=1e-9)


def test_the_toolbox_states_the_wrist_range_of_the_model():
    """toolbox.robot.WRIST_RANGE (what the prompts give a program) is the menagerie FR3's last
    joint, the one the executor and the checks' inverse kinematics turn the held object with."""
    from toolbox.robot import WRIST_RANGE

    model = robot.build_robot_spec().compile()
    index = robot.RobotIndex.from_model(model)
    np.testing.assert_allclose(WRIST_RANGE, index.arm_range[-1], atol=1e-6)


def test_gripper_stroke_spans_the_stroke():
    table = robot.measure_stroke()
    assert table.gap[0] == pytest.approx(0.085, abs=0.002)
    assert table.gap[-1] < 0.002
    assert np.all(np.diff(table.gap) < 0)
    assert table.ctrl_for_gap(0.04) == pytest.approx(
        np.interp(0.04, table.gap[::-1], table.ctrl[::-1])
    )
    # Closing moves the fingertips along the approach axis by about a centimetre.
    assert 0.005 < table.tip[-1] - table.tip[0] < 0.02


def _top_down(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    return se3.make(se3.rot_z(yaw)[:3, :3] @ np.diag([1.0, -1.0, -1.0]), [x, y, z])


@pytest.mark.slow
def test_ik_reaches_top_down_poses_across_the_workspace():
    ik = ArmIK()
    misses = []
    for x in np.linspace(0.3, 0.7, 5):
        for y in np.linspace(-0.3, 0.3, 5):
            for z in (0.02, 0.15, 0.3):
                for yaw in np.linspace(0.0, np.pi, 4, endpoint=False):
                    # The 2F-85 is symmetric under a half turn: one of the two yaws must do.
                    sols = [
                        ik.solve(_top_down(x, y, z, a), robot.READY_QPOS)
                        for a in (yaw, yaw + np.pi)
                    ]
                    if not any(s.ok for s in sols):
                        misses.append((x, y, z, yaw))
                    for s in sols:
                        if s.ok:
                            err = ArmIK.errors(
                                ik.fk(s.q), _top_down(x, y, z, yaw if s is sols[0] else yaw + np.pi)
                            )
                            assert err[0] <= POSITION_TOL and err[1] <= ROTATION_TOL
                            lo, hi = robot.RobotIndex.from_model(ik.model).arm_range.T
                            assert np.all(s.q >= lo) and np.all(s.q <= hi)
    assert not misses


def test_ik_reports_an_unreachable_pose():
    sol = ArmIK().solve(_top_down(1.4, 0.0, 0.1, 0.0), robot.READY_QPOS)
    assert not sol.ok and sol.position_error > 0.1


def test_ik_step_keeps_the_gripper_frozen_and_respects_velocity_limits():
    ik = ArmIK()
    dt = 0.02
    q = robot.READY_QPOS.copy()
    target = _top_down(0.6, 0.25, 0.05, 1.0)
    for _ in range(20):
        q_next = ik.step(q, target, dt)
        assert np.all(np.abs(q_next - q) <= robot.ARM_VELOCITY_LIMITS * dt + 1e-9)
        q = q_next
    index = robot.RobotIndex.from_model(ik.model)
    gripper_q = np.delete(ik.configuration.q, index.arm_qpos)
    assert gripper_q == pytest.approx(np.delete(ik._q, index.arm_qpos))


@pytest.mark.parametrize("side", [-1.0, 1.0])
def test_a_vertical_move_with_the_wrist_turned_far_does_not_wind_up_the_arm(side):
    # The wrist turned 0.08 rad short of a limit (as a grasp or a long transfer may leave it):
    # a descent by 23 cm and back needs no joint but 2, 4 and 6. A posture pull on the wrist
    # used to move the arm along its self-motion instead, here winding joints 1 and 3 by 0.73
    # and 0.63 rad (assembly dev draws 60337 and 61253 then found no way to the next object).
    from sim._motion import Segment, plan_segments

    ik = ArmIK()
    lo, hi = robot.RobotIndex.from_model(ik.model).arm_range[6]
    q0 = robot.READY_QPOS.copy()
    q0[6] = hi - 0.08 if side > 0 else lo + 0.08
    T = ik.fk(q0)
    down = T.copy()
    down[2, 3] = T[2, 3] - 0.23
    planned = plan_segments(
        ik,
        q0,
        [Segment(label="down", goal=down, duration=2.0), Segment(label="up", goal=T, duration=2.0)],
        0.02,
    )
    assert isinstance(planned, list), planned
    qs = np.concatenate([p.q for p in planned])
    drift = np.abs(qs - q0).max(axis=0)
    assert drift[[0, 2, 4, 6]] == pytest.approx(0.0, abs=0.05), np.round(drift, 2)
