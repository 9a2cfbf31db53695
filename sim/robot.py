"""The robot in the simulator: the arm and gripper `geometry.robot.ROBOT` describes (a Franka
Research 3 with a Robotiq 2F-85 by default), from MuJoCo Menagerie.

Design rule: the description says which models, joints, postures and tool frame; this module
turns it into MuJoCo elements and names (joint, actuator, site and geom names, the park key,
the TCP site, the measurement of the gripper's stroke that `ROBOT.gripper.stroke` records), so
the executor and the IK never spell a menagerie name themselves. The models are read through
`mujoco_menagerie` (offline: `MENAGERIE_ROOT`); nothing is copied into this repository.

The robot's frames: the arm's base sits at the world origin; the TCP site `robot/tcp` lies
between the finger pads, its z axis pointing out of the gripper (the approach direction) and its
y axis along the jaws' closing direction (the gripper's own frame).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import pathlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Literal

import mujoco
import numpy as np

from geometry.robot import ROBOT, GripperStroke
from sim.errors import RobotModelError

PREFIX = "robot/"
"""Prefix of every element the robot adds to a scene."""

ARM_JOINTS: tuple[str, ...] = tuple(f"{PREFIX}{name}" for name in ROBOT.arm.joints)
ARM_ACTUATORS: tuple[str, ...] = ARM_JOINTS  # the menagerie names actuators after joints
GRIPPER_ACTUATOR = f"{PREFIX}gripper/fingers_actuator"
GRIPPER_BASE_BODY = f"{PREFIX}gripper/base"
GRIPPER_DRIVER_JOINTS = (
    f"{PREFIX}gripper/left_driver_joint",
    f"{PREFIX}gripper/right_driver_joint",
)
LEFT_PAD_GEOMS = (f"{PREFIX}gripper/left_pad1", f"{PREFIX}gripper/left_pad2")
RIGHT_PAD_GEOMS = (f"{PREFIX}gripper/right_pad1", f"{PREFIX}gripper/right_pad2")
TCP_SITE = f"{PREFIX}tcp"
PARK_KEY = f"{PREFIX}park"
WELD_ASSIST = f"{PREFIX}weld_assist"
"""An inactive weld from the gripper base to the world; the executor retargets it to a held
object while the weld assist is on (see docs/executor.md)."""

TCP_OFFSET = ROBOT.gripper.tcp_offset
"""TCP position along the gripper's z axis from its base [m]: the pads' centre when closed."""

PARK_QPOS = np.array(ROBOT.arm.park)
"""Arm posture for observations [rad]: out of the cameras' sight over the workspace."""

READY_QPOS = np.array(ROBOT.arm.ready)
"""Arm posture above the workspace [rad]: the IK's posture target and the way in and out of
the park posture."""

ARM_VELOCITY_LIMITS = np.array(ROBOT.arm.velocity_limits)
"""Joint speed limits [rad/s]."""

GRIPPER_OPEN, GRIPPER_CLOSED = ROBOT.gripper.control
"""The gripper's control range: fully open, fully closed."""

Visuals = bool | Literal["coarse"]  # the robot's visual meshes: all, none, or merged (drawing)
DRAWING_CELL_M = 0.001  # [m] the grid a drawing's robot meshes merge their vertices on
_INTEGRATOR = mujoco.mjtIntegrator.mjINT_IMPLICITFAST  # what the menagerie FR3 scene uses
_QPOS_SIZE = {
    mujoco.mjtJoint.mjJNT_FREE: 7,
    mujoco.mjtJoint.mjJNT_BALL: 4,
    mujoco.mjtJoint.mjJNT_SLIDE: 1,
    mujoco.mjtJoint.mjJNT_HINGE: 1,
}


def _load_spec(robot: str, entry: str) -> mujoco.MjSpec:
    import mujoco_menagerie

    try:
        spec = mujoco_menagerie.get(robot).spec(entry)
    except Exception as exc:
        raise RobotModelError(
            f"cannot load menagerie model {robot}/{entry}: {exc}. Offline, point "
            f"MENAGERIE_ROOT at a folder holding {ROBOT.arm.model[0]}/ and "
            f"{ROBOT.gripper.model[0]}/ "
            "(e.g. export MENAGERIE_ROOT=../shared/menagerie)"
        ) from exc
    return spec


def _absolute_meshdir(spec: mujoco.MjSpec) -> None:
    """Make the spec's meshdir absolute (MjSpec.attach resolves it against the parent).

    A model file that leaves meshdir empty keeps its meshes in ``assets/`` in the menagerie
    layout; that folder is used when the mesh files are not beside the model file.
    """
    root = pathlib.Path(spec.modelfiledir)
    candidates = [root / spec.meshdir] if spec.meshdir else [root, root / "assets"]
    first = next(iter(spec.meshes), None)
    if first is None:
        return
    for folder in candidates:
        if (folder / first.file).is_file():
            spec.meshdir = str(folder.resolve())
            return
    raise RobotModelError(f"cannot find mesh {first.file!r} under {[str(c) for c in candidates]}")


