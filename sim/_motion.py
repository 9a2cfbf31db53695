"""Motion segments of a transfer and their kinematic planning.

Design rule: every segment is planned kinematically (IK on the robot-only model, tick by tick
at the control rate) before the physics runs it, so an unreachable waypoint is found before
the arm moves, and the physics only replays joint targets through the position actuators.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from scipy.spatial.transform import Rotation

from sim.ik import POSITION_TOL, ROTATION_TOL, ArmIK

PATH_POSITION_TOL = 0.005  # [m] largest TCP lag behind its moving target
PATH_ROTATION_TOL = np.radians(3.0)  # [rad]
SETTLE_TICKS = 4  # ticks at the goal appended to every Cartesian segment


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk time scaling of s ∈ [0, 1]."""
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


def interpolate_poses(T0: np.ndarray, T1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Poses (n, 4, 4) from T0 to T1 at fractions `s` (n,): linear position, geodesic rotation."""
    rel = Rotation.from_matrix(T0[:3, :3].T @ T1[:3, :3]).as_rotvec()
    out = np.repeat(np.eye(4)[None], len(s), axis=0)
    out[:, :3, :3] = T0[:3, :3] @ Rotation.from_rotvec(s[:, None] * rel).as_matrix()
    out[:, :3, 3] = T0[:3, 3] + s[:, None] * (T1[:3, 3] - T0[:3, 3])
    return out


def turn_poses(T0: np.ndarray, T1: np.ndarray, s: np.ndarray, turn: float) -> np.ndarray:
    """Poses (n, 4, 4) from T0 to T1 at fractions `s` (n,): linear position, the orientation
    turned about the world vertical by `s * turn` [rad], which may exceed half a turn (the long
    way round, where the geodesic would run the wrist into its limit); whatever rotation from
    T0 to T1 that turn leaves over (a small tilt) is interpolated along the way."""
    turned = Rotation.from_rotvec([0.0, 0.0, turn]).as_matrix() @ T0[:3, :3]
    rest = Rotation.from_matrix(turned.T @ T1[:3, :3]).as_rotvec()
    out = np.repeat(np.eye(4)[None], len(s), axis=0)
    yaw = Rotation.from_rotvec(s[:, None] * [0.0, 0.0, turn]).as_matrix()  # (n, 3, 3)
    out[:, :3, :3] = yaw @ T0[:3, :3] @ Rotation.from_rotvec(s[:, None] * rest).as_matrix()
    out[:, :3, 3] = T0[:3, 3] + s[:, None] * (T1[:3, 3] - T0[:3, 3])
    return out


@dataclass(frozen=True, kw_only=True)
class Segment:
    """One motion: the TCP to `goal` (Cartesian) or the arm to `q_goal` (joint space), or a
    pause, over `duration` [s], while the gripper's control ramps from `grip[0]` to `grip[1]`.
    A Cartesian move turns the TCP the shortest way, or by `turn` [rad] about the vertical
    (T_goal's orientation must then be the start's turned by `turn`)."""

    label: str
    duration: float
    goal: np.ndarray | None = None  # (4, 4) TCP pose
    q_goal: np.ndarray | None = None  # (7,) arm joints
    grip: tuple[float, float] | None = None  # None: keep the current gripper control
    turn: float | None = None  # [rad] about the world z axis; None: the geodesic


@dataclass(frozen=True, kw_only=True)
class PlannedSegment:
    segment: Segment
    q: np.ndarray  # (n, 7) joint targets, one per control tick
    grip: np.ndarray | None  # (n,) gripper control per tick


def split_at(segments: Sequence[PlannedSegment], *labels: str) -> list[list[PlannedSegment]]:
    """`segments` cut before the segment of each label, in order: len(labels) + 1 runs (the
    first may be empty). The executor runs a transfer's phases by these labels, not by their
    positions in the list.

    Raises:
        ValueError: a label is missing, or out of order.
    """
    names = [s.segment.label for s in segments]
    cuts, start = [], 0
    for label in labels:
        try:
            start = names.index(label, start)
        except ValueError:
            raise ValueError(f"no segment {label!r} after position {start} in {names}") from None
        cuts.append(start)
    bounds = [0, *cuts, len(segments)]
    return [list(segments[i:j]) for i, j in pairwise(bounds)]


@dataclass(frozen=True, kw_only=True)
class PlanFailure:
    label: str  # the segment that failed
    position_error: float  # [m]
    rotation_error: float  # [rad]

    def describe(self) -> str:
        return (
            f"no IK solution while {self.label}: TCP off by "
            f"{self.position_error * 1000:.1f} mm / {np.degrees(self.rotation_error):.1f}°"
        )


def plan_segments(
    ik: ArmIK, q0: np.ndarray, segments: Sequence[Segment], dt: float
) -> list[PlannedSegment] | PlanFailure:
    """Plan segments one after another from joints `q0` (7,); the first failure ends it."""
    out = []
    q = np.asarray(q0, dtype=float)
    T = ik.fk(q)
    for seg in segments:
        n = max(1, int(np.ceil(seg.duration / dt)))
        s = min_jerk(np.arange(1, n + 1) / n)
        if seg.goal is not None:
            if seg.turn is None:
                path = interpolate_poses(T, seg.goal, s)
            else:
                path = turn_poses(T, seg.goal, s, seg.turn)
            path = np.concatenate([path, np.repeat(seg.goal[None], SETTLE_TICKS, axis=0)])
            qs, errs = ik.track(q, path, dt)
            final = errs[-1]
            if (
                errs[:, 0].max() > PATH_POSITION_TOL
                or errs[:, 1].max() > PATH_ROTATION_TOL
                or final[0] > POSITION_TOL
                or final[1] > ROTATION_TOL
            ):
                worst = int(
                    np.argmax(errs[:, 0] / PATH_POSITION_TOL + errs[:, 1] / PATH_ROTATION_TOL)
                )
                return PlanFailure(
                    label=seg.label,
                    position_error=float(errs[worst, 0]),
                    rotation_error=float(errs[worst, 1]),
                )
            T = seg.goal
        elif seg.q_goal is not None:
            qs = q + s[:, None] * (np.asarray(seg.q_goal) - q)
            T = ik.fk(qs[-1])
        else:
            qs = np.repeat(q[None], n, axis=0)
        grip = None
        if seg.grip is not None:
            grip = seg.grip[0] + s[: len(qs)] * (seg.grip[1] - seg.grip[0])
            if len(qs) > len(grip):
                grip = np.concatenate([grip, np.full(len(qs) - len(grip), seg.grip[1])])
        out.append(PlannedSegment(segment=seg, q=qs, grip=grip))
        q = qs[-1]
    return out
