"""The robot executor (sim.executor) on a minimal scene: a table and a few free cubes."""

from __future__ import annotations

import json
import os
from pathlib import Path

import mujoco
import numpy as np
import pytest
import trimesh

_SHARED = Path(__file__).resolve().parents[3] / "shared" / "menagerie"
if _SHARED.is_dir():
    os.environ.setdefault("MENAGERIE_ROOT", str(_SHARED))

from contracts import se3  # noqa: E402
from contracts.errors import UsageError  # noqa: E402
from sim import robot  # noqa: E402
from sim.errors import ExecutionError  # noqa: E402
from sim.executor import Executor, ExecutorConfig  # noqa: E402
from sim.sensing import EXACT, Sensors, find_body  # noqa: E402

SIZE = 0.04
CUBE = trimesh.creation.box((SIZE,) * 3)
CUBE_SYMS = se3.cube_group()


def _at(x: float, y: float, z: float = SIZE / 2, yaw: float = 0.0) -> np.ndarray:
    T = se3.rot_z(yaw)
    T[:3, 3] = [x, y, z]
    return T


def cube_scene(
    cubes: dict[str, tuple[float, float, float]],
) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Table top at z = 0, one free 40 mm cube per entry (x, y, yaw), the robot parked."""
    spec = mujoco.MjSpec()
    spec.option.timestep = 0.002
    spec.worldbody.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.65, 0.75, 0.025],
        pos=[0.35, 0.0, -0.025],
        friction=[0.8, 0.005, 0.0001],
    )
    for name, (x, y, yaw) in cubes.items():
        body = spec.worldbody.add_body(
            name=name, pos=[x, y, SIZE / 2], quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
        )
        body.add_freejoint()
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[SIZE / 2] * 3,
            mass=0.045,
            friction=[0.8, 0.005, 0.0001],
        )
    robot.attach_robot(spec)
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(robot.PARK_KEY).id)
    mujoco.mj_forward(model, data)
    return model, data


def truth(ex: Executor, oid: str) -> np.ndarray:
    """The simulated pose of an object: what the tests judge by (the executor never sees it)."""
    b = find_body(ex.model, oid)
    return se3.make(ex.data.xmat[b].reshape(3, 3), ex.data.xpos[b])


def _executor(
    cubes, *, belief=None, weld_assist=False, in_hand=EXACT, track=False, **kwargs
) -> Executor:
    """An executor on a cube scene; its belief is the cubes' true poses unless given."""
    model, data = _executor_scene(cubes)
    sensors = Sensors.of(
        model, data, list(cubes), in_hand=in_hand, track_objects=track, weld_assist=weld_assist
    )
    config = kwargs.pop("config", ExecutorConfig())
    from dataclasses import replace

    config = replace(config, in_hand=in_hand, track_objects=track)
    ex = Executor(
        model,
        data,
        {k: (CUBE, CUBE_SYMS) for k in cubes},
        belief={},
        sensors=sensors,
        config=config,
        **kwargs,
    )
    ex.belief = {k: truth(ex, k) for k in cubes} if belief is None else dict(belief)
    return ex


_executor_scene = cube_scene


def _speed(ex: Executor, oid: str) -> float:
    b = find_body(ex.model, oid)
    dof = ex.model.jnt_dofadr[ex.model.body_jntadr[b]]
    return float(np.linalg.norm(ex.data.qvel[dof : dof + 6]))


def _gripper_open_and_clear(ex: Executor, oid: str) -> bool:
    d = ex.data
    driver = d.qpos[ex.index.driver_qpos]
    touching = any(ex.sensors.gripper.pads_touch())
    return bool(np.all(driver < 0.35)) and not touching