def _is_visual(geom: mujoco.MjsGeom) -> bool:
    """A menagerie visual geom: a mesh that takes part in no collision."""
    return geom.type == mujoco.mjtGeom.mjGEOM_MESH and geom.contype == 0 and geom.conaffinity == 0


def _keep_inertias(spec: mujoco.MjSpec, prefix: str) -> None:
    """Give each body whose inertia the compiler derives from its geoms (no explicit inertial),
    explicitly, the inertia it has with its full visual geoms (`geom_inertials`), in place: the
    visual meshes can then be removed or coarsened with the physics kept to the last bit."""
    inertials = geom_inertials()
    for body in spec.bodies:
        if body.name != spec.worldbody.name and not body.explicitinertial:
            mass, ipos, iquat, inertia = inertials[prefix + body.name]
            body.explicitinertial = True
            body.mass, body.ipos, body.iquat, body.inertia = mass, ipos, iquat, inertia


def _strip_visuals(spec: mujoco.MjSpec, prefix: str) -> None:
    """Remove the visual meshes of a menagerie spec, in place, keeping every body's inertia
    (`_keep_inertias`): the physics of the stripped robot is the full robot's to the last bit
    (a test steps both)."""
    _keep_inertias(spec, prefix)
    for geom in list(spec.geoms):
        if _is_visual(geom):
            spec.delete(geom)
    used = {g.meshname for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH}
    for mesh in list(spec.meshes):
        if mesh.name not in used:
            spec.delete(mesh)


def _coarsen_visuals(spec: mujoco.MjSpec, prefix: str, cell: float) -> None:
    """Merge the vertices of the spec's visual meshes that share a `cell` grid cell [m], in
    place, keeping every body's inertia (`_keep_inertias`): a robot to draw, not to simulate.

    The menagerie files repeat each vertex for every face that uses it; merged on a 1 mm grid
    the FR3 and 2F-85 keep 113,000 of their 298,000 faces, and the compiled model (mostly the
    meshes' bounding-volume trees) shrinks from 62 to 21 MB, with no difference a half-size
    video frame shows."""
    import trimesh

    _keep_inertias(spec, prefix)
    used = {g.meshname for g in spec.geoms if _is_visual(g)}
    for mesh in spec.meshes:
        if mesh.name not in used or not mesh.file:
            continue
        loaded: Any = trimesh.load(
            pathlib.Path(spec.meshdir) / mesh.file, force="mesh", process=False
        )
        vertices = np.asarray(loaded.vertices, np.float64) * np.asarray(mesh.scale, np.float64)
        faces = np.asarray(loaded.faces, np.int64)
        _, index, counts = np.unique(
            np.floor(vertices / cell).astype(np.int64), axis=0, return_inverse=True,
            return_counts=True,
        )  # fmt: skip
        index = index.ravel()
        merged = np.zeros((counts.size, 3))
        np.add.at(merged, index, vertices)
        merged /= counts[:, None]
        kept = index[faces]
        kept = kept[(kept[:, 0] != kept[:, 1]) & (kept[:, 1] != kept[:, 2])
                    & (kept[:, 0] != kept[:, 2])]  # fmt: skip
        kept = kept[np.unique(np.sort(kept, axis=1), axis=0, return_index=True)[1]]
        mesh.file = ""
        mesh.scale = [1.0, 1.0, 1.0]
        mesh.uservert = merged.astype(np.float32).ravel().tolist()
        mesh.userface = kept.astype(np.int32).ravel().tolist()


@functools.cache
def geom_inertials() -> dict[str, tuple[float, np.ndarray, np.ndarray, np.ndarray]]:
    """(mass, ipos, iquat, inertia) of each robot body as the compiler derives them from the
    full model's geoms: compiled once per process, without filling MuJoCo's mesh cache (the
    robot's visual meshes would hold about 120 MB there)."""
    spec = mujoco.MjSpec()
    attach_robot(spec, visuals=True)
    with no_mesh_cache():
        model = spec.compile()
    return {
        model.body(b).name: (
            float(model.body_mass[b]),
            model.body_ipos[b].copy(),
            model.body_iquat[b].copy(),
            model.body_inertia[b].copy(),
        )
        for b in range(1, model.nbody)
    }


