"""Scene specs → MuJoCo worlds.

The world (DESIGN frame): robot base at the origin, x forward, z up, table top at z = 0 with
the workspace in front of the robot. `build_spec` makes an `mujoco.MjSpec` holding the table,
floor, lights, the domain's cameras and one free body per object; with ``with_robot=True``
it hands the spec to `sim.robot.attach_robot(spec)` (the robot is that module's business).
Each object body is named `body_name(id)` and has a free joint `joint_name(id)`; its visual
geom is the watertight mesh, its collision geoms the catalogue's convex parts (group 3,
hidden). Inertia is exact: the catalogue mass spread over the watertight mesh.

Scenes enter through `parse_scene`, which refuses malformed input with errors that name the
path (ContractError) or the object (UnknownObjectError, InvalidSceneError).

Lights: a directional key light (casting shadows) and a fill light, plus MuJoCo's headlight
as ambient light (`LIGHTS`). They can be changed per render without rebuilding the model:
`lighting_of(model)` reads them as a `Lighting`, `set_lighting(model, data, lighting)`
writes one (`sim.realism.vary_lighting` draws varied ones; `sim.observation.Renderer.render`
applies one for a single render and restores the previous lights afterwards).
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import mujoco
import numpy as np

import domains
from contracts import validate
from contracts.errors import ContractError, UsageError
from domains import Domain, Instance
from domains.errors import UnknownObjectError
from sim.errors import InvalidSceneError, SimError

TABLE_HALF = (0.65, 0.75, 0.025)  # half sizes of the table top [m]
TABLE_CENTRE_X = 0.35  # [m]; the table spans x ∈ [-0.30, 1.00]
FLOOR_Z = -0.75  # [m]
RENDER_CAMERA = "rivet_render"  # a movable camera for arbitrary camera dicts
OFFSCREEN = (1920, 1080)  # offscreen framebuffer [px]: fits the 1280×720 cameras
TIMESTEP = 0.002  # [s]
OBJECT_GROUP_VISUAL = 2  # geom group of object visuals (robots use 0 and 1)
OBJECT_GROUP_COLLISION = 3  # hidden
# Stiff contacts for objects and table: wooden blocks sink < 0.1 mm per contact, so tall
# stacks stay within the 2 mm settling criterion (MuJoCo's default sinks ~0.5 mm per contact).
CONTACT_SOLREF = (0.005, 1.0)
CONTACT_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)


def body_name(object_id: str) -> str:
    """Name of an object's body in the MuJoCo model."""
    return f"object/{object_id}"


def joint_name(object_id: str) -> str:
    """Name of an object's free joint in the MuJoCo model."""
    return f"object/{object_id}/free"


# -- parsing --------------------------------------------------------------------------------


def _pose(value: Any, path: str) -> np.ndarray:
    try:
        pose = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ContractError(path, "pose must be a 4×4 array of numbers") from None
    if pose.shape != (4, 4):
        raise ContractError(path, f"pose must be 4×4, got shape {pose.shape}")
    if not np.isfinite(pose).all():
        raise ContractError(path, "pose has non-finite entries")
    if not np.allclose(pose[3], (0, 0, 0, 1), atol=1e-6):
        raise ContractError(path, "last row of a pose must be [0, 0, 0, 1]")
    r = pose[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-4):
        raise ContractError(path, "rotation is not orthonormal")
    det = np.linalg.det(r)
    if det < 0:
        raise ContractError(path, f"rotation is not proper (det = {det:.3f})")
    # re-orthonormalise the tolerated round-off so the simulator gets a clean rotation
    u, _, vt = np.linalg.svd(r)
    pose[:3, :3] = u @ vt
    return pose