@pytest.mark.slow
@pytest.mark.parametrize("correction", [False, True], ids=["open-loop", "in-hand-correction"])
def test_moves_a_cube_from_a_to_b_and_parks(correction):
    ex = _executor(
        {"a": (0.5, 0.0, 0.0), "b": (0.42, 0.18, 0.4)},
        config=ExecutorConfig(in_hand_correction=correction),
    )
    target = _at(0.58, -0.15, yaw=0.6)
    result = ex.execute(
        {"status": "ok", "steps": [{"object": "a", "target_pose": target.tolist()}]}
    )
    assert result.ok, result.failure
    step = result.steps[0]
    assert step.position_error < 0.003
    assert step.yaw_error < np.radians(2.0)
    T = truth(ex, "a")
    assert se3.within_tolerance(
        T, target, trans_tol=0.003, rot_tol=np.radians(2), symmetries=CUBE_SYMS
    )
    assert _gripper_open_and_clear(ex, "a")
    assert _speed(ex, "a") < 1e-3 and _speed(ex, "b") < 1e-3  # at rest
    assert truth(ex, "b")[:3, 3] == pytest.approx([0.42, 0.18, SIZE / 2], abs=1e-3)
    arm = ex.data.qpos[ex.index.arm_qpos]
    assert np.max(np.abs(arm - robot.PARK_QPOS)) < 0.01
    assert [p for p, _ in step.phases] == [
        "unpark",
        "grasp",
        "approach",
        "close",
        "lift",
        "transfer",
        "place",
        "release",
        "done",
    ]
    assert result.sim_time > 0 and result.realtime_factor > 1.0
    assert not step.weld_engaged
    record = json.loads(json.dumps(result.to_dict()))  # the harness stores it as JSON
    assert record["ok"] and record["steps"][0]["object"] == "a"


@pytest.mark.slow
def test_stacks_one_cube_on_another_with_the_weld_assist():
    ex = _executor({"a": (0.45, 0.1, 0.0), "b": (0.55, -0.1, 0.3)}, weld_assist=True)
    base = truth(ex, "b")
    on_top = base @ se3.make(t=[0, 0, SIZE]) @ se3.rot_z(0.2)
    result = ex.execute([{"object": "a", "target_pose": on_top}])
    assert result.ok, result.failure
    assert result.steps[0].weld_engaged
    assert ex.data.eq_active[ex.index.weld] == 0  # released with the fingers
    assert se3.within_tolerance(
        truth(ex, "a"), on_top, trans_tol=0.003, rot_tol=np.radians(2), symmetries=CUBE_SYMS
    )
    assert truth(ex, "b")[:3, 3] == pytest.approx(base[:3, 3], abs=2e-3)


def _failure(ex: Executor, plan):
    result = ex.execute(plan)
    assert not result.ok
    assert result.failure is not None
    with pytest.raises(ExecutionError) as info:
        result.raise_for_failure()
    return result, result.failure, info.value


def test_unknown_object_fails_before_anything_moves():
    ex = _executor({"a": (0.5, 0.0, 0.0)})
    q0 = ex.data.qpos.copy()
    plan = [
        {"object": "a", "target_pose": _at(0.5, 0.1)},
        {"object": "ghost", "target_pose": _at(0.5, -0.1)},
    ]
    _, failure, error = _failure(ex, plan)
    assert (failure.step, failure.object, failure.kind, failure.phase) == (
        1,
        "ghost",
        "unknown_object",
        "validate",
    )
    assert "'ghost'" in failure.reason and "known: a" in failure.reason
    assert error.step == 1 and "ghost" in str(error)
    assert np.max(np.abs(ex.data.qpos[ex.index.arm_qpos] - q0[ex.index.arm_qpos])) < 1e-3
    assert truth(ex, "a")[:3, 3] == pytest.approx([0.5, 0.0, SIZE / 2], abs=1e-3)


@pytest.mark.parametrize(
    "pose",
    [
        np.diag([1.0, 1.0, -1.0, 1.0]) + se3.make(t=[0.5, 0.1, 0.02]) - np.eye(4),  # a mirror
        np.diag([2.0, 1.0, 1.0, 1.0]),  # a scale
        [[1, 0, 0], [0, 1, 0], [0, 0, 1]],  # not 4×4
        np.full((4, 4), np.nan),
    ],
    ids=["mirror", "scale", "3x3", "nan"],
)
def test_non_rigid_target_fails_naming_the_step(pose):
    ex = _executor({"a": (0.5, 0.0, 0.0)})
    _, failure, _ = _failure(ex, [{"object": "a", "target_pose": pose}])
    assert (failure.step, failure.object, failure.kind) == (0, "a", "non_rigid_target")


