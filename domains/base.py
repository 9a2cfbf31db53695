"""The `Domain` base class: a task family's files, geometry, cameras, tolerances and generator.

A domain lives in its own folder beside its module (dm_control style):

    task.md          the task text τ a model is told
    catalogue.json   objects (id, mesh key, colour, mass, friction) and meshes (file, convex
                     collision parts, symmetry group, canonical frame in words)
    cameras.json     the default RGB-D camera `front` and the alternatives `view1`, `view2`
    tolerances.json  the scoring tolerances
    meshes/          OBJ files written by `make_meshes.py`
    benchmark/       the fixed benchmark sets: goalGG_startS.json (dev split) and
                     test/goalGG_startS.json (test split), 20 goals × 3 starts each

Subclasses provide `make_goal` and `make_start` for both splits (`split="dev"`: the goal and
start families programs are developed on; `"test"`: families the dev split never uses, see
docs/domains.md, "Splits"); the base class turns them into instances with a construction
order, rejecting draws that are not physically valid or whose order the robot cannot execute
(a step without a top-down grasp of the 2F-85).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from functools import cached_property
from pathlib import Path
from typing import Any, ClassVar

import networkx as nx
import numpy as np
import trimesh

from domains import _meshing, symmetry
from domains.benchmark import (
    BENCHMARK_GOALS,
    BENCHMARK_STARTS,
    SPLIT_SEEDS,
    benchmark_name,
    check_split,
)
from domains.cameras import CameraEnvelope
from domains.catalogue import CameraSpec, MeshSpec, ObjectSpec, Tolerance
from domains.errors import DomainError, GenerationError, UnknownObjectError
from domains.generation import PhysicsCheck, draw_instance
from domains.instance import Instance
from domains.reference_order import ReferencePlanner
from geometry import (
    PLACEMENT,
    WORKSPACE,
    Geometry,
    MoveCheck,
    Piece,
    Workspace,
    bodies_of,
    contact_edges,
)

CAMERA_NAMES = ("front", "view1", "view2")


class Domain:
    """A task family. Subclasses set `name`, `root` and the relation thresholds."""

    name: ClassVar[str]
    root: ClassVar[Path]
    # the reference relations' vocabulary and thresholds (the domain's judge, not `relate`)
    REFERENCE_RELATIONS: ClassVar[dict[str, str]] = {
        "on": "the source rests on the target (touching from above)",
        "adjacent": "the two objects touch or nearly touch side by side (both directions)",
    }
    on_gap: ClassVar[float] = 0.008  # [m]
    adjacent_gap: ClassVar[float | None] = 0.012  # [m]
    temp_clearance: ClassVar[float] = 0.03  # [m]
    # (gap, largest shift) [m]: where a goal packs objects edge to edge, the oracle opens its
    # gaps towards `gap` (moving no object more than the shift) before placing them — a robot
    # whose in-hand estimate is good to a few tenths of a millimetre cannot hit gaps of half a
    # millimetre (the programs get the same tool: `toolbox.packing.spread_footprints`)
    placement_spread: ClassVar[tuple[float, float] | None] = None
    # where objects may be (reachable by the FR3 top-down), checked on every mesh vertex
    workspace: ClassVar[Workspace] = WORKSPACE
    # where generators and temporary places put objects (inside `workspace`)
    placement: ClassVar[Workspace] = PLACEMENT
    max_height: ClassVar[float] = 0.35  # highest allowed point of any object [m]
    # the domain properties its drafts are checked for, by function (`checks.properties`)
    properties: ClassVar[dict[str, list[tuple[str, dict[str, Any]]]]] = {}
    # what `compose` draws, in the words of the plan checks' rule; None: no composer
    composed_goals: ClassVar[str | None] = None

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

    @cached_property
    def camera_envelope(self) -> CameraEnvelope:
        """The cameras this domain's programs must handle: an envelope around the named views
        (`domains.cameras`); the checks draw `perceive`'s cameras from it."""
        return CameraEnvelope.around(self.cameras.values())

    # -- reference relations -------------------------------------------------------------

    def reference_relations(self, records: Sequence[Mapping]) -> dict:
        """The reference relation graph of records (networkx node-link, directed multigraph).

        Types are those of `REFERENCE_RELATIONS`; computed from geometry with this domain's
        gaps. This is the domain's own judge of relations (state scoring), not the generated
        `relate`.
        """
        g = nx.MultiDiGraph()
        for r in records:
            g.add_node(r["id"])
        bodies = bodies_of(records, self.parts)
        for a, b, kind in contact_edges(bodies, on_gap=self.on_gap, adjacent_gap=self.adjacent_gap):
            if kind in self.REFERENCE_RELATIONS:
                g.add_edge(a, b, type=kind)
        return nx.node_link_data(g, edges="edges")

    # -- generation ----------------------------------------------------------------------

    def make_goal(
        self, rng: np.random.Generator, index: int | None, split: str = "dev"
    ) -> list[dict]:
        """Goal records. `index` is the benchmark goal number (1 = the authoring reference in
        the dev split), or None for a free draw; `split` picks the goal families (the test
        split's never appear in the dev split)."""
        raise NotImplementedError

    def make_start(
        self, rng: np.random.Generator, goal: Sequence[Mapping], split: str = "dev"
    ) -> list[dict]:
        """Start records for a goal (`split`: the dev or the test split's starts)."""
        raise NotImplementedError

    @cached_property
    def reference_planner(self) -> ReferencePlanner:
        """The reference construction planner (geometry only, no grasp checks): the order the
        domain's instances carry, not the generated `plan`."""
        return ReferencePlanner(
            parts=self.parts,
            symmetries=self._symmetries,
            region=self.placement,
            clearance=self.temp_clearance,
        )

    @cached_property
    def grasps(self) -> MoveCheck:
        """The robot's grasp predicate for moves of this domain's objects (`geometry.moves`)."""
        return MoveCheck(self._meshes, self._symmetries, self.parts)

    @cached_property
    def robot_reference_planner(self) -> ReferencePlanner:
        """The reference construction planner whose orders the robot can execute."""
        return dataclasses.replace(self.reference_planner, grasps=self.grasps)

    def record(self, object_id: str, pose: np.ndarray) -> dict:
        return {
            "id": object_id,
            "mesh": self.object(object_id).mesh,
            "pose": np.asarray(pose, float),
        }

    def scene(self, records: Sequence[Mapping]) -> dict:
        return {"domain": self.name, "objects": [dict(r) for r in records]}

    def generate(
        self,
        seed: int,
        *,
        physics: PhysicsCheck | None = None,
        grasps: bool | None = None,
        split: str = "dev",
        ordered: bool = True,
    ) -> Instance:
        """A free draw: goal and start both from `seed`.

        Args:
            split: "dev" (the default: the instances this has always drawn, named
                ``seedS``) or "test" (the test split's goal and start families, from other
                seed keys, named ``test/seedS``).
            physics: also reject scenes this says are not physically valid (e.g.
                `sim.settle.physical_problems`: they do not settle in MuJoCo); None: geometry
                only (workspace, height, interpenetration).
            grasps: make the order executable by the robot (every step has a 2F-85 grasp,
                `geometry.moves`); None: when `physics` is given.
            ordered: False: no construction order (the instance's ``order`` is empty), for
                callers that need only the two scenes; a start no order reaches is kept.
        """
        dev = check_split(split) == "dev"
        return draw_instance(
            self,
            name=f"seed{seed}" if dev else f"{split}/seed{seed}",
            seed=seed,
            goal_key=(seed, 0) if dev else (seed, 2),
            goal_index=None,
            start_key=(seed, 1) if dev else (seed, 3),
            physics=physics,
            grasps=physics is not None if grasps is None else grasps,
            split=split,
            ordered=ordered,
        )

    def compose(self, seed: int) -> tuple[list[dict], list[dict]] | None:
        """(start, goal) records whose goal no split's catalogue holds — composed from the
        parts the task text allows, in shapes, combinations or spacings the catalogue does not
        use (`composed_goals` says which) — and whose start is drawn as dev starts are; None
        when the domain has no composer or `seed` gives no scene. The plan checks
        (`checks.inputs`) and `benchmarks.compositions_bench` draw from it."""
        return None

    def hidden_scene(self, seed: int) -> tuple[list[dict], str] | None:
        """(records, id): a scene of the task text's hiding case — the object `id` stands
        behind others, as seen from the front camera, and holds nothing up — or None when the
        domain draws none or `seed` gives none. Whether the object is in fact hidden, and the
        scene valid, is for the caller to test (the perceive checks keep the draws that hide it
        entirely; `benchmarks.occlusion_bench` scores them all)."""
        return None

    def composed_instance(self, seed: int, *, ordered: bool = True) -> Instance | None:
        """`compose(seed)` with a construction order the robot can execute
        (`robot_reference_planner`), named ``composed/seedS``; None when there is none.
        `ordered=False`: the two scenes only (``order`` empty), as `generate` gives them."""
        drawn = self.compose(seed)
        if drawn is None:
            return None
        start, goal = drawn
        order: Sequence[dict] = ()
        if ordered:
            try:
                order = self.robot_reference_planner.order(start, goal)
            except GenerationError:
                return None
        return Instance(
            domain=self.name,
            name=f"composed/seed{seed}",
            seed=seed,
            start=self.scene(start),
            goal=self.scene(goal),
            order=tuple(order),
        )

    def benchmark_instance(
        self,
        goal: int,
        start: int,
        *,
        physics: PhysicsCheck | None = None,
        grasps: bool | None = None,
        split: str = "dev",
    ) -> Instance:
        """Benchmark instance `goal` (1–20; 1 = the reference in the dev split) × `start`
        (1–3) of `split` ("dev" or "test"), regenerated (`physics`, `grasps`: as for
        `generate`)."""
        if not (1 <= goal <= BENCHMARK_GOALS and 1 <= start <= BENCHMARK_STARTS):
            raise ValueError(
                f"benchmark has goals 1–{BENCHMARK_GOALS}, starts 1–{BENCHMARK_STARTS}"
            )
        key = SPLIT_SEEDS[check_split(split)]
        return draw_instance(
            self,
            name=benchmark_name(goal, start, split),
            seed=None,
            goal_key=(key, goal),
            goal_index=goal,
            start_key=(key, goal, start),
            physics=physics,
            grasps=physics is not None if grasps is None else grasps,
            split=split,
        )

    @property
    def reference_transcript(self) -> Path:
        """The replay transcript `rivet author DOMAIN` plays by default (may not exist yet)."""
        return self.root / "transcripts" / "reference"

    # -- the fixed benchmark ---------------------------------------------------------------

    @property
    def benchmark_dir(self) -> Path:
        """The dev split's benchmark folder (`benchmark_dir_of(split)` for either split)."""
        return self.root / "benchmark"

    def benchmark_dir_of(self, split: str = "dev") -> Path:
        """The folder of a split's benchmark files: benchmark/ (dev), benchmark/test/ (test)."""
        return self.benchmark_dir if check_split(split) == "dev" else self.benchmark_dir / split

    def benchmark(self, split: str = "dev") -> list[Instance]:
        """The committed benchmark set of `split`, goal-major order (goal01_start1,
        goal01_start2, …)."""
        paths = sorted(self.benchmark_dir_of(split).glob("goal*_start*.json"))
        if len(paths) != BENCHMARK_GOALS * BENCHMARK_STARTS:
            flag = "" if split == "dev" else f" --split {split}"
            raise DomainError(
                f"{self.name}: {split} benchmark has {len(paths)} files, expected "
                f"{BENCHMARK_GOALS * BENCHMARK_STARTS}; run "
                f"`rivet scene benchmark {self.name}{flag}`"
            )
        return [Instance.from_dict(json.loads(p.read_text())) for p in paths]

    def benchmark_path(self, goal: int, start: int, split: str = "dev") -> Path:
        return self.benchmark_dir / f"{benchmark_name(goal, start, split)}.json"
