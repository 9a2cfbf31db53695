"""Differential inverse kinematics of the arm's TCP, with mink.

Design rule: the IK works on its own kinematic model of the robot alone (built by
`sim.robot.build_robot_spec`, the same elements and names as in any scene), never on the
physics model, so planning can run ahead of the simulation without touching its state. The
QP has a frame task on the TCP site, a light posture task towards `READY_QPOS` on the first
six joints (not the wrist: see `ArmIK`), the gripper's DOFs frozen by an equality constraint,
and the arm's joint and velocity limits.

Two uses: `track` follows a Cartesian path tick by tick, as the executor does while it runs,
and `solve` iterates on one target until it converges or stalls (a reachability test).
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass

import mink
import mujoco
import numpy as np

from contracts import se3
from sim import robot

SOLVER = "daqp"
POSITION_TOL = 5e-4  # [m] a target counts as reached within this distance ...
ROTATION_TOL = np.radians(0.5)  # [rad] ... and this angle

# mink logs each joint outside its limits at DEBUG level on every solve; keep it quiet.
logging.getLogger("mink").setLevel(logging.WARNING)


@functools.cache
def ik_model() -> mujoco.MjModel:
    """The arm and hand alone, compiled once per process; outside MuJoCo's global mesh cache,
    which would otherwise keep the robot's collision meshes (about 23 MB) for good."""
    spec = robot.build_robot_spec(visuals=False)
    with robot.no_mesh_cache():
        return spec.compile()


@dataclass(frozen=True, kw_only=True)
class IKSolution:
    """Result of `ArmIK.solve`."""

    q: np.ndarray  # (n_arm,) arm joints [rad]
    position_error: float  # [m]
    rotation_error: float  # [rad]

    @property
    def ok(self) -> bool:
        return self.position_error <= POSITION_TOL and self.rotation_error <= ROTATION_TOL


class ArmIK:
    """mink differential IK for the FR3's TCP.

    The posture task leaves the wrist (the arm's last joint) alone. With the gripper pointing down, the
    wrist's angle follows from the grasp's yaw and the other joints; a posture pull on it, when
    a grasp or a long transfer has turned it far from READY's, moves the arm along its
    self-motion instead, on every tick of a Cartesian move whose frame task it does not
    disturb: one descent and retreat onto a place with the wrist near its limit wound joints 1,
    3 and 5 by up to 1.9 rad, and the next move above an object had no IK solution (assembly
    dev draws 60337 and 61253, `benchmarks.transfer_sweep`).

    Args:
        posture_cost: weight of the posture task on the joints before the wrist, relative to
            the frame task.
        limit_margin: distance kept from the joint limits [rad].
    """

    def __init__(self, *, posture_cost: float = 1e-3, limit_margin: float = 0.02) -> None:
        model = ik_model()
        self.model = model
        index = robot.RobotIndex.from_model(model)
        self._arm_qpos = index.arm_qpos
        self._arm_dof = index.arm_dof
        self._tcp = index.tcp_site
        self.configuration = mink.Configuration(model)
        self.frame_task = mink.FrameTask(
            robot.TCP_SITE, "site", position_cost=1.0, orientation_cost=0.5, lm_damping=1e-6
        )
        cost = np.zeros(model.nv)
        cost[self._arm_dof[:-1]] = posture_cost  # every arm joint but the wrist
        self.posture_task = mink.PostureTask(model, cost=cost)
        q_ready = np.zeros(model.nq)
        q_ready[self._arm_qpos] = robot.READY_QPOS
        self.posture_task.set_target(q_ready)
        frozen = [d for d in range(model.nv) if d not in set(self._arm_dof.tolist())]
        self._constraints = [mink.DofFreezingTask(model, dof_indices=frozen)]
        self._limits = [
            mink.ConfigurationLimit(model, min_distance_from_limits=limit_margin),
            mink.VelocityLimit(
                model, dict(zip(robot.ARM_JOINTS, robot.ARM_VELOCITY_LIMITS, strict=True))
            ),
        ]
        # The frozen gripper joints sit mid-range so that the limit margin cannot conflict
        # with the freezing constraint; they do not move the TCP.
        self._q = model.jnt_range[:, :].mean(axis=1)[np.argsort(model.jnt_qposadr)].copy()

    # -- kinematics -------------------------------------------------------------------------

    def _set(self, q_arm: np.ndarray) -> None:
        self._q[self._arm_qpos] = q_arm
        self.configuration.update(self._q)

    def fk(self, q_arm: np.ndarray) -> np.ndarray:
        """TCP pose (4, 4) in the world at arm joints `q_arm` (n_arm,) [rad]."""
        self._set(np.asarray(q_arm, dtype=float))
        return self._tcp_pose()

    def _tcp_pose(self) -> np.ndarray:
        data = self.configuration.data
        return se3.make(data.site_xmat[self._tcp].reshape(3, 3), data.site_xpos[self._tcp])

    @staticmethod
    def errors(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
        """(position [m], rotation [rad]) distance between two poses."""
        return (
            float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3])),
            se3.rotation_angle(T_a[:3, :3].T @ T_b[:3, :3]),
        )

    # -- differential steps -----------------------------------------------------------------

    def step(self, q_arm: np.ndarray, target: np.ndarray, dt: float) -> np.ndarray:
        """One IK step of `dt` [s] from `q_arm` towards the TCP pose `target` (4, 4)."""
        self._set(np.asarray(q_arm, dtype=float))
        return self._step(target, dt)

    def _step(self, target: np.ndarray, dt: float) -> np.ndarray:
        self.frame_task.set_target(mink.SE3.from_matrix(target))
        v = mink.solve_ik(
            self.configuration,
            [self.frame_task, self.posture_task],
            dt,
            SOLVER,
            damping=1e-9,
            limits=self._limits,
            constraints=self._constraints,
        )
        self.configuration.integrate_inplace(v, dt)
        return self.configuration.data.qpos[self._arm_qpos].copy()

    def track(
        self, q_arm: np.ndarray, path: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Follow a path of TCP poses, one IK step of `dt` [s] per pose.

        Args:
            q_arm: start joints (n_arm,) [rad].
            path: TCP targets (n, 4, 4), one per tick.

        Returns:
            joints (n, n_arm) after each tick and the tracking errors (n, 2): position [m],
            rotation [rad] of the TCP from its target after each tick.
        """
        self._set(np.asarray(q_arm, dtype=float))
        qs = np.empty((len(path), len(self._arm_qpos)))
        errs = np.empty((len(path), 2))
        for i, target in enumerate(path):
            qs[i] = self._step(target, dt)
            errs[i] = self.errors(self._tcp_pose(), target)
        return qs, errs

    def solve(
        self, target: np.ndarray, q_seed: np.ndarray, *, max_iters: int = 200, dt: float = 0.05
    ) -> IKSolution:
        """Iterate IK steps from `q_seed` until the TCP reaches `target` or stops moving."""
        self._set(np.asarray(q_seed, dtype=float))
        q = self.configuration.data.qpos[self._arm_qpos].copy()
        pos, rot = self.errors(self._tcp_pose(), target)
        for _ in range(max_iters):
            if pos <= POSITION_TOL * 0.2 and rot <= ROTATION_TOL * 0.2:
                break
            q_next = self._step(target, dt)
            pos, rot = self.errors(self._tcp_pose(), target)
            if np.max(np.abs(q_next - q)) < 1e-7:
                break  # stalled: at a limit or a singularity
            q = q_next
        q = self.configuration.data.qpos[self._arm_qpos].copy()
        return IKSolution(q=q, position_error=pos, rotation_error=rot)