@pytest.mark.slow
def test_unreachable_target_fails_naming_the_step():
    ex = _executor({"a": (0.5, 0.0, 0.0)})
    _, failure, _ = _failure(ex, [{"object": "a", "target_pose": _at(1.3, 0.0)}])
    assert (failure.step, failure.object, failure.kind) == (0, "a", "unreachable")
    assert "no IK solution" in failure.reason
    assert truth(ex, "a")[:3, 3] == pytest.approx([0.5, 0.0, SIZE / 2], abs=1e-3)


def test_a_plan_must_be_a_list_of_steps():
    ex = _executor({"a": (0.5, 0.0, 0.0)})
    with pytest.raises(UsageError):
        ex.execute({"status": "infeasible", "reason": "no"})
    with pytest.raises(UsageError):
        ex.execute([{"object": "a"}])


@pytest.mark.slow
def test_records_frames_at_the_configured_rate():
    frames = []
    ex = _executor(
        {"a": (0.5, 0.0, 0.0)},
        record=lambda model, data: frames.append(data.time),
        config=ExecutorConfig(record_fps=10.0),
    )
    result = ex.execute([{"object": "a", "target_pose": _at(0.45, 0.12, yaw=0.3)}])
    assert result.ok, result.failure
    assert result.frames == len(frames)
    assert len(frames) == pytest.approx(result.sim_time * 10.0, abs=2)


def _mesh_scene(objects: dict[str, tuple[list[trimesh.Trimesh], np.ndarray, float]]):
    """Table plus one free body per entry: (convex parts, pose, mass); the robot parked."""
    spec = mujoco.MjSpec()
    spec.worldbody.add_geom(
        type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.65, 0.75, 0.025], pos=[0.35, 0.0, -0.025]
    )
    for name, (parts, pose, mass) in objects.items():
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, pose[:3, :3].ravel())
        body = spec.worldbody.add_body(name=name, pos=pose[:3, 3], quat=quat)
        body.add_freejoint()
        volume = sum(p.volume for p in parts)
        for i, part in enumerate(parts):
            spec.add_mesh(
                name=f"{name}/{i}",
                uservert=part.vertices.ravel().tolist(),
                userface=part.faces.ravel().tolist(),
            )
            body.add_geom(
                type=mujoco.mjtGeom.mjGEOM_MESH,
                meshname=f"{name}/{i}",
                mass=mass * part.volume / volume,
                friction=[0.8, 0.005, 0.0001],
            )
    robot.attach_robot(spec)
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(robot.PARK_KEY).id)
    mujoco.mj_forward(model, data)
    return model, data


@pytest.mark.slow
def test_a_knob_plate_and_a_tall_pillar_are_placed_precisely():
    plate = trimesh.creation.box((0.09, 0.09, 0.015))  # too wide for the jaws: the knob it is
    plate.apply_translation((0, 0, 0.0075))
    knob = trimesh.creation.box((0.015, 0.015, 0.015))
    knob.apply_translation((0, 0, 0.0225))
    pillar = trimesh.creation.box((0.03, 0.03, 0.08))
    pillar.apply_translation((0, 0, 0.04))
    model, data = _mesh_scene(
        {
            "plate": ([plate, knob], _at(0.4, 0.17, 0.0, 0.3), 0.08),
            "pillar": ([pillar], _at(0.6, -0.15, 0.0, -0.4), 0.06),
        }
    )
    quarter_turns = [se3.rot_z(a) for a in (0.0, np.pi / 2, np.pi, 3 * np.pi / 2)]
    ex = Executor(
        model,
        data,
        {
            "plate": (trimesh.util.concatenate([plate, knob]), quarter_turns),
            "pillar": (pillar, quarter_turns),
        },
        belief={},
        sensors=Sensors.of(model, data, ["plate", "pillar"], in_hand=EXACT),
        config=ExecutorConfig(in_hand=EXACT),
    )
    ex.belief = {k: truth(ex, k) for k in ("plate", "pillar")}
    # The plate goes beside the pillar's target, 2 mm apart.
    plan = [
        {"object": "pillar", "target_pose": _at(0.5, 0.0, 0.0, 0.2)},
        {"object": "plate", "target_pose": _at(0.5, 0.0, 0.0, 0.2) @ se3.make(t=[0.0, 0.062, 0.0])},
    ]
    result = ex.execute(plan)
    assert result.ok, result.failure
    for step in result.steps:
        assert step.position_error < 0.003 and step.yaw_error < np.radians(2.0), step
    assert result.steps[1].grasp.width == pytest.approx(0.015, abs=1e-6)