def parse_scene(domain: Domain, value: Any, *, path: str = "") -> dict:
    """A scene spec checked against the domain; poses become (4, 4) arrays.

    Raises:
        ContractError: malformed structure (names the JSON path).
        UnknownObjectError: an id or mesh the catalogue does not have.
        InvalidSceneError: a duplicated object, or a mesh that is not the object's.
    """
    where = path or "scene"
    if not isinstance(value, Mapping):
        raise ContractError(path, "scene must be an object with 'domain' and 'objects'")
    try:
        validate("scene", value)
    except ContractError as e:
        raise ContractError(f"{path}.{e.path}".strip("."), e.problem) from None
    if value.get("domain") != domain.name:
        raise ContractError(
            f"{path}.domain".lstrip("."), f"expected {domain.name!r}, got {value.get('domain')!r}"
        )
    objs = value.get("objects")
    if not isinstance(objs, list):
        raise ContractError(f"{path}.objects".lstrip("."), "objects must be a list")
    out, seen = [], set()
    for k, o in enumerate(objs):
        p = f"{path}.objects[{k}]".lstrip(".")
        if not isinstance(o, Mapping) or not {"id", "mesh", "pose"} <= set(o):
            raise ContractError(p, "an object needs 'id', 'mesh' and 'pose'")
        oid, mesh = o["id"], o["mesh"]
        if not isinstance(oid, str) or not isinstance(mesh, str):
            raise ContractError(p, "'id' and 'mesh' must be strings")
        spec = domain.object(oid)
        if mesh != spec.mesh:
            domain.mesh_spec(mesh)
            raise InvalidSceneError(
                oid, f"has mesh {mesh!r}, the catalogue says {spec.mesh!r}", where=where
            )
        if oid in seen:
            raise InvalidSceneError(oid, "appears twice", where=where)
        seen.add(oid)
        out.append({"id": oid, "mesh": mesh, "pose": _pose(o["pose"], f"{p}.pose")})
    if not out:
        raise ContractError(f"{path}.objects".lstrip("."), "a scene needs at least one object")
    return {"domain": domain.name, "objects": out}


def parse_instance(value: Any) -> tuple[Domain, Instance]:
    """An instance ``{"domain", "start", "goal", ...}`` checked against its domain."""
    if not isinstance(value, Mapping):
        raise ContractError("", "instance must be an object with 'domain', 'start' and 'goal'")
    validate("instance", value)
    name = value.get("domain")
    if not isinstance(name, str):
        raise ContractError("domain", "must be a domain name")
    domain = domains.load(name)
    for key in ("start", "goal"):
        if key not in value:
            raise ContractError(key, "missing")
    start = parse_scene(domain, value["start"], path="start")
    goal = parse_scene(domain, value["goal"], path="goal")
    if sorted(o["id"] for o in start["objects"]) != sorted(o["id"] for o in goal["objects"]):
        raise ContractError("goal.objects", "start and goal must hold the same object ids")
    try:
        base = Instance.from_dict(value)
    except (KeyError, TypeError, ValueError) as e:
        raise ContractError("order", f"malformed construction order ({e})") from None
    inst = Instance(
        domain=name, name=base.name, seed=base.seed, start=start, goal=goal, order=base.order
    )
    return domain, inst


def load_instance(path: str | Path) -> tuple[Domain, Instance]:
    """Read and check an instance file, or a benchmark name such as ``cubes/goal01_start1``."""
    p = Path(path)
    if not p.exists() and "/" in str(path) and not str(path).endswith(".json"):
        dname, _, iname = str(path).partition("/")
        if dname in domains.names():
            p = domains.load(dname).benchmark_dir / f"{iname}.json"
    if not p.exists():
        raise UsageError(f"{path}: no such instance file")
    try:
        value = json.loads(p.read_text())
    except json.JSONDecodeError as e:
        raise ContractError("", f"{p}: not JSON ({e.msg} at line {e.lineno})") from None
    return parse_instance(value)


# -- poses ----------------------------------------------------------------------------------


def _quat(rot: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rot, dtype=float).ravel())
    return q


def camera_quat(t_world_camera: np.ndarray) -> np.ndarray:
    """MuJoCo camera quaternion for an OpenCV camera pose (MuJoCo looks along -z, y up)."""
    return _quat(np.asarray(t_world_camera, float)[:3, :3] @ np.diag([1.0, -1.0, -1.0]))


def fovy_of(camera: Mapping) -> float:
    """Vertical field of view [deg] of a camera dict (square pixels, centred)."""
    k = np.asarray(camera["K"], float)
    return float(np.degrees(2 * np.arctan((camera["height"] / 2) / k[1, 1])))


