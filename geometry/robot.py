"""The robot description: the arm, the gripper and the numbers every part is built from.

Design rule: one record, `ROBOT`, says which robot RIVET drives — the arm's joints, limits and
postures, where it reaches, the gripper's stroke, fingers and tool frame, the wrist camera's
accuracy. The simulator builds its robot from it (`sim.robot`: which menagerie models, joint
names and ranges, the TCP site, the park posture), the IK takes its joints, limits and posture
from it (`sim.ik`), the executor its in-hand estimate (`sim.sensing`), the hand model its
gripper (`geometry.grasps`, `geometry.clearance`, `geometry.moves`), and the toolbox the facts
it shows programs (`toolbox.robot`), which the check rules and the prompts quote. No other
module spells a number of the robot; the names of the menagerie models' own elements (pads,
drivers, the flange site) stay in `sim.robot`, which reads them.

The default is a Franka Research 3 arm with a Robotiq 2F-85 gripper, from MuJoCo Menagerie.
The gripper's numbers were measured from the menagerie model (`sim.robot.measure_stroke` for the
stroke, its collision geometry for the finger boxes); the joint ranges and speeds are Franka's
datasheet, as the menagerie model states them. `tests/sim/test_robot.py` measures the model
again and compares.

`RIVET_ROBOT=FILE.json` replaces the default with another description (`Robot.to_json` writes
one, `Robot.from_json` reads it): every consumer, the frozen sets' `toolbox_hash` included
(`artifacts.hashing`), then follows it. The simulator still loads the menagerie models the
description names, so a description must say what those models are.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from geometry.plans import Workspace

ENV = "RIVET_ROBOT"  # a JSON description replacing `DEFAULT`


@dataclass(frozen=True, kw_only=True)
class GripperStroke:
    """How the jaws move with the gripper's control (measured in simulation for the 2F-85:
    its pads travel on an arc, so the fingertips' depth along the TCP's z axis depends on the
    opening).

    Attributes:
        ctrl: (n,) increasing control values, from `Gripper.control`'s open to its closed.
        gap: (n,) distance between the pads' inner faces [m], decreasing.
        tip: (n,) fingertip depth along the TCP z axis, from the TCP [m].
        pad_height: contact height of a pad, from its tip towards the palm [m].
        pad_width: pad width across the closing direction [m].
        max_gap: the widest opening [m].
    """

    ctrl: np.ndarray
    gap: np.ndarray
    tip: np.ndarray
    pad_height: float
    pad_width: float
    max_gap: float

    def ctrl_for_gap(self, gap: float) -> float:
        """Control value that opens the jaws to `gap` [m] (clipped to the stroke)."""
        return float(np.interp(gap, self.gap[::-1], self.ctrl[::-1]))

    def tip_at_gap(self, gap: float) -> float:
        """Fingertip depth along the TCP z axis [m] when the jaws are `gap` [m] apart."""
        return float(np.interp(gap, self.gap[::-1], self.tip[::-1]))

    def to_json(self) -> dict[str, Any]:
        return {
            "ctrl": self.ctrl.tolist(),
            "gap": self.gap.tolist(),
            "tip": self.tip.tolist(),
            "pad_height": self.pad_height,
            "pad_width": self.pad_width,
            "max_gap": self.max_gap,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> GripperStroke:
        return cls(
            ctrl=np.asarray(data["ctrl"], dtype=float),
            gap=np.asarray(data["gap"], dtype=float),
            tip=np.asarray(data["tip"], dtype=float),
            pad_height=float(data["pad_height"]),
            pad_width=float(data["pad_width"]),
            max_gap=float(data["max_gap"]),
        )


@dataclass(frozen=True, kw_only=True)
class FingerModel:
    """Boxes around the gripper's fingers and palm, in the TCP frame [m].

    For the 2F-85, measured from the menagerie model's collision geometry over the whole stroke. Each finger
    is a stack of boxes, `segments`, given as (from, to) height above the fingertip, how far
    the finger reaches outwards beyond its pad's contact face, and its half width across the
    closing direction. From `linkage_from` up to `palm_from` the couplers and drivers reach out
    to at least `linkage_outer` from the centre line (they splay as the jaws close). Above
    that, `palm` boxes (from, to, x_min, x_max, y_min, y_max) in the TCP frame: the gripper's
    base, then the arm's last link (the FR3's link 7), which is rigid with the TCP and juts out on one side (so the
    two wrist yaws of a grasp differ); the last box reaches 1 m up and stands for the arm.
    """

    segments: tuple[tuple[float, float, float, float], ...]
    linkage_from: float
    linkage_outer: float
    linkage_depth: float
    linkage_half_width: float
    palm_from: float
    palm: tuple[tuple[float, float, float, float, float, float], ...]
    clearances: tuple[float, ...]
    """Jaw opening beyond the object's width, per side, for the approach and the release: the
    first that clears the neighbours is used [m]."""
    min_clearance: float  # the least per-side opening allowed for wide objects [m]
    tip_margin: float  # fingertips stay this far above whatever is below them [m]
    min_contact: float  # the least pad contact height accepted [m]
    high_contact: float  # contact height of the alternative grasp high on a face [m]
    ceiling: tuple[tuple[float, float], ...]
    """(jaw gap, free height above the fingertips between the fingers) [m]: above it the spring
    links and the base close the space between the jaws; the wider open, the lower."""
    inner_half_width: float  # half width of that closed space across the closing direction [m]

    @property
    def depth(self) -> float:
        """How far a fingertip reaches outwards from its pad's contact face [m]."""
        return self.segments[0][2]

    @property
    def width(self) -> float:
        """A fingertip's width across the closing direction [m]."""
        return 2 * self.segments[0][3]

    def ceiling_at(self, gap: float) -> float:
        """Free height between the fingers above their tips at jaw opening `gap` [m]."""
        gaps, heights = zip(*self.ceiling, strict=True)
        return float(np.interp(gap, gaps, heights))

    def boxes(self, gap: float, tip: float, margin: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """Boxes (centre (3,), half extents (3,)) in the TCP frame (z towards the fingertips)
        for jaws `gap` apart with the fingertips at depth `tip`, inflated by `margin`."""
        out = []
        y0 = gap / 2
        layers = [(lo, hi, y0, y0 + depth, hw) for lo, hi, depth, hw in self.segments]
        outer = max(y0 + self.linkage_depth, self.linkage_outer)
        layers.append((self.linkage_from, self.palm_from, y0, outer, self.linkage_half_width))
        for lo, hi, y_in, y_out, hw in layers:
            for side in (-1.0, 1.0):
                centre = np.array([0.0, side * (y_in + y_out) / 2, tip - (lo + hi) / 2])
                half = np.array([hw, (y_out - y_in) / 2, (hi - lo) / 2]) + margin
                out.append((centre, half))
        ceiling = self.ceiling_at(gap)
        centre = np.array([0.0, 0.0, tip - ceiling - 0.5])
        half = np.array([self.inner_half_width, y0, 0.5]) + np.array([margin, 0.0, margin])
        out.append((centre, half))
        for lo, hi, x0, x1, y_lo, y_hi in self.palm:
            centre = np.array([(x0 + x1) / 2, (y_lo + y_hi) / 2, tip - (lo + hi) / 2])
            half = np.array([(x1 - x0) / 2, (y_hi - y_lo) / 2, (hi - lo) / 2]) + margin
            out.append((centre, half))
        return out


@dataclass(frozen=True, kw_only=True)
class Arm:
    """The arm, top-down over a table in front of it.

    Attributes:
        name: a short name, for messages and rule texts ("FR3").
        full_name: the name in full, for the prompts ("Franka FR3").
        model: (menagerie folder, model file stem) the simulator loads.
        joints: the arm's joint names in that model, base to flange; the actuators are named
            after them.
        joint_ranges: per joint, (lowest, highest) [rad]; the last is the wrist (the flange
            about the tool axis), which a held object turns with (`wrist_range`).
        velocity_limits: per joint [rad/s].
        park: joint angles for observations [rad]: out of the cameras' sight.
        ready: joint angles above the workspace, the IK's posture target [rad].
        workspace: where it reaches top-down with the gripper; every point of an object it
            picks or places must lie inside.
        placement: where the task's scenes keep their objects, inside `workspace`, with the
            arm comfortably within reach (near the workspace's edge the wrist runs out of
            range): generators draw inside it, plans put objects aside in it.
        placement_spread: (gap, max shift) [m]: a tightly packed goal is placed reliably once
            its gaps are opened to `gap`, moving no part more than `max shift`.
    """

    name: str
    full_name: str
    model: tuple[str, str]
    joints: tuple[str, ...]
    joint_ranges: tuple[tuple[float, float], ...]
    velocity_limits: tuple[float, ...]
    park: tuple[float, ...]
    ready: tuple[float, ...]
    workspace: Workspace
    placement: Workspace
    placement_spread: tuple[float, float]

    def __post_init__(self) -> None:
        n = len(self.joints)
        for name in ("joint_ranges", "velocity_limits", "park", "ready"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"Arm.{name} has {len(getattr(self, name))} values for {n} joints")

    @property
    def wrist_range(self) -> tuple[float, float]:
        """The last joint's range [rad]: a held object turns with it."""
        return self.joint_ranges[-1]


@dataclass(frozen=True, kw_only=True)
class Gripper:
    """The parallel-jaw gripper on the arm's flange.

    Attributes:
        name: a short name, for messages and rule texts ("2F-85").
        full_name: the name in full, for the prompts ("Robotiq 2F-85").
        model: (menagerie folder, model file stem) the simulator attaches.
        tcp_offset: the tool centre point along the gripper's z axis from its base [m]: the
            pads' centre when closed. The TCP frame's z axis points out of the gripper (the
            approach direction), its y axis along the jaws' closing direction.
        control: (fully open, fully closed) actuator control values.
        max_grasp_width: the widest face pair the jaws take [m] (they open to `stroke.max_gap`).
        stroke: how the jaws open with the control.
        fingers: the boxes around the fingers, linkage and palm.
    """

    name: str
    full_name: str
    model: tuple[str, str]
    tcp_offset: float
    control: tuple[float, float]
    max_grasp_width: float
    stroke: GripperStroke
    fingers: FingerModel


@dataclass(frozen=True, kw_only=True)
class WristCamera:
    """The camera on the wrist that estimates the held object's pose after a grasp.

    Attributes:
        position_noise: the estimate's error, Gaussian, per reading [m].
        rotation_noise: likewise about a random axis [rad].
    """

    position_noise: float
    rotation_noise: float


@dataclass(frozen=True, kw_only=True)
class Robot:
    """An arm with a gripper and a wrist camera: what RIVET drives (`ROBOT`)."""

    arm: Arm
    gripper: Gripper
    wrist_camera: WristCamera

    @property
    def name(self) -> str:
        return f"{self.arm.name} with a {self.gripper.name}"

    def to_json(self) -> dict[str, Any]:
        """The description as JSON values (`from_json` reads them back)."""
        arm = asdict(self.arm)
        gripper = {f.name: getattr(self.gripper, f.name) for f in fields(self.gripper)}
        gripper["stroke"] = self.gripper.stroke.to_json()
        gripper["fingers"] = asdict(self.gripper.fingers)
        camera = asdict(self.wrist_camera)
        return json.loads(json.dumps({"arm": arm, "gripper": gripper, "wrist_camera": camera}))

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Robot:
        """A description from JSON values (as `to_json` writes them); KeyError / TypeError /
        ValueError name what is missing or malformed."""
        a, g = dict(data["arm"]), dict(data["gripper"])
        for key in ("workspace", "placement"):
            w = a[key]
            a[key] = Workspace(x=_pair(w["x"]), y=_pair(w["y"]), reach=float(w["reach"]))
        for key in ("model", "joints", "velocity_limits", "park", "ready"):
            a[key] = tuple(a[key])
        a["joint_ranges"] = tuple(_pair(r) for r in a["joint_ranges"])
        a["placement_spread"] = _pair(a["placement_spread"])
        g["model"], g["control"] = tuple(g["model"]), _pair(g["control"])
        g["stroke"] = GripperStroke.from_json(g["stroke"])
        g["fingers"] = FingerModel(**{k: _tuples(v) for k, v in g["fingers"].items()})
        camera = WristCamera(**{k: float(v) for k, v in data["wrist_camera"].items()})
        return cls(arm=Arm(**a), gripper=Gripper(**g), wrist_camera=camera)


def _pair(v: Any) -> tuple[float, float]:
    a, b = v
    return (float(a), float(b))


def _tuples(v: Any) -> Any:
    return tuple(_tuples(x) for x in v) if isinstance(v, list | tuple) else v


DEFAULT = Robot(
    arm=Arm(
        name="FR3",
        full_name="Franka FR3",
        model=("franka_fr3", "fr3"),
        joints=tuple(f"fr3_joint{i}" for i in range(1, 8)),
        joint_ranges=(
            (-2.7437, 2.7437),
            (-1.7837, 1.7837),
            (-2.9007, 2.9007),
            (-3.0421, -0.1518),
            (-2.8065, 2.8065),
            (0.5445, 4.5169),
            (-3.0159, 3.0159),
        ),
        velocity_limits=(2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26),
        # upright and leaning back, wrist folded behind the base: cameras in front of the table
        # (x ≈ 1.0–1.3 m, elevated) do not see the arm over the workspace
        park=(0.0, -0.6, 0.0, -0.5, 0.0, 3.9, 0.785),
        # TCP at (0.45, 0, 0.40) m pointing down
        ready=(0.0, -0.35, 0.0, -2.12, 0.0, 1.771, 0.785),
        workspace=Workspace(x=(0.25, 0.75), y=(-0.35, 0.35), reach=0.78),
        placement=Workspace(x=(0.32, 0.68), y=(-0.27, 0.27), reach=0.72),
        # the executor hits a target to a few tenths of a millimetre
        placement_spread=(0.0015, 0.0015),
    ),
    gripper=Gripper(
        name="2F-85",
        full_name="Robotiq 2F-85",
        model=("robotiq_2f85", "2f85"),
        tcp_offset=0.145,
        control=(0.0, 255.0),
        max_grasp_width=0.080,
        stroke=GripperStroke(
            ctrl=np.linspace(0.0, 255.0, 18),
            gap=np.array(
                [0.085166, 0.080818, 0.076317, 0.071674, 0.066897, 0.061996, 0.056981, 0.051862,
                 0.046649, 0.041353, 0.035984, 0.030554, 0.025073, 0.019552, 0.014003, 0.008437,
                 0.002864, 0.000423]
            ),
            tip=np.array(
                [0.004525, 0.006193, 0.007764, 0.009231, 0.010592, 0.011844, 0.012983, 0.014006,
                 0.014912, 0.015698, 0.016361, 0.016901, 0.017315, 0.017602, 0.017763, 0.017794,
                 0.017698, 0.017626]
            ),
            pad_height=0.0375,
            pad_width=0.022,
            max_gap=0.085,
        ),
        fingers=FingerModel(
            segments=((0.000, 0.040, 0.017, 0.012), (0.040, 0.060, 0.033, 0.017)),
            linkage_from=0.060,
            linkage_outer=0.064,
            linkage_depth=0.0315,
            linkage_half_width=0.020,
            palm_from=0.120,
            palm=(
                (0.120, 0.160, -0.038, 0.038, -0.038, 0.038),
                (0.160, 1.000, -0.082, 0.042, -0.042, 0.082),
            ),
            clearances=(0.008, 0.004),
            min_clearance=0.0025,
            tip_margin=0.003,
            min_contact=0.008,
            high_contact=0.015,
            ceiling=(
                (0.006, 0.0748),
                (0.025, 0.0655),
                (0.046, 0.0571),
                (0.067, 0.0549),
                (0.085, 0.0375),
            ),
            inner_half_width=0.025,
        ),
    ),
    # looking at the held object from ~10 cm (the paper's ZED M: at that range a fitted pose
    # is good to a few tenths of a millimetre and degree)
    wrist_camera=WristCamera(position_noise=0.0003, rotation_noise=float(np.radians(0.3))),
)  # fmt: skip
"""The Franka FR3 with the Robotiq 2F-85."""


def load(path: str | os.PathLike[str] | None = None) -> Robot:
    """The description in the JSON file `path`; None: `RIVET_ROBOT`'s file, else `DEFAULT`.

    Raises:
        ValueError: the file cannot be read as a description (its path and what is wrong).
    """
    path = path if path is not None else os.environ.get(ENV) or None
    if path is None:
        return DEFAULT
    try:
        return Robot.from_json(json.loads(Path(path).read_text()))
    except (OSError, KeyError, TypeError, ValueError) as e:
        raise ValueError(
            f"{ENV}: {path} is not a robot description ({type(e).__name__}: {e})"
        ) from None


ROBOT = load()
"""The robot every part is built from."""

STROKE = ROBOT.gripper.stroke
WORKSPACE = ROBOT.arm.workspace
PLACEMENT = ROBOT.arm.placement
PLACEMENT_SPREAD = ROBOT.arm.placement_spread
MAX_GRASP_WIDTH = ROBOT.gripper.max_grasp_width

__all__ = [
    "DEFAULT",
    "ENV",
    "MAX_GRASP_WIDTH",
    "PLACEMENT",
    "PLACEMENT_SPREAD",
    "ROBOT",
    "STROKE",
    "WORKSPACE",
    "Arm",
    "FingerModel",
    "Gripper",
    "GripperStroke",
    "Robot",
    "WristCamera",
    "load",
]