def _asymmetric(x: float, y: float, yaw: float) -> Executor:
    """One cube at (x, y, yaw) that counts as asymmetric: its target yaw is exact."""
    model, data = cube_scene({"c": (x, y, yaw)})
    ex = Executor(
        model,
        data,
        {"c": (CUBE, None)},
        belief={},
        sensors=Sensors.of(model, data, ["c"], in_hand=EXACT),
        config=ExecutorConfig(in_hand=EXACT),
    )
    ex.belief = {"c": truth(ex, "c")}
    return ex


@pytest.mark.slow
@pytest.mark.parametrize(
    ("yaw", "turn", "how"),
    [(0.0, 159.0, "long way"), (140.0, 145.0, "joint space")],
    ids=["transfer-turns-the-long-way", "approach-in-joint-space"],
)
def test_a_turn_the_wrist_cannot_take_the_short_way(yaw, turn, how):
    # beside the robot on its left, turned by 145–160° on the way to the right: the geodesic
    # wrist turn runs joint 7 into its limit from the configuration the move starts in
    target = _at(0.5, -0.2, yaw=np.radians(yaw + turn))
    ex = _asymmetric(0.36, 0.24, np.radians(yaw))
    ex._unpark()
    chosen = ex.transfers.choose(
        ex._q_cmd, ex._grip_cmd, CUBE, [np.eye(4)], ex.belief["c"], target, []
    )
    joint_approach = any(
        p.segment.label == "moving above the object" and p.segment.q_goal is not None
        for p in chosen.pick
    )
    assert (chosen.long_way, joint_approach) == (
        (True, False) if how == "long way" else (False, True)
    )
    ex = _asymmetric(0.36, 0.24, np.radians(yaw))
    result = ex.execute([{"object": "c", "target_pose": target}])
    assert result.ok, result.failure
    assert result.steps[0].position_error < 0.002
    assert result.steps[0].yaw_error < np.radians(1.0)


@pytest.mark.parametrize("noise", [1e-12, 0.0, -1e-12])
def test_a_half_turn_transfer_goes_each_way_round_once(noise):
    # A part with a half-turn symmetry (a beam) is often carried by exactly half a turn: the
    # short way and the long way are then the two sides, each tried once. The geodesic of a
    # half turn has no preferred side (float noise picks one), so it could take the long
    # way's side twice and run the wrist into the limit the other side avoids.
    ex = _asymmetric(0.45, 0.1, 0.0)
    target = _at(0.5, -0.05, yaw=np.pi)
    target[:3, :3] = target[:3, :3] @ se3.rotvec_to_matrix([0.0, 0.0, noise])
    ex._unpark()
    chosen = ex.transfers.choose(
        ex._q_cmd, ex._grip_cmd, CUBE, [np.eye(4)], ex.belief["c"], target, []
    )
    turns = [
        ex.transfers.place_motion(chosen.grasp, chosen.grasp.place_tcp, 0.25, way)[0].turn
        for way in (False, True)
    ]
    assert sorted(np.abs(turns)) == pytest.approx([np.pi, np.pi], abs=1e-6)
    assert turns[0] == pytest.approx(-turns[1])


def _walk_a_dev_draw(seed: int) -> tuple[int, tuple[int, str | None]]:
    import domains
    from benchmarks.transfer_sweep import planner, walk
    from sim.settle import physical_problems
    from sim.trials import OraclePolicy

    domain = domains.load("assembly")
    instance = domain.generate(seed, physics=physical_problems, split="dev")
    steps = OraclePolicy().solve_from_truth(instance, domain).plan["steps"]
    return len(steps), walk(domain, instance.start["objects"], steps, planner())