# -- lights ---------------------------------------------------------------------------------

# The scene's lights (world frame): directional, so `pos` only places the shadow map.
LIGHTS: tuple[dict[str, Any], ...] = (
    {
        "name": "key",
        "pos": (0.9, 0.5, 1.5),
        "dir": (-0.3, -0.35, -1.0),
        "diffuse": (0.5, 0.5, 0.5),
        "specular": (0.2, 0.2, 0.2),
        "castshadow": True,
    },
    {
        "name": "fill",
        "pos": (1.2, -0.6, 1.0),
        "dir": (-0.6, 0.5, -0.8),
        "diffuse": (0.25, 0.25, 0.25),
        "specular": (0.0, 0.0, 0.0),
        "castshadow": False,
    },
)
HEADLIGHT = {"ambient": (0.3, 0.3, 0.3), "diffuse": (0.2, 0.2, 0.2), "specular": (0.05, 0.05, 0.05)}


@dataclass(frozen=True, eq=False)
class Lighting:
    """The lights of a compiled model at one render.

    Attributes:
        pos, dir: (n, 3) position and direction of each model light (model order), in its
            body's frame (the world for the scene's lights); `dir` need not be normalised.
        diffuse, specular, ambient: (n, 3) colours of each light.
        headlight: (3, 3) MuJoCo's headlight rows ambient, diffuse, specular (it lights the
            scene from the camera; the scene uses its ambient part as room light).
    """

    pos: np.ndarray
    dir: np.ndarray
    diffuse: np.ndarray
    specular: np.ndarray
    ambient: np.ndarray
    headlight: np.ndarray

    @property
    def n(self) -> int:
        return len(self.pos)


def lighting_of(model: mujoco.MjModel) -> Lighting:
    """A copy of the model's current lights."""
    h = model.vis.headlight
    return Lighting(
        pos=model.light_pos.copy(),
        dir=model.light_dir.copy(),
        diffuse=model.light_diffuse.copy(),
        specular=model.light_specular.copy(),
        ambient=model.light_ambient.copy(),
        headlight=np.array([h.ambient, h.diffuse, h.specular], dtype=np.float32),
    )


def set_lighting(model: mujoco.MjModel, data: mujoco.MjData, lighting: Lighting) -> None:
    """Write `lighting` into the model (no recompilation) and update the lights' world poses.

    Directions are normalised. The change lasts until the next call: a caller that varies the
    lights for one render restores `lighting_of(model)` afterwards (`Renderer.render` does).
    """
    if lighting.n != model.nlight:
        raise SimError(f"lighting has {lighting.n} lights, the model {model.nlight}")
    d = np.asarray(lighting.dir, float)
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    if not np.all(norm > 0):
        raise SimError("lighting: a light direction is zero")
    model.light_pos[:] = lighting.pos
    model.light_dir[:] = np.where(np.isclose(norm, 1.0, rtol=0, atol=1e-12), d, d / norm)
    model.light_diffuse[:] = lighting.diffuse
    model.light_specular[:] = lighting.specular
    model.light_ambient[:] = lighting.ambient
    h = model.vis.headlight
    h.ambient[:], h.diffuse[:], h.specular[:] = lighting.headlight
    mujoco.mj_camlight(model, data)


# -- building -------------------------------------------------------------------------------


