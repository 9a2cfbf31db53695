"""What the robot can sense while it executes a plan — the only places the executor's world
touches the objects' simulated state.

Design rule: the executor acts on its belief (perceived start poses, then the targets it placed
objects at) and on the robot's own sensors. Reading an object's true pose from the simulation
is allowed only here, each use named for what it stands for:

- `GripperSensor`: the 2F-85's own signals — how far the jaws are open (the fingers'
  kinematics, as the gripper reports its position) and whether each pad touches something
  (a pad contact sensor; it does not say *what* it touches). Failure detection uses these.
- `InHandSensor`: an estimate of the pose in the hand of the object held, or of the one between
  the open jaws just before they close, standing in for a wrist camera (the paper's ZED M):
  the true relative pose plus seeded Gaussian noise. Off, the executor is open loop after the
  grasp and takes the perceiving camera's calibration as exact.
- `ObjectTracker`: ground-truth object poses before each pick — a sensor no real robot has,
  switched on only explicitly (the oracle-sensing protocol, to show what perception costs).
- `PlacementMeter`: the placement error after each release, for scoring only (the executor
  never reads it).

The weld assist (`sim.weld`) is a physics aid, not a sensor, and is off by default.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from contracts import se3
from geometry.robot import ROBOT
from sim import robot

OBJECT_BODY_NAMES = ("{id}", "object/{id}")
"""How an object's body may be named in the model (the first that exists is used)."""


def find_body(model: mujoco.MjModel, oid: str) -> int:
    """Body id of object `oid` in the model, -1 when it is not there."""
    for pattern in OBJECT_BODY_NAMES:
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, pattern.format(id=oid))
        if body >= 0:
            return body
    return -1


def _body_pose(data: mujoco.MjData, body: int) -> np.ndarray:
    return se3.make(data.xmat[body].reshape(3, 3), data.xpos[body])


class GripperSensor:
    """The gripper's own signals: jaw opening [m] and pad contact (with anything)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, index: robot.RobotIndex):
        self.model, self.data, self.index = model, data, index
        self._left = np.array(sorted(index.left_pads))
        self._right = np.array(sorted(index.right_pads))
        self._robot = np.flatnonzero(np.isin(model.geom_bodyid, list(index.robot_bodies)))
        pads = [next(iter(index.left_pads)), next(iter(index.right_pads))]
        self._pads = pads
        self._half_thickness = float(model.geom_size[pads[0], 1])

    def opening(self) -> float:
        """Distance between the pads' inner faces [m], from the fingers' kinematics."""
        d = self.data
        base = self.index.gripper_base
        R, p = d.xmat[base].reshape(3, 3), d.xpos[base]
        a, b = ((d.geom_xpos[g] - p) @ R for g in self._pads)
        return max(0.0, abs(float(b[1] - a[1])) - 2 * self._half_thickness)

    def pads_touch(self) -> tuple[bool, bool]:
        """Whether the left and the right pad each touch something that is not the robot."""
        d = self.data
        n = d.ncon
        if n == 0:
            return False, False
        g = d.contact.geom[:n]  # (n, 2)
        other = ~np.isin(g, self._robot)
        left = np.isin(g, self._left)
        right = np.isin(g, self._right)
        touch_left = bool(np.any((left[:, 0] & other[:, 1]) | (left[:, 1] & other[:, 0])))
        touch_right = bool(np.any((right[:, 0] & other[:, 1]) | (right[:, 1] & other[:, 0])))
        return touch_left, touch_right


@dataclass(frozen=True, kw_only=True)
class InHandNoise:
    """The in-hand pose estimate's error: Gaussian, per reading [m], [rad]."""

    position: float
    rotation: float

    @property
    def exact(self) -> bool:
        return self.position == 0 and self.rotation == 0


WRIST_CAMERA = InHandNoise(
    position=ROBOT.wrist_camera.position_noise, rotation=ROBOT.wrist_camera.rotation_noise
)
"""The robot's wrist camera (`geometry.robot.ROBOT.wrist_camera`): its fitted pose of the
object in the hand, good to a few tenths of a millimetre and degree."""
EXACT = InHandNoise(position=0.0, rotation=0.0)
"""The oracle-sensing protocol's in-hand reading: the true relative pose."""