@pytest.mark.slow
def test_a_dev_draw_whose_beam_turns_half_round_plans_through():
    # a fresh dev draw, found by `python -m benchmarks.transfer_sweep --seed 60000`: step 2
    # carries the beam by half a turn, and the geodesic ran 36 mm short from the configuration
    # step 1 left the arm in. Which side a geodesic half turn takes depends on the poses' last
    # bits (the same draw read back from its JSON file planned through), so the draw is made
    # here, as the sweep made it.
    n, walked = _walk_a_dev_draw(60090)
    assert walked == (n, None)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [60337, 61253])
def test_a_dev_draw_whose_place_leaves_the_wrist_at_its_limit_plans_through(seed):
    # fresh dev draws, found by `python -m benchmarks.transfer_sweep --seed 60000` and
    # `--seed 61000`: step 7 places a part where every grasp leaves the wrist at its limit;
    # the IK's posture pull on the wrist wound the arm up along the descent and the retreat,
    # and step 8's move above the next part ran 400 mm short.
    n, walked = _walk_a_dev_draw(seed)
    assert walked == (n, None)


@pytest.mark.slow
def test_a_place_the_cartesian_transfers_leave_out_of_reach_is_made_with_a_joint_transfer():
    # dev goal10_start1, step 0: for the L-block's best grasp the short transfer runs 16 mm
    # off, and the long one ends with the wrist at its limit, from where the descent runs 34 mm
    # off (the planner fell back to the third grasp). Allowed that one grasp only, the planner
    # carries the block in joint space to a fresh IK solution above its place; the trial
    # succeeds in the simulator.
    import domains
    from benchmarks.transfer_sweep import planner
    from sim.transfer import TransferPlanner, _fingertips, obstacles
    from sim.trials import OraclePolicy, run_trial

    domain = domains.load("assembly")
    instance = next(i for i in domain.benchmark("dev") if i.name == "goal10_start1")
    config = ExecutorConfig(max_grasp_candidates=1)
    executors = planner()
    transfers = TransferPlanner(executors.ik, config, executors.wrist, executors.tick_dt)
    step = OraclePolicy().solve_from_truth(instance, domain).plan["steps"][0]
    records = {r["id"]: r for r in instance.start["objects"]}
    belief = {o: np.asarray(r["pose"], float) for o, r in records.items()}
    meshes = {o: domain.mesh(r["mesh"]) for o, r in records.items()}
    oid = step["object"]
    chosen = transfers.choose(
        robot.READY_QPOS,
        robot.GRIPPER_OPEN,
        meshes[oid],
        list(domain.symmetries(records[oid]["mesh"])),
        belief[oid],
        np.asarray(step["target_pose"], float),
        obstacles(belief, meshes, oid),
    )
    assert chosen.transfer_q is not None
    # the held block and the fingertips are kept clear along that move: not above the
    # transfer height itself, which they hang below
    held = np.vstack([meshes[oid].vertices, _fingertips(chosen.grasp)])
    q_lift = chosen.pick[-1].q[-1]
    for floor, found in ((chosen.transfer_z, False), (-1.0, True)):
        q = transfers._joint_transfer(q_lift, chosen.grasp, held, floor, chosen.transfer_z)
        assert (q is not None) == found

    result = run_trial(domain, instance, OraclePolicy(), config=config)
    assert result.final_ok, result.failure
    assert result.steps[0]["ok"] and result.steps[0]["position_error"] < 0.002


def test_turn_poses_go_the_long_way_round_and_end_on_the_goal():
    from sim._motion import turn_poses

    down = se3.make(np.diag([1.0, -1.0, -1.0]), [0.4, 0.2, 0.2])  # TCP pointing down
    goal = se3.rot_z(np.radians(150.0)) @ down
    goal[:3, :3] = goal[:3, :3] @ se3.rotvec_to_matrix([0.02, 0.0, 0.0])  # and a small tilt
    goal[:3, 3] = [0.5, -0.2, 0.2]
    turn = np.radians(150.0 - 360.0)
    path = turn_poses(down, goal, np.linspace(0.0, 1.0, 5), turn)
    assert np.allclose(path[0], down) and np.allclose(path[-1], goal, atol=1e-9)
    # halfway the x axis of the TCP has turned by turn / 2 = -105°, not by +75°
    mid = path[2][:3, :3] @ down[:3, :3].T
    assert np.degrees(np.arctan2(mid[1, 0], mid[0, 0])) == pytest.approx(-105.0, abs=1.0)