def build_spec(
    domain: Domain, scene: Mapping, *, with_robot: bool = False,
    robot_visuals: bool | Literal["coarse"] = True,
) -> mujoco.MjSpec:  # fmt: skip
    """The MuJoCo spec of a (parsed) scene: world, cameras and objects at their poses.

    `robot_visuals=False`: the robot without its visual meshes, the same physics
    (`sim.robot.attach_robot`), for a model that is simulated but never rendered;
    `"coarse"`: its visual meshes merged on a millimetre grid, for a model that only draws.
    """
    spec = mujoco.MjSpec()
    spec.modelname = f"rivet_{domain.name}"
    spec.option.timestep = TIMESTEP
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.visual.global_.offwidth, spec.visual.global_.offheight = OFFSCREEN
    spec.visual.quality.shadowsize = 2048
    spec.visual.map.znear = 0.01
    spec.visual.map.zfar = 20.0
    spec.visual.headlight.ambient = list(HEADLIGHT["ambient"])
    spec.visual.headlight.diffuse = list(HEADLIGHT["diffuse"])
    spec.visual.headlight.specular = list(HEADLIGHT["specular"])
    spec.stat.extent = 1.0
    spec.stat.center = [0.4, 0.0, 0.1]

    _world(spec)
    for name, cam in domain.cameras.items():
        c = cam.to_camera()
        spec.worldbody.add_camera(
            name=name,
            pos=c["T_world_camera"][:3, 3],
            quat=camera_quat(c["T_world_camera"]),
            fovy=cam.fovy,
        )
    spec.worldbody.add_camera(name=RENDER_CAMERA, pos=[1, 0, 0.5], fovy=45)

    used = sorted({o["mesh"] for o in scene["objects"]})
    for key in used:
        m = domain.mesh_spec(key)
        spec.add_mesh(name=f"mesh/{key}", file=str(m.file.resolve()))
        for j, f in enumerate(m.collision):
            spec.add_mesh(name=f"mesh/{key}/part{j}", file=str(f.resolve()))
    for o in scene["objects"]:
        _add_object(spec, domain, o)
    if with_robot:
        try:
            robot = importlib.import_module("sim.robot")
        except ModuleNotFoundError as e:
            if e.name != "sim.robot":
                raise
            raise SimError("with_robot=True but sim.robot is not available yet") from None
        robot.attach_robot(spec, visuals=robot_visuals)
    return spec


def _world(spec: mujoco.MjSpec) -> None:
    spec.add_texture(
        name="floor",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        rgb1=[0.32, 0.33, 0.35],
        rgb2=[0.28, 0.29, 0.31],
        width=512,
        height=512,
    )
    spec.add_material(name="floor", textures=["", "floor"], texrepeat=[6, 6], reflectance=0.0)
    spec.add_material(name="table", rgba=[0.6, 0.58, 0.55, 1], specular=0.05, shininess=0.05)
    wb = spec.worldbody
    wb.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[4, 4, 0.1],
        pos=[0, 0, FLOOR_Z],
        material="floor",
    )
    wb.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(TABLE_HALF),
        pos=[TABLE_CENTRE_X, 0, -TABLE_HALF[2]],
        material="table",
        friction=[0.8, 0.005, 0.0001],
        solref=list(CONTACT_SOLREF),
        solimp=list(CONTACT_SOLIMP),
    )
    for sx in (-1, 1):  # table legs, for the eye only
        for sy in (-1, 1):
            wb.add_geom(
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=[0.03, 0.03, -FLOOR_Z / 2 - 0.025],
                pos=[
                    TABLE_CENTRE_X + sx * (TABLE_HALF[0] - 0.06),
                    sy * (TABLE_HALF[1] - 0.06),
                    FLOOR_Z / 2 - 0.025,
                ],
                rgba=[0.35, 0.33, 0.3, 1],
                contype=0,
                conaffinity=0,
            )
    for light in LIGHTS:
        wb.add_light(
            name=light["name"],
            type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
            pos=list(light["pos"]),
            dir=list(light["dir"]),
            diffuse=list(light["diffuse"]),
            specular=list(light["specular"]),
            castshadow=light["castshadow"],
        )


def _add_object(spec: mujoco.MjSpec, domain: Domain, o: Mapping) -> None:
    obj = domain.object(o["id"])
    mesh = domain.mesh(obj.mesh)
    pose = np.asarray(o["pose"], float)
    spec.add_material(name=f"object/{obj.id}", rgba=list(obj.colour), specular=0.25, shininess=0.3)
    body = spec.worldbody.add_body(
        name=body_name(obj.id), pos=pose[:3, 3], quat=_quat(pose[:3, :3])
    )
    body.add_freejoint(name=joint_name(obj.id))
    scaled = mesh.copy()
    scaled.density = obj.mass / mesh.volume
    body.explicitinertial = True
    body.mass = obj.mass
    body.ipos = scaled.center_mass
    i = scaled.moment_inertia
    body.fullinertia = [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]
    body.add_geom(
        name=f"object/{obj.id}/visual",
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname=f"mesh/{obj.mesh}",
        material=f"object/{obj.id}",
        contype=0,
        conaffinity=0,
        group=OBJECT_GROUP_VISUAL,
    )
    for j in range(len(domain.mesh_spec(obj.mesh).collision)):
        body.add_geom(
            name=f"object/{obj.id}/collision{j}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=f"mesh/{obj.mesh}/part{j}",
            group=OBJECT_GROUP_COLLISION,
            friction=[obj.friction, 0.005, 0.0001],
            rgba=[1, 1, 1, 0],
            solref=list(CONTACT_SOLREF),
            solimp=list(CONTACT_SOLIMP),
        )


