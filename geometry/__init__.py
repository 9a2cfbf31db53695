"""The oracle geometry: what generators, settling, the plan checks, trial scoring, the
executor's grasp model and the programs' toolbox agree on.

- `convex`: convex pieces and bodies, separating-axis distances, placement helpers;
- `shape`: shapes as convex pieces (from collision parts or a mesh), mass, resting poses;
- `contacts`: interpenetration, support, stability with loads, contact relations;
- `plans`: applying a plan of transfers and judging every state (the one "plan success");
- `robot`: the robot description (arm, joints, reach, gripper stroke and fingers) every part is
  built from (`ROBOT`);
- `grasps`, `clearance`, `moves`: the robot's hand — top-down grasps, the gripper's volume
  against meshes, whole moves among neighbours;
- `tolerances`: the one table of tolerances, each entry with the physical fact behind it.

Pure numpy/scipy/trimesh (no simulator, no I/O), so it runs on the host and inside the
sandbox, where `toolbox` re-exports its documented names to programs.
"""

from geometry.contacts import (
    TABLE,
    Geometry,
    UnknownShape,
    collisions,
    contact_edges,
    resting_on,
    scene_problems,
    separation,
    supports,
    unstable_objects,
)
from geometry.convex import (
    Body,
    DegenerateError,
    Piece,
    bodies_of,
    body_separation,
    place,
    resting_height,
    yaw_of,
    yaw_pose,
)
from geometry.grasps import Grasp, GraspReport, Obstacle, plan_grasps
from geometry.moves import MoveCheck, MoveVerdict
from geometry.plans import PlanOutcome, PlanProblem, Workspace, apply_plan
from geometry.robot import (
    PLACEMENT,
    PLACEMENT_SPREAD,
    ROBOT,
    STROKE,
    WORKSPACE,
    FingerModel,
    Robot,
)
from geometry.shape import RestingPose, Shape, stable_poses
from geometry.tolerances import TOLERANCES, Tolerances

__all__ = [
    "PLACEMENT",
    "PLACEMENT_SPREAD",
    "ROBOT",
    "STROKE",
    "TABLE",
    "TOLERANCES",
    "WORKSPACE",
    "Body",
    "DegenerateError",
    "FingerModel",
    "Geometry",
    "Grasp",
    "GraspReport",
    "MoveCheck",
    "MoveVerdict",
    "Obstacle",
    "Piece",
    "PlanOutcome",
    "PlanProblem",
    "RestingPose",
    "Robot",
    "Shape",
    "Tolerances",
    "UnknownShape",
    "Workspace",
    "apply_plan",
    "bodies_of",
    "body_separation",
    "collisions",
    "contact_edges",
    "place",
    "plan_grasps",
    "resting_height",
    "resting_on",
    "scene_problems",
    "separation",
    "stable_poses",
    "supports",
    "unstable_objects",
    "yaw_of",
    "yaw_pose",
]