# -- the executor acts on its belief, not on the simulator (#15.1) -----------------------------


@pytest.mark.slow
@pytest.mark.parametrize("track", [False, True], ids=["belief-only", "tracking-sensor"])
def test_a_grasp_goes_where_the_robot_believes_the_object_is(track):
    # the robot's belief puts cube a 3 cm from where it is: the fingers close on air, unless
    # the explicitly enabled tracking sensor (ground truth, a protocol option) corrects it
    cubes = {"a": (0.5, 0.0, 0.0)}
    believed = _at(0.5, 0.03)
    ex = _executor(cubes, belief={"a": believed}, track=track)
    result = ex.execute([{"object": "a", "target_pose": _at(0.42, 0.15, yaw=0.3)}])
    if track:
        assert result.ok, result.failure
        assert truth(ex, "a")[:3, 3] == pytest.approx([0.42, 0.15, SIZE / 2], abs=3e-3)
    else:
        assert not result.ok
        # the gripper's own signals tell: nothing between the jaws, or it slid out on the way
        assert result.failure.step == 0
        assert result.failure.kind in {"grasp_failed", "dropped"}, result.failure
        assert (
            "nothing is held" in result.failure.reason or "left the hand" in result.failure.reason
        )
        assert truth(ex, "a")[:3, 3] == pytest.approx([0.5, 0.0, SIZE / 2], abs=5e-3)


@pytest.mark.slow
@pytest.mark.parametrize("estimate", [False, True], ids=["as-believed", "offset-estimated"])
def test_a_camera_offset_read_at_the_first_grasp_is_taken_off_every_target(estimate):
    # the camera that perceived the start and the goal is 5 mm off: the belief and the plan's
    # targets are shifted alike. With the jaws open around the first cube the wrist camera
    # shows where it is; the executor takes that offset off both targets
    shift = np.array([0.004, -0.003, 0.0])
    cubes = {"a": (0.5, 0.0, 0.0), "b": (0.42, 0.18, 0.4)}
    ex = _executor(cubes, config=ExecutorConfig(camera_offset=estimate))
    ex.belief = {k: se3.make(t=shift) @ T for k, T in ex.belief.items()}
    goals = {"a": _at(0.58, -0.15, yaw=0.6), "b": _at(0.5, 0.1)}
    result = ex.execute(
        [{"object": k, "target_pose": se3.make(t=shift) @ T} for k, T in goals.items()]
    )
    assert result.ok, result.failure
    off = {k: float(np.linalg.norm(truth(ex, k)[:2, 3] - T[:2, 3])) for k, T in goals.items()}
    if estimate:
        assert ex.camera_offset == pytest.approx(shift[:2], abs=1e-3)
        assert max(off.values()) < 0.0015, off
        assert [s.camera_offset is not None for s in result.steps] == [True, True]
        # what the robot believes stays in the camera's frame: where the plan said
        assert np.allclose(ex.belief["a"], se3.make(t=shift) @ goals["a"])
    else:
        assert ex.camera_offset is None
        assert min(off.values()) > 0.004, off


def test_a_reading_far_from_the_belief_is_the_object_misperceived_not_the_camera():
    ex = _executor({"a": (0.5, 0.0, 0.0)})
    ex.belief = {"a": _at(0.5, 0.02)}
    ex._read_offset("a")
    assert ex.camera_offset is None
    ex.belief = {"a": _at(0.5, 0.004)}
    ex._read_offset("a")
    assert ex.camera_offset == pytest.approx((0.0, 0.004), abs=1e-5)