@dataclass
class SceneModel:
    """A compiled world for a set of objects, whose poses can be set and read."""

    domain: Domain
    object_ids: tuple[str, ...]
    model: mujoco.MjModel
    data: mujoco.MjData

    def qpos_address(self, object_id: str) -> int:
        jid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, joint_name(object_id))
        return int(self.model.jnt_qposadr[jid])

    def qvel_address(self, object_id: str) -> int:
        jid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, joint_name(object_id))
        return int(self.model.jnt_dofadr[jid])

    def set_poses(self, records: Sequence[Mapping]) -> None:
        """Put objects at their poses, at rest, and recompute positions."""
        mujoco.mj_resetData(self.model, self.data)
        for r in records:
            a = self.qpos_address(r["id"])
            pose = np.asarray(r["pose"], float)
            self.data.qpos[a : a + 3] = pose[:3, 3]
            self.data.qpos[a + 3 : a + 7] = _quat(pose[:3, :3])
        mujoco.mj_forward(self.model, self.data)

    def poses(self) -> dict[str, np.ndarray]:
        """Current object poses (4, 4) by id."""
        out = {}
        for i in self.object_ids:
            a = self.qpos_address(i)
            q = self.data.qpos[a : a + 7]
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, q[3:] / np.linalg.norm(q[3:]))
            t = np.eye(4)
            t[:3, :3] = rot.reshape(3, 3)
            t[:3, 3] = q[:3]
            out[i] = t
        return out

    def records(self) -> list[dict]:
        poses = self.poses()
        return [
            {"id": i, "mesh": self.domain.object(i).mesh, "pose": poses[i]} for i in self.object_ids
        ]


_CACHE: dict[tuple, SceneModel] = {}


def scene_model(domain: Domain, scene: Mapping) -> SceneModel:
    """A (cached) compiled objects-only world for the scene's objects, posed as in `scene`."""
    key = (domain.name, tuple(sorted((o["id"], o["mesh"]) for o in scene["objects"])))
    if key not in _CACHE:
        if len(_CACHE) > 16:
            _CACHE.clear()
        spec = build_spec(domain, scene)
        try:
            model = spec.compile()
        except ValueError as e:
            raise SimError(f"{domain.name}: scene does not compile: {e}") from None
        _CACHE[key] = SceneModel(
            domain=domain,
            object_ids=tuple(o["id"] for o in scene["objects"]),
            model=model,
            data=mujoco.MjData(model),
        )
    sm = _CACHE[key]
    sm.set_poses(scene["objects"])
    return sm


def object_of_geom(model: mujoco.MjModel) -> dict[int, str]:
    """Map geom id → object id for the object geoms of a model (robot geoms are absent)."""
    out = {}
    for g in range(model.ngeom):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.geom_bodyid[g])) or ""
        if name.startswith("object/"):
            out[g] = name[len("object/") :]
    return out


__all__ = [
    "HEADLIGHT",
    "LIGHTS",
    "RENDER_CAMERA",
    "Lighting",
    "SceneModel",
    "body_name",
    "build_spec",
    "camera_quat",
    "fovy_of",
    "joint_name",
    "lighting_of",
    "load_instance",
    "object_of_geom",
    "parse_instance",
    "parse_scene",
    "scene_model",
    "set_lighting",
]

# UnknownObjectError is re-raised from parse_scene as is; keep the name importable here.
_ = UnknownObjectError
