"""The robot's hand and reach: what the executor can do with one plan step, as it models it.

This is the executor's own model (`geometry.grasps` and `geometry.moves`, re-exported): it picks
its grasps with these functions, and the plan checks (`property.gripper_room`) refuse every step
they reject. The robot is a Franka FR3 with a Robotiq 2F-85 parallel gripper. A step is one transfer: the
gripper comes down vertically over the object, closes its jaws across two opposite vertical
faces (at most `MAX_GRASP_WIDTH` apart), lifts it straight up, carries it at a safe height,
turns it only about the vertical, lowers it straight down onto the target and opens. So a step needs:

- a grasp whose fingers, finger linkages, gripper base and the arm's wrist clear every other
  object — at the pick, among the objects as they are before the step, and at the place,
  among them as they are after it (the jaws open a few millimetres beyond the object on each
  side; the fingertips stay 3 mm above what the object stands on);
- nothing above the object at the pick or the place: its vertical sweep keeps `SWEEP_CLEARANCE`
  from an overhang, and may touch a neighbour beside it `SWEEP_TOUCH` deep;
- a target that differs from the current pose only by a turn about the vertical (modulo the
  object's symmetry);
- both ends inside `WORKSPACE`, every point of the object (the arm reaches them top-down).

The task's scenes keep every object inside `PLACEMENT`, a region inside `WORKSPACE` where the
arm is comfortably within reach: put objects aside there. Where a domain packs parts tightly
(its facts say so), `PLACEMENT_SPREAD` = (gap, max shift) is how far to open the goal's gaps
and how far a part may move for that (`toolbox.spread_footprints`).

`Hand(meshes, symmetries).can_move(...)` answers all of this but the arm's joint limits (the
checks add an IK test). `MAX_OPENING` is the widest the jaws open; for the approach and the release
they open `JAW_CLEARANCES[0]` beyond the gripped width on each side, or `JAW_CLEARANCES[1]` when a
neighbour is too close for that (`toolbox.finger_footprints` draws the open fingers from above for
such an opening; each fingertip reaches `FINGER_DEPTH` outwards from its pad and is `FINGER_WIDTH`
wide), and the hand keeps `GRASP_MARGINS[0]` from every neighbour, or `GRASP_MARGINS[1]` where no
grasp has that much room, and a tilt under `YAW_ONLY` [rad] is a turn about the vertical. The
held object turns with the arm's last joint (range `WRIST_RANGE`) by the object's turn, so a grasp
that leaves the wrist near one end of its range cannot make a long turn that way; a grasp half a
turn from it may. Records and poses are as in `toolbox.stability`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from geometry import GraspReport, MoveVerdict, Shape, Workspace
from geometry.grasps import Grasp, Obstacle, plan_grasps
from geometry.moves import MoveCheck
from geometry.robot import ROBOT
from geometry.tolerances import TOLERANCES
from toolbox.errors import ToolboxError

__all__ = [
    "FINGER_DEPTH",
    "FINGER_WIDTH",
    "GRASP_MARGINS",
    "JAW_CLEARANCES",
    "MAX_GRASP_WIDTH",
    "MAX_OPENING",
    "PLACEMENT",
    "PLACEMENT_SPREAD",
    "SWEEP_CLEARANCE",
    "SWEEP_TOUCH",
    "WORKSPACE",
    "WRIST_RANGE",
    "YAW_ONLY",
    "Grasp",
    "GraspReport",
    "Hand",
    "MoveVerdict",
    "Workspace",
]

# The robot's facts, from its description (`geometry.robot.ROBOT`):
WORKSPACE = ROBOT.arm.workspace  # where the arm reaches top-down
PLACEMENT = ROBOT.arm.placement  # where scenes keep their objects, inside WORKSPACE
PLACEMENT_SPREAD = ROBOT.arm.placement_spread  # [m] (gap, max shift) for tightly packed goals
MAX_GRASP_WIDTH = ROBOT.gripper.max_grasp_width  # [m] the widest face pair the jaws take
MAX_OPENING = ROBOT.gripper.stroke.max_gap  # [m] widest the jaws open
JAW_CLEARANCES = ROBOT.gripper.fingers.clearances  # [m] per side, beyond the gripped width
# [m] a fingertip's extent outwards from its pad face, and across the closing direction
FINGER_DEPTH = ROBOT.gripper.fingers.depth
FINGER_WIDTH = ROBOT.gripper.fingers.width
WRIST_RANGE = ROBOT.arm.wrist_range  # [rad] the arm's last joint (the flange about the tool axis)
GRASP_MARGINS = TOLERANCES.grasp_margins  # [m] gripper to neighbours, larger preferred
SWEEP_TOUCH = TOLERANCES.sweep_touch  # [m] the held object's sweep may touch others this deep
SWEEP_CLEARANCE = TOLERANCES.sweep_clearance  # [m] from the sweep to an overhang
YAW_ONLY = TOLERANCES.yaw_only  # [rad] tilt within which a turn is one about the vertical


class Hand:
    """The executor's grasp model for a set of meshes.

    Args:
        meshes: mesh key → `trimesh.Trimesh` in the object's canonical frame (what the
            functions receive as `meshes`).
        symmetries: mesh key → object-frame symmetry transforms (n, 4, 4) (e.g.
            `toolbox.cube_symmetries()`); an object may then end at `target @ S` for any of
            them, which gives the wrist more ways to place it. Default: none. The plan checks
            and the executor pass each mesh's full symmetry group (every proper rotation the
            domain section's mesh list counts): a Hand given fewer may refuse moves they accept.

    Results are cached on the poses involved: asking again about the same move is free.
    """

    def __init__(
        self, meshes: Mapping[str, Any], symmetries: Mapping[str, Any] | None = None
    ) -> None:
        self.meshes = dict(meshes)
        syms = dict(symmetries or {})
        self.symmetries = {
            k: np.asarray(syms.get(k, [np.eye(4)]), dtype=float).reshape(-1, 4, 4)
            for k in self.meshes
        }
        try:
            pieces = {k: Shape.from_mesh(m)._pieces for k, m in self.meshes.items()}
        except Exception as e:
            raise ToolboxError(f"Hand: a mesh is not a closed solid ({e})") from None
        self._check = MoveCheck(self.meshes, self.symmetries, pieces)

    def _others(self, records: Sequence[Mapping], skip: str) -> dict[str, tuple[str, np.ndarray]]:
        out = {}
        for r in records:
            if str(r["id"]) == skip:
                continue
            if r["mesh"] not in self.meshes:
                raise ToolboxError(f"unknown mesh {r['mesh']!r}; known: {sorted(self.meshes)}")
            out[str(r["id"])] = (str(r["mesh"]), np.asarray(r["pose"], dtype=float))
        return out

    def can_move(
        self,
        records: Sequence[Mapping],
        object_id: str,
        target_pose: Any,
        *,
        place_records: Sequence[Mapping] | None = None,
    ) -> MoveVerdict:
        """Whether the robot can carry `object_id` from its pose in `records` (the objects
        before the step) to `target_pose`: a `MoveVerdict` (`.ok`, else `.reason` and
        `.blockers`, the ids in the way). `place_records` are the other objects as they stand
        at the place (the moved object's own record in them is ignored); the default,
        `records`, is right for a plan step, which moves `object_id` alone, and is how the
        checks judge each step. Pass others only to ask about a place among other poses."""
        me = next((r for r in records if str(r["id"]) == str(object_id)), None)
        if me is None:
            raise ToolboxError(f"no record with id {object_id!r}")
        T_from = np.asarray(me["pose"], dtype=float)
        T_to = np.asarray(target_pose, dtype=float)
        if T_from.shape != (4, 4) or T_to.shape != (4, 4):
            raise ToolboxError("poses must be (4, 4) matrices")
        pick = self._others(records, str(object_id))
        place = pick if place_records is None else self._others(place_records, str(object_id))
        return self._check.move(str(object_id), str(me["mesh"]), T_from, T_to, pick, place)

    def can_pick(self, records: Sequence[Mapping], object_id: str) -> MoveVerdict:
        """Whether the robot can pick `object_id` where it is (and put it back there)."""
        me = next((r for r in records if str(r["id"]) == str(object_id)), None)
        if me is None:
            raise ToolboxError(f"no record with id {object_id!r}")
        return self.can_move(records, object_id, me["pose"])

    def first_infeasible(
        self, records: Sequence[Mapping], steps: Sequence[Mapping]
    ) -> tuple[int, MoveVerdict] | None:
        """The first step of `steps` (``{"object", "target_pose"}``) from `records` the robot
        cannot make, with why; None when it can make them all."""
        state = [dict(r) for r in records]
        for k, step in enumerate(steps):
            verdict = self.can_move(state, str(step["object"]), step["target_pose"])
            if not verdict.ok:
                return k, verdict
            state = [
                dict(r, pose=np.asarray(step["target_pose"], float))
                if str(r["id"]) == str(step["object"])
                else r
                for r in state
            ]
        return None

    def grasps(
        self,
        records: Sequence[Mapping],
        object_id: str,
        target_pose: Any,
        *,
        limit: int | None = None,
    ) -> GraspReport:
        """Every feasible grasp for the move (best first; `limit` stops early), with counts
        of why the others were refused: a `GraspReport`. The grasps alone: the neighbours are
        `records` at both ends, and what lies above the object is not tested."""
        me = next((r for r in records if str(r["id"]) == str(object_id)), None)
        if me is None:
            raise ToolboxError(f"no record with id {object_id!r}")
        obstacles = [
            Obstacle(id=j, mesh=self.meshes[m], pose=T)
            for j, (m, T) in self._others(records, str(object_id)).items()
        ]
        return plan_grasps(
            self.meshes[me["mesh"]],
            np.asarray(me["pose"], float),
            np.asarray(target_pose, float),
            symmetries=list(self.symmetries[me["mesh"]]),
            pick_obstacles=obstacles,
            place_obstacles=obstacles,
            limit=limit,
        )