@contextlib.contextmanager
def no_mesh_cache() -> Iterator[None]:
    """MuJoCo's global mesh cache off for one compile."""
    cache = mujoco.mj_getCache()
    capacity = mujoco.mj_getCacheCapacity(cache)
    mujoco.mj_setCacheCapacity(cache, 0)
    try:
        yield
    finally:
        mujoco.mj_setCacheCapacity(cache, capacity)


def _arm_with_gripper(*, visuals: Visuals = True) -> mujoco.MjSpec:
    arm = _load_spec(*ROBOT.arm.model)
    gripper = _load_spec(*ROBOT.gripper.model)
    _absolute_meshdir(arm)
    _absolute_meshdir(gripper)
    if visuals == "coarse":
        _coarsen_visuals(arm, PREFIX, DRAWING_CELL_M)
        _coarsen_visuals(gripper, f"{PREFIX}gripper/", DRAWING_CELL_M)
    elif not visuals:
        _strip_visuals(arm, PREFIX)
        _strip_visuals(gripper, f"{PREFIX}gripper/")
    # The 2F-85's joint ranges are authored in radians (its file says so); a copy whose
    # <compiler angle="radian"/> line is missing would read them as degrees.
    gripper.compiler.degree = False
    # Attaching keeps the parent's options; give the arm the gripper's so nothing conflicts.
    arm.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    arm.option.impratio = 10.0
    for key in list(arm.keys):
        arm.delete(key)  # the arm's "home" key knows no gripper joints; we add our own
    for name, (lo, hi) in zip(ROBOT.arm.joints, ROBOT.arm.joint_ranges, strict=True):
        arm.joint(name).range = [lo, hi]  # the description's limits (the IK keeps to them)
    n_gripper_q = sum(_QPOS_SIZE[j.type] for j in gripper.joints)
    arm.attach(gripper, prefix="gripper/", site=arm.site("attachment_site"))
    arm.body("gripper/base").add_site(
        name="tcp",
        pos=[0.0, 0.0, TCP_OFFSET],
        size=[0.004, 0.0, 0.0],
        rgba=[1.0, 0.3, 0.1, 1.0],
        group=5,
    )
    arm.add_key(
        name="park",
        qpos=[*PARK_QPOS, *([0.0] * n_gripper_q)],
        ctrl=[*PARK_QPOS, GRIPPER_OPEN],
    )
    return arm


def attach_robot(spec: mujoco.MjSpec, *, visuals: Visuals = True) -> None:
    """Add the FR3 + 2F-85 at the world origin of `spec`, in place.

    `visuals=False` leaves out the robot's visual meshes (about 380,000 vertices, 60 MB of
    model and three times that while compiling), with the same physics to the last bit: for a
    model nothing renders the robot in (the trials' physics, the IK). `visuals="coarse"`:
    the visual meshes with their vertices merged on a `DRAWING_CELL_M` grid, the same physics
    too: for a model that only draws the robot (the recordings' videos).

    Also sets the options that attaching drops (elliptic friction cones, impratio 10, the
    implicitfast integrator), gravity compensation on the robot's bodies (the FR3 compensates
    gravity in its own controller), a keyframe `robot/park`, the TCP site and the inactive weld
    the executor's optional weld assist uses. Every added name starts with `PREFIX`.
    """
    arm = _arm_with_gripper(visuals=visuals)
    spec.option.integrator = _INTEGRATOR
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    spec.attach(arm, prefix=PREFIX, frame=spec.worldbody.add_frame(pos=[0.0, 0.0, 0.0]))
    for body in spec.bodies:
        if body.name.startswith(PREFIX):
            body.gravcomp = 1.0
    spec.add_equality(
        name=WELD_ASSIST,
        type=mujoco.mjtEq.mjEQ_WELD,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        name1=GRIPPER_BASE_BODY,
        active=False,
        solref=[0.01, 1.0],
    )


def build_robot_spec(*, visuals: Visuals = True) -> mujoco.MjSpec:
    """A spec holding only the robot (no floor): the IK's kinematic model."""
    spec = mujoco.MjSpec()
    spec.modelname = "rivet_robot"
    attach_robot(spec, visuals=visuals)
    return spec