class InHandSensor:
    """A noisy estimate of the held object's pose in the TCP frame (see the module doc)."""

    def __init__(
        self,
        data: mujoco.MjData,
        index: robot.RobotIndex,
        bodies: Mapping[str, int],
        noise: InHandNoise,
        seed: int = 0,
    ) -> None:
        self.data, self.index, self.bodies, self.noise = data, index, dict(bodies), noise
        self.rng = np.random.default_rng(seed)

    def estimate(self, oid: str) -> np.ndarray | None:
        """T_tcp_object (4, 4), or None when `oid` is not in the scene."""
        if oid not in self.bodies:
            return None
        T_tcp = robot.tcp_pose(self.data, self.index)
        rel = se3.inverse(T_tcp) @ _body_pose(self.data, self.bodies[oid])
        if self.noise.exact:
            return rel
        axis = self.rng.standard_normal(3)
        angle = self.rng.standard_normal() * self.noise.rotation
        R = se3.rotvec_to_matrix(axis / max(float(np.linalg.norm(axis)), 1e-12) * angle)
        out = rel.copy()
        out[:3, :3] = R @ rel[:3, :3]
        out[:3, 3] += self.rng.standard_normal(3) * self.noise.position
        return out


class ObjectTracker:
    """Ground-truth object poses: a perfect object tracker (explicit only, see the module doc)."""

    def __init__(self, data: mujoco.MjData, bodies: Mapping[str, int]) -> None:
        self.data, self.bodies = data, dict(bodies)

    def poses(self) -> dict[str, np.ndarray]:
        return {oid: _body_pose(self.data, b) for oid, b in self.bodies.items()}


class PlacementMeter:
    """An object's placement error after a release, for scoring a step (never fed back)."""

    def __init__(self, data: mujoco.MjData, bodies: Mapping[str, int]) -> None:
        self.data, self.bodies = data, dict(bodies)

    def errors(
        self, oid: str, target: np.ndarray, symmetries: Sequence[np.ndarray]
    ) -> tuple[float, float, float]:
        """(position [m], rotation [rad], yaw [rad]) of the object against its target, modulo
        its symmetries (yaw of the symmetric alternative nearest in position)."""
        T = _body_pose(self.data, self.bodies[oid])
        pos, rot = se3.pose_error(T, target, list(symmetries))
        yaw = min(
            abs(_wrap(se3.yaw(T) - se3.yaw(target @ S)))
            for S in symmetries
            if np.linalg.norm(T[:3, 3] - (target @ S)[:3, 3]) <= pos + 1e-6
        )
        return pos, rot, float(yaw)


def _wrap(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


@dataclass(frozen=True, kw_only=True)
class Sensors:
    """Everything the executor may learn from the simulation during a plan, by what it stands
    for (see the module doc). `objects`: the ids of the scene's objects (what a plan may name;
    where they are is not in it)."""

    objects: frozenset[str]
    gripper: GripperSensor
    meter: PlacementMeter
    in_hand: InHandSensor | None = None
    tracker: ObjectTracker | None = None
    weld: Any = None  # sim.weld.WeldAssist, a physics aid

    @staticmethod
    def of(
        model: mujoco.MjModel,
        data: mujoco.MjData,
        object_ids: Sequence[str],
        *,
        in_hand: InHandNoise | None = WRIST_CAMERA,
        track_objects: bool = False,
        weld_assist: bool = False,
        seed: int = 0,
    ) -> Sensors:
        """The sensors for a scene built with `sim.robot.attach_robot` and `sim.scene`."""
        index = robot.RobotIndex.from_model(model)
        bodies = {oid: b for oid in object_ids if (b := find_body(model, oid)) >= 0}
        weld = None
        if weld_assist:
            from sim.weld import WeldAssist

            if index.weld < 0:
                raise ValueError(f"weld_assist needs the equality {robot.WELD_ASSIST!r}")
            weld = WeldAssist(model, data, index, bodies)
        return Sensors(
            objects=frozenset(bodies),
            gripper=GripperSensor(model, data, index),
            meter=PlacementMeter(data, bodies),
            in_hand=None if in_hand is None else InHandSensor(data, index, bodies, in_hand, seed),
            tracker=ObjectTracker(data, bodies) if track_objects else None,
            weld=weld,
        )