@pytest.mark.slow
def test_after_a_placement_the_belief_is_the_plan_target_not_the_outcome():
    # with the tracker off the executor's belief of a moved object is where it put it: the
    # target (what the robot commanded), whatever the physics did with it
    ex = _executor({"a": (0.5, 0.0, 0.0), "b": (0.42, 0.18, 0.4)})
    target = _at(0.45, -0.12, yaw=0.2)
    result = ex.execute([{"object": "a", "target_pose": target}])
    assert result.ok, result.failure
    assert np.allclose(ex.belief["a"], target)
    assert not np.allclose(truth(ex, "a"), target, atol=1e-6)  # the world differs a little


def test_the_robot_cannot_move_what_it_did_not_perceive():
    ex = _executor({"a": (0.5, 0.0, 0.0), "b": (0.42, 0.18, 0.4)}, belief={})
    ex.belief = {"a": truth(ex, "a")}  # b was not perceived
    _, failure, _ = _failure(ex, [{"object": "b", "target_pose": _at(0.5, 0.1)}])
    assert (failure.step, failure.object, failure.kind) == (0, "b", "not_perceived")


_GROUND_TRUTH_READS = {"xpos", "xmat", "xquat", "xipos", "ximat", "qpos", "qvel", "sensordata"}
_GROUND_TRUTH_CALLS = {"mj_name2id", "find_body", "name2id"}


@pytest.mark.parametrize("module", ["sim/executor.py", "sim/transfer.py"])
def test_the_executors_decisions_never_read_the_simulated_object_poses(module):
    # the executor and its motion planning see the world only through `sim.sensing` (gripper,
    # in-hand camera, the optional tracker) and the robot's own joints (`sim.robot`'s index):
    # no attribute access of body poses or object lookups by name in their source
    import ast

    source = (Path(__file__).resolve().parents[2] / module).read_text()
    offending = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr in _GROUND_TRUTH_READS - {"qpos", "qvel"}:
            offending.append(f"line {node.lineno}: .{node.attr}")
        if isinstance(node, ast.Attribute | ast.Name):
            name = node.attr if isinstance(node, ast.Attribute) else node.id
            if name in _GROUND_TRUTH_CALLS:
                offending.append(f"line {node.lineno}: {name}")
        if (
            isinstance(node, ast.Subscript)
            and isinstance(node.value, ast.Attribute)
            and node.value.attr in {"qpos", "qvel"}
        ):
            # joint state only through the robot's own index (arm, driver) — never an
            # object's free joint
            index = ast.unparse(node.slice)
            if not index.startswith(("self.index.", "ex.index.", "index.", "idx.")):
                offending.append(f"line {node.lineno}: {ast.unparse(node)}")
    assert not offending, f"{module} reads simulator state directly: {offending}"


@pytest.mark.slow
def test_a_symmetric_object_believed_in_another_of_its_frames_is_held_as_planned():
    # perception may report a cube in any of its 24 equivalent frames; the in-hand estimate
    # comes in the body's own frame: the executor must correct with the equivalent frame its
    # grasp expects, or it turns the hand a quarter turn at the place (and the fingers go
    # where the grasp check never looked)
    from sim import robot as sim_robot

    tcp_at = []
    ex = _executor(
        {"a": (0.5, 0.0, 0.0), "b": (0.42, 0.18, 0.4)},
        record=lambda model, data: tcp_at.append((data.time, sim_robot.tcp_pose(data, ex.index))),
        config=ExecutorConfig(record_fps=25.0),
    )
    ex.belief["a"] = ex.belief["a"] @ se3.rot_z(np.pi / 2)  # the same cube, another frame
    result = ex.execute([{"object": "a", "target_pose": _at(0.45, -0.12, yaw=0.3)}])
    assert result.ok, result.failure
    step = result.steps[0]
    assert step.position_error < 0.002
    release = dict(step.phases)["release"]
    T = min(tcp_at, key=lambda tT: abs(tT[0] - release))[1]
    planned = step.grasp.place_tcp
    turn = np.degrees(np.arctan2(*(planned[:3, :3].T @ T[:3, :3])[[1, 0], 0]))
    assert min(abs(turn), 180.0 - abs(turn)) < 5.0, f"the hand is {turn:.0f}° off its grasp"