@dataclass(frozen=True, kw_only=True)
class RobotIndex:
    """Indices of the robot's elements in a compiled model."""

    arm_qpos: np.ndarray  # (7,) qpos addresses of the arm joints
    arm_dof: np.ndarray  # (7,) dof addresses of the arm joints
    arm_actuators: np.ndarray  # (7,)
    arm_range: np.ndarray  # (7, 2) joint limits [rad]
    gripper_actuator: int
    driver_qpos: np.ndarray  # (2,) qpos addresses of the 2F-85's driver joints
    tcp_site: int
    gripper_base: int  # body id
    left_pads: frozenset[int]  # geom ids
    right_pads: frozenset[int]
    robot_bodies: frozenset[int]
    weld: int  # equality id of the weld assist, -1 when the model has none

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> RobotIndex:
        """Look the robot up in `model`; raises RobotModelError when it is not there."""

        def find(kind: mujoco.mjtObj, name: str) -> int:
            i = mujoco.mj_name2id(model, kind, name)
            if i < 0:
                raise RobotModelError(
                    f"the model has no {kind.name.removeprefix('mjOBJ_').lower()} {name!r}; "
                    "was the scene built with sim.robot.attach_robot?"
                )
            return i

        joints = [find(mujoco.mjtObj.mjOBJ_JOINT, n) for n in ARM_JOINTS]
        drivers = [find(mujoco.mjtObj.mjOBJ_JOINT, n) for n in GRIPPER_DRIVER_JOINTS]
        return cls(
            arm_qpos=model.jnt_qposadr[joints].copy(),
            arm_dof=model.jnt_dofadr[joints].copy(),
            arm_actuators=np.array([find(mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in ARM_ACTUATORS]),
            arm_range=model.jnt_range[joints].copy(),
            gripper_actuator=find(mujoco.mjtObj.mjOBJ_ACTUATOR, GRIPPER_ACTUATOR),
            driver_qpos=model.jnt_qposadr[drivers].copy(),
            tcp_site=find(mujoco.mjtObj.mjOBJ_SITE, TCP_SITE),
            gripper_base=find(mujoco.mjtObj.mjOBJ_BODY, GRIPPER_BASE_BODY),
            left_pads=frozenset(find(mujoco.mjtObj.mjOBJ_GEOM, n) for n in LEFT_PAD_GEOMS),
            right_pads=frozenset(find(mujoco.mjtObj.mjOBJ_GEOM, n) for n in RIGHT_PAD_GEOMS),
            robot_bodies=frozenset(
                b for b in range(model.nbody) if model.body(b).name.startswith(PREFIX)
            ),
            weld=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, WELD_ASSIST),
        )


def park(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Put the arm in its park posture with the gripper open (robot joints only), at rest."""
    index = RobotIndex.from_model(model)
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, PARK_KEY)
    robot_joints = [j for j in range(model.njnt) if model.joint(j).name.startswith(PREFIX)]
    for j in robot_joints:
        adr, dof = model.jnt_qposadr[j], model.jnt_dofadr[j]
        data.qpos[adr] = model.key_qpos[key, adr] if key >= 0 else 0.0
        data.qvel[dof] = 0.0
    data.qpos[index.arm_qpos] = PARK_QPOS
    data.ctrl[index.arm_actuators] = PARK_QPOS
    data.ctrl[index.gripper_actuator] = GRIPPER_OPEN
    mujoco.mj_forward(model, data)


def tcp_pose(data: mujoco.MjData, index: RobotIndex) -> np.ndarray:
    """World pose (4, 4) of the TCP site."""
    T = np.eye(4)
    T[:3, :3] = data.site_xmat[index.tcp_site].reshape(3, 3)
    T[:3, 3] = data.site_xpos[index.tcp_site]
    return T


@functools.cache
def measure_stroke() -> GripperStroke:
    """Measure the gripper's stroke in simulation: pad gap and fingertip depth over its control
    range (the pads' size and widest opening are the description's). `ROBOT.gripper.stroke`
    holds the numbers this gives (a test compares them), so nothing else needs the simulator
    for the hand."""
    gripper = _load_spec(*ROBOT.gripper.model)
    _absolute_meshdir(gripper)
    gripper.compiler.degree = False
    gripper.option.gravity = [0.0, 0.0, 0.0]
    gripper.option.integrator = _INTEGRATOR
    model = gripper.compile()
    data = mujoco.MjData(model)
    base = model.body("base").id
    pads = [model.geom(n).id for n in ("left_pad1", "right_pad1")]
    ctrls = np.linspace(GRIPPER_OPEN, GRIPPER_CLOSED, len(ROBOT.gripper.stroke.ctrl))
    gaps, tips = [], []
    for c in ctrls:
        data.ctrl[0] = c
        for _ in range(400):
            mujoco.mj_step(model, data)
        R, p = data.xmat[base].reshape(3, 3), data.xpos[base]
        centres = [(data.geom_xpos[g] - p) @ R for g in pads]  # in the gripper base frame
        half_thickness = model.geom_size[pads[0], 1]
        half_height = model.geom_size[pads[0], 2]
        gaps.append(abs(centres[1][1] - centres[0][1]) - 2 * half_thickness)
        tips.append(0.5 * (centres[0][2] + centres[1][2]) + half_height - TCP_OFFSET)
    return dataclasses.replace(
        ROBOT.gripper.stroke, ctrl=ctrls, gap=np.maximum(np.array(gaps), 0.0), tip=np.array(tips)
    )
