"""The `Domain` base class: a task family's files, geometry, cameras, tolerances and generator.

A domain lives in its own folder beside its module (dm_control style):

    task.md          the task text τ a model is told
    catalogue.json   objects (id, mesh key, colour, mass, friction) and meshes (file, convex
                     collision parts, symmetry group, canonical frame in words)
    cameras.json     the default RGB-D camera `front` and the alternatives `view1`, `view2`
    tolerances.json  the scoring tolerances
    meshes/          OBJ files written by `make_meshes.py`
    benchmark/       the fixed benchmark set: goalGG_startS.json, 20 goals × 3 starts

Subclasses provide `make_goal` and `make_start`; the base class turns them into instances
with a construction order, rejecting draws that are not physically valid or whose order the
robot cannot execute (a step without a top-down grasp of the 2F-85).
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, ClassVar

import networkx as nx
import numpy as np
import trimesh

from domains import _meshing, symmetry
from domains._planning import Planner
from domains.errors import DomainError, GenerationError, UnknownObjectError
from geometry import WORKSPACE, Geometry, MoveCheck, Piece, Workspace, bodies_of, contact_edges

BENCHMARK_GOALS = 20
BENCHMARK_STARTS = 3
CAMERA_NAMES = ("front", "view1", "view2")


@dataclass(frozen=True, kw_only=True)
class ObjectSpec:
    """One object instance of the catalogue."""

    id: str
    mesh: str  # key into the domain's meshes
    colour: tuple[float, float, float, float]  # RGBA in [0, 1]
    mass: float  # [kg]
    friction: float  # sliding friction coefficient


@dataclass(frozen=True, kw_only=True)
class MeshSpec:
    """A mesh of the catalogue; `frame` says in words where its canonical frame is."""

    key: str
    file: Path  # watertight OBJ, metres, in the canonical frame
    collision: tuple[Path, ...]  # convex parts whose union is the mesh
    symmetry: Mapping[str, Any]  # see `domains.symmetry`
    frame: str


@dataclass(frozen=True, kw_only=True)
class CameraSpec:
    """A pinhole camera looking from `position` at `target` [m], square pixels, centred."""

    name: str
    width: int
    height: int
    fovy: float  # vertical field of view [deg]
    position: tuple[float, float, float]
    target: tuple[float, float, float]

    def to_camera(self) -> dict:
        """The camera in the DESIGN format: K (3, 3) and T_world_camera (4, 4), OpenCV axes."""
        p, t = np.array(self.position, float), np.array(self.target, float)
        forward = (t - p) / np.linalg.norm(t - p)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        pose = np.eye(4)
        pose[:3, :3] = np.stack([right, down, forward], axis=1)
        pose[:3, 3] = p
        f = (self.height / 2) / np.tan(np.radians(self.fovy) / 2)
        k = np.array(
            [[f, 0.0, (self.width - 1) / 2], [0.0, f, (self.height - 1) / 2], [0.0, 0.0, 1.0]]
        )
        return {"width": self.width, "height": self.height, "K": k, "T_world_camera": pose}


@dataclass(frozen=True, kw_only=True)
class Tolerance:
    """Scoring tolerance: an object is right when within both bounds, modulo symmetry."""

    translation: float  # [m]
    rotation: float | None  # [rad]; None: orientation is not scored (e.g. cubes)


@dataclass(frozen=True, kw_only=True)
class Instance:
    """A start scene, a goal scene and a construction order from one to the other."""

    domain: str
    name: str
    seed: int | None
    start: dict
    goal: dict
    order: tuple[dict, ...] = field(default=())  # plan steps {"object", "target_pose"}

    def to_dict(self) -> dict:
        """JSON-ready form (poses as nested lists)."""
        return {
            "domain": self.domain,
            "name": self.name,
            "seed": self.seed,
            "start": scene_to_json(self.start),
            "goal": scene_to_json(self.goal),
            "order": {
                "status": "ok",
                "steps": [
                    {"object": s["object"], "target_pose": _pose_json(s["target_pose"])}
                    for s in self.order
                ],
            },
        }

    @staticmethod
    def from_dict(value: Mapping[str, Any]) -> Instance:
        """Read the JSON form; `order`, `name` and `seed` are optional."""
        steps = (value.get("order") or {}).get("steps", [])
        return Instance(
            domain=value["domain"],
            name=value.get("name", ""),
            seed=value.get("seed"),
            start=scene_from_json(value["start"]),
            goal=scene_from_json(value["goal"]),
            order=tuple(
                {"object": s["object"], "target_pose": np.asarray(s["target_pose"], float)}
                for s in steps
            ),
        )


def _pose_json(pose: Any) -> list[list[float]]:
    return [[round(float(v), 10) + 0.0 for v in row] for row in np.asarray(pose, float)]


def scene_to_json(scene: Mapping[str, Any]) -> dict:
    """A scene with poses as nested lists (rounded to 1e-10)."""
    return {
        "domain": scene["domain"],
        "objects": [
            {"id": o["id"], "mesh": o["mesh"], "pose": _pose_json(o["pose"])}
            for o in scene["objects"]
        ],
    }


def scene_from_json(scene: Mapping[str, Any]) -> dict:
    """A scene with poses as (4, 4) float arrays (no validation: see `sim.scene.parse_scene`)."""
    return {
        "domain": scene["domain"],
        "objects": [
            {"id": o["id"], "mesh": o["mesh"], "pose": np.asarray(o["pose"], float)}
            for o in scene["objects"]
        ],
    }


class Domain:
    """A task family. Subclasses set `name`, `root` and the relation thresholds."""

    name: ClassVar[str]
    root: ClassVar[Path]
    # the reference relation function's vocabulary and thresholds
    RELATIONS: ClassVar[dict[str, str]] = {
        "on": "the source rests on the target (touching from above)",
        "adjacent": "the two objects touch or nearly touch side by side (both directions)",
    }
    on_gap: ClassVar[float] = 0.008  # [m]
    adjacent_gap: ClassVar[float | None] = 0.012  # [m]
    temp_clearance: ClassVar[float] = 0.03  # [m]
    # where objects may be (reachable by the FR3 top-down), checked on every mesh vertex
    workspace: ClassVar[Workspace] = WORKSPACE
    # where generators and temporary places put objects (inside `workspace`)
    placement: ClassVar[Workspace] = Workspace(x=(0.32, 0.68), y=(-0.27, 0.27), reach=0.72)
    max_height: ClassVar[float] = 0.35  # highest allowed point of any object [m]
    # the domain properties its drafts are checked for, by function (`checks.properties`)
    properties: ClassVar[dict[str, list[tuple[str, dict[str, Any]]]]] = {}

    def __init__(self) -> None:
        self.task: str = (self.root / "task.md").read_text()
        cat = json.loads((self.root / "catalogue.json").read_text())
        self.mesh_specs: dict[str, MeshSpec] = {
            key: MeshSpec(
                key=key,
                file=self.root / m["file"],
                collision=tuple(self.root / f for f in m["collision"]),
                symmetry=m["symmetry"],
                frame=m["frame"],
            )
            for key, m in cat["meshes"].items()
        }
        self.objects: tuple[ObjectSpec, ...] = tuple(
            ObjectSpec(
                id=o["id"],
                mesh=o["mesh"],
                colour=tuple(o["colour"]),
                mass=o["mass"],
                friction=o["friction"],
            )
            for o in cat["objects"]
        )
        for o in self.objects:
            if o.mesh not in self.mesh_specs:
                raise DomainError(f"{self.name}: object {o.id!r} uses unknown mesh {o.mesh!r}")
        cams = json.loads((self.root / "cameras.json").read_text())
        self.cameras: dict[str, CameraSpec] = {
            n: CameraSpec(
                name=n,
                width=c["width"],
                height=c["height"],
                fovy=c["fovy"],
                position=tuple(c["position"]),
                target=tuple(c["target"]),
            )
            for n, c in cams.items()
        }
        if tuple(self.cameras) != CAMERA_NAMES:
            raise DomainError(f"{self.name}: cameras must be {CAMERA_NAMES}")
        tol = json.loads((self.root / "tolerances.json").read_text())
        rot = tol.get("rotation_deg")
        self.tolerance = Tolerance(
            translation=tol["translation_m"], rotation=None if rot is None else np.radians(rot)
        )

    def __repr__(self) -> str:
        return f"<Domain {self.name}>"

    # -- catalogue ------------------------------------------------------------------------

    @property
    def object_ids(self) -> tuple[str, ...]:
        return tuple(o.id for o in self.objects)

    def object(self, object_id: str) -> ObjectSpec:
        """The catalogue entry of `object_id` (UnknownObjectError lists the valid ids)."""
        for o in self.objects:
            if o.id == object_id:
                return o
        raise UnknownObjectError(self.name, "object", object_id, self.object_ids)

    def mesh_spec(self, key: str) -> MeshSpec:
        if key not in self.mesh_specs:
            raise UnknownObjectError(self.name, "mesh", key, tuple(self.mesh_specs))
        return self.mesh_specs[key]

    @cached_property
    def _meshes(self) -> dict[str, trimesh.Trimesh]:
        return {k: _meshing.load(m.file) for k, m in self.mesh_specs.items()}

    def meshes(self) -> dict[str, trimesh.Trimesh]:
        """Canonical meshes by key (fresh copies: callers may modify them)."""
        return {k: m.copy() for k, m in self._meshes.items()}

    def mesh(self, key: str) -> trimesh.Trimesh:
        self.mesh_spec(key)
        return self._meshes[key]

    @cached_property
    def collision_meshes(self) -> dict[str, list[trimesh.Trimesh]]:
        """Convex parts per mesh key, as meshes (object frame)."""
        return {k: [_meshing.load(f) for f in m.collision] for k, m in self.mesh_specs.items()}

    @cached_property
    def shapes(self) -> Geometry:
        """The objects' shapes by mesh key (the collision parts): what the oracle geometry —
        collisions, support, stability, plan checks, trial scoring — works with."""
        return Geometry.from_parts(
            {k: [p.vertices for p in ms] for k, ms in self.collision_meshes.items()}
        )

    @cached_property
    def parts(self) -> dict[str, list[Piece]]:
        """Convex pieces per mesh key (object frame), for separation queries."""
        return {k: list(s._pieces) for k, s in self.shapes.items()}

    @cached_property
    def _symmetries(self) -> dict[str, np.ndarray]:
        return {k: symmetry.group(m.symmetry) for k, m in self.mesh_specs.items()}

    def symmetries(self, key: str) -> np.ndarray:
        """Symmetry group of a mesh: (n, 4, 4) object-frame transforms, identity first."""
        self.mesh_spec(key)
        return self._symmetries[key]

    def camera(self, name: str = "front") -> dict:
        """Camera `name` (front, view1, view2) in the DESIGN format."""
        if name not in self.cameras:
            raise UnknownObjectError(self.name, "camera", name, tuple(self.cameras))
        return self.cameras[name].to_camera()

    # -- reference relations -------------------------------------------------------------

    def relate(self, records: Sequence[Mapping]) -> dict:
        """The reference relation graph of records (networkx node-link, directed multigraph).

        Types are those of `RELATIONS`; computed from geometry with this domain's gaps.
        """
        g = nx.MultiDiGraph()
        for r in records:
            g.add_node(r["id"])
        bodies = bodies_of(records, self.parts)
        for a, b, kind in contact_edges(bodies, on_gap=self.on_gap, adjacent_gap=self.adjacent_gap):
            if kind in self.RELATIONS:
                g.add_edge(a, b, type=kind)
        return nx.node_link_data(g, edges="edges")

    # -- generation ----------------------------------------------------------------------

    def make_goal(self, rng: np.random.Generator, index: int | None) -> list[dict]:
        """Goal records. `index` is the benchmark goal number (1 = the authoring reference),
        or None for a free draw."""
        raise NotImplementedError

    def make_start(self, rng: np.random.Generator, goal: Sequence[Mapping]) -> list[dict]:
        """Start records for a goal."""
        raise NotImplementedError

    @cached_property
    def planner(self) -> Planner:
        """The geometric construction planner (no grasp checks)."""
        return Planner(
            parts=self.parts,
            symmetries=self._symmetries,
            region=self.placement,
            clearance=self.temp_clearance,
        )

    @cached_property
    def grasps(self) -> MoveCheck:
        """The robot's grasp predicate for moves of this domain's objects (needs the robot
        models: `MENAGERIE_ROOT`)."""
        return MoveCheck(self._meshes, self._symmetries, self.parts)

    @cached_property
    def robot_planner(self) -> Planner:
        """The construction planner whose orders the robot can execute."""
        return dataclasses.replace(self.planner, grasps=self.grasps)

    def record(self, object_id: str, pose: np.ndarray) -> dict:
        return {
            "id": object_id,
            "mesh": self.object(object_id).mesh,
            "pose": np.asarray(pose, float),
        }

    def scene(self, records: Sequence[Mapping]) -> dict:
        return {"domain": self.name, "objects": [dict(r) for r in records]}

    def generate(self, seed: int, *, physics: bool = True, grasps: bool | None = None) -> Instance:
        """A free draw: goal and start both from `seed`.

        Args:
            physics: reject scenes that do not settle in MuJoCo.
            grasps: make the order executable by the robot (every step has a grasp);
                None: as `physics`. Both need MuJoCo; without them only geometry is checked.
        """
        return self._instance(
            name=f"seed{seed}",
            seed=seed,
            goal_key=(seed, 0),
            goal_index=None,
            start_key=(seed, 1),
            physics=physics,
            grasps=physics if grasps is None else grasps,
        )

    def benchmark_instance(
        self, goal: int, start: int, *, physics: bool = True, grasps: bool | None = None
    ) -> Instance:
        """Benchmark instance `goal` (1–20, 1 = reference) × `start` (1–3), regenerated
        (`physics`, `grasps`: as for `generate`)."""
        if not (1 <= goal <= BENCHMARK_GOALS and 1 <= start <= BENCHMARK_STARTS):
            raise ValueError(
                f"benchmark has goals 1–{BENCHMARK_GOALS}, starts 1–{BENCHMARK_STARTS}"
            )
        return self._instance(
            name=benchmark_name(goal, start),
            seed=None,
            goal_key=(10_000, goal),
            goal_index=goal,
            start_key=(10_000, goal, start),
            physics=physics,
            grasps=physics if grasps is None else grasps,
        )

    def _instance(
        self, *, name, seed, goal_key, goal_index, start_key, physics, grasps
    ) -> Instance:
        planner = self.robot_planner if grasps else self.planner
        problems: list[str] = []
        for attempt in range(40):
            goal = self.make_goal(np.random.default_rng([*goal_key, attempt]), goal_index)
            goal_problems = self._problems(goal, physics)
            if not goal_problems:
                break
            problems.append(f"goal draw {attempt}: {goal_problems[0]}")
        else:
            raise GenerationError(f"{self.name} {name}: no valid goal; " + "; ".join(problems[-3:]))
        for attempt in range(40):
            rng = np.random.default_rng([*start_key, attempt])
            start = self.make_start(rng, goal)
            start_problems = self._problems(start, physics)
            if start_problems:
                problems.append(f"start draw {attempt}: {start_problems[0]}")
                continue
            try:
                order = planner.order(start, goal)
            except GenerationError as e:
                problems.append(f"start draw {attempt}: {e}")
                continue
            if not order:
                problems.append(f"start draw {attempt}: start equals goal")
                continue
            return Instance(
                domain=self.name,
                name=name,
                seed=seed,
                start=self.scene(start),
                goal=self.scene(goal),
                order=tuple(order),
            )
        raise GenerationError(f"{self.name} {name}: no valid start; " + "; ".join(problems[-3:]))

    def _problems(self, records: Sequence[Mapping], physics: bool) -> list[str]:
        from sim.settle import geometric_problems, physical_problems  # sim builds on domains

        scene = self.scene(records)
        found = [str(p) for p in geometric_problems(self, scene)]
        if not found and physics:
            found = [str(p) for p in physical_problems(self, scene)]
        return found

    @property
    def reference_transcript(self) -> Path:
        """The replay transcript `rivet author DOMAIN` plays by default (may not exist yet)."""
        return self.root / "transcripts" / "reference"

    # -- the fixed benchmark ---------------------------------------------------------------

    @property
    def benchmark_dir(self) -> Path:
        return self.root / "benchmark"

    def benchmark(self) -> list[Instance]:
        """The committed benchmark set, goal-major order (goal01_start1, goal01_start2, …)."""
        paths = sorted(self.benchmark_dir.glob("goal*_start*.json"))
        if len(paths) != BENCHMARK_GOALS * BENCHMARK_STARTS:
            raise DomainError(
                f"{self.name}: benchmark has {len(paths)} files, expected "
                f"{BENCHMARK_GOALS * BENCHMARK_STARTS}; run `python -m domains.benchmark {self.name}`"
            )
        return [Instance.from_dict(json.loads(p.read_text())) for p in paths]

    def benchmark_path(self, goal: int, start: int) -> Path:
        return self.benchmark_dir / f"{benchmark_name(goal, start)}.json"


def benchmark_name(goal: int, start: int) -> str:
    return f"goal{goal:02d}_start{start}"


_NAME = re.compile(r"^goal(\d\d)_start(\d)$")


def parse_benchmark_name(name: str) -> tuple[int, int] | None:
    """(goal, start) of a name like ``goal01_start2``, else None."""
    m = _NAME.match(name)
    return (int(m.group(1)), int(m.group(2))) if m else None
