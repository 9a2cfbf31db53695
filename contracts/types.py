"""The scene representation as typed values, each with `to_dict` / `from_dict`.

Design rule: `from_dict` validates through `contracts.validate` (so every boundary raises the
same `ContractError` naming the path); `to_dict` returns the JSON form of DESIGN.md. Poses are
read-only float (4, 4) arrays; equality compares the JSON forms.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import networkx as nx
import numpy as np

from contracts.errors import ContractError
from contracts.validate import validate


def _frozen_array(value: Any, shape: tuple[int, ...]) -> np.ndarray:
    a = np.array(value, dtype=float)
    if a.shape != shape:
        raise ValueError(f"expected shape {shape}, got {a.shape}")
    a.setflags(write=False)
    return a


class _Value:
    """Equality and hashing through the JSON form (numpy arrays do not compare as values)."""

    KIND: ClassVar[str]

    def to_dict(self) -> Any:
        raise NotImplementedError

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and self.to_dict() == other.to_dict()  # type: ignore[attr-defined]

    def __hash__(self) -> int:
        return hash(repr(self.to_dict()))

    def validate(self) -> None:
        validate(self.KIND, self.to_dict())


@dataclass(frozen=True, kw_only=True, eq=False)
class Camera(_Value):
    """Pinhole camera, OpenCV convention (x right, y down, z forward)."""

    KIND: ClassVar[str] = "camera"
    width: int
    height: int
    K: np.ndarray  # (3, 3) [px]
    T_world_camera: np.ndarray  # (4, 4)

    def __post_init__(self) -> None:
        object.__setattr__(self, "K", _frozen_array(self.K, (3, 3)))
        object.__setattr__(self, "T_world_camera", _frozen_array(self.T_world_camera, (4, 4)))

    def to_dict(self) -> dict[str, Any]:
        return {
            "width": int(self.width),
            "height": int(self.height),
            "K": self.K.tolist(),
            "T_world_camera": self.T_world_camera.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Any) -> Camera:
        d = validate(cls.KIND, data)
        return cls(
            width=d["width"], height=d["height"], K=d["K"], T_world_camera=d["T_world_camera"]
        )


@dataclass(frozen=True, kw_only=True, eq=False)
class ObservationMeta(_Value):
    """`camera.json` of an observation folder: the camera and the depth PNG's scale."""

    KIND: ClassVar[str] = "observation"
    camera: Camera
    depth_scale: float  # depth.png value = metres * 1000 * depth_scale

    def to_dict(self) -> dict[str, Any]:
        return {**self.camera.to_dict(), "depth_scale": float(self.depth_scale)}

    @classmethod
    def from_dict(cls, data: Any) -> ObservationMeta:
        d = validate(cls.KIND, data)
        cam = {k: d[k] for k in ("width", "height", "K", "T_world_camera")}
        return cls(camera=Camera.from_dict(cam), depth_scale=d["depth_scale"])


@dataclass(frozen=True, kw_only=True, eq=False)
class ObjectRecord(_Value):
    """One object: instance id, key of its canonical mesh, and `T_world_object`."""

    KIND: ClassVar[str] = "records"
    id: str
    mesh: str
    pose: np.ndarray  # (4, 4)

    def __post_init__(self) -> None:
        object.__setattr__(self, "pose", _frozen_array(self.pose, (4, 4)))

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "mesh": self.mesh, "pose": self.pose.tolist()}

    def validate(self) -> None:
        validate("records", [self.to_dict()])

    @classmethod
    def from_dict(cls, data: Any) -> ObjectRecord:
        d = validate("records", [data])[0]
        return cls(id=d["id"], mesh=d["mesh"], pose=d["pose"])


def records_to_list(records: tuple[ObjectRecord, ...] | list[ObjectRecord]) -> list[dict]:
    return [r.to_dict() for r in records]


def records_from_list(data: Any) -> tuple[ObjectRecord, ...]:
    d = validate("records", data)
    return tuple(ObjectRecord(id=r["id"], mesh=r["mesh"], pose=r["pose"]) for r in d)


@dataclass(frozen=True, kw_only=True, eq=False)
class SceneSpec(_Value):
    """Ground-truth scene of a domain (also the record format)."""

    KIND: ClassVar[str] = "scene"
    domain: str
    objects: tuple[ObjectRecord, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "objects", tuple(self.objects))

    def to_dict(self) -> dict[str, Any]:
        return {"domain": self.domain, "objects": records_to_list(self.objects)}

    @classmethod
    def from_dict(cls, data: Any) -> SceneSpec:
        d = validate(cls.KIND, data)
        return cls(domain=d["domain"], objects=records_from_list(d["objects"]))

    def by_id(self) -> dict[str, ObjectRecord]:
        return {o.id: o for o in self.objects}


@dataclass(frozen=True, kw_only=True, eq=False)
class PlanStep(_Value):
    """Transfer `object` to `target_pose` (T_world_object after the transfer)."""

    KIND: ClassVar[str] = "plan"
    object: str
    target_pose: np.ndarray  # (4, 4)

    def __post_init__(self) -> None:
        object.__setattr__(self, "target_pose", _frozen_array(self.target_pose, (4, 4)))

    def to_dict(self) -> dict[str, Any]:
        return {"object": self.object, "target_pose": self.target_pose.tolist()}

    def validate(self) -> None:
        validate("plan", {"status": "ok", "steps": [self.to_dict()]})


@dataclass(frozen=True, kw_only=True, eq=False)
class Instance(_Value):
    """A start/goal pair, optionally with a name, its seed and a valid construction order."""

    KIND: ClassVar[str] = "instance"
    domain: str
    start: SceneSpec
    goal: SceneSpec
    name: str | None = None
    seed: int | None = None
    order: tuple[PlanStep, ...] | None = None  # a valid construction order (an ok plan)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"domain": self.domain}
        if self.name is not None:
            d["name"] = self.name
        if self.seed is not None:
            d["seed"] = int(self.seed)
        d["start"] = self.start.to_dict()
        d["goal"] = self.goal.to_dict()
        if self.order is not None:
            d["order"] = {"status": "ok", "steps": [s.to_dict() for s in self.order]}
        return d

    @classmethod
    def from_dict(cls, data: Any) -> Instance:
        d = validate(cls.KIND, data)
        order = (d.get("order") or {}).get("steps")
        return cls(
            domain=d["domain"],
            name=d.get("name"),
            seed=d.get("seed"),
            start=SceneSpec.from_dict(d["start"]),
            goal=SceneSpec.from_dict(d["goal"]),
            order=None
            if order is None
            else tuple(PlanStep(object=s["object"], target_pose=s["target_pose"]) for s in order),
        )


@dataclass(frozen=True, kw_only=True, eq=False)
class OkPlan(_Value):
    KIND: ClassVar[str] = "plan"
    kind: Literal["ok"] = "ok"
    steps: tuple[PlanStep, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", tuple(self.steps))

    def to_dict(self) -> dict[str, Any]:
        return {"status": "ok", "steps": [s.to_dict() for s in self.steps]}


@dataclass(frozen=True, kw_only=True, eq=False)
class InfeasiblePlan(_Value):
    KIND: ClassVar[str] = "plan"
    kind: Literal["infeasible"] = "infeasible"
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {"status": "infeasible", "reason": self.reason}


Plan = OkPlan | InfeasiblePlan


def plan_from_dict(data: Any) -> Plan:
    d = validate("plan", data)
    if d["status"] == "ok":
        return OkPlan(
            steps=tuple(
                PlanStep(object=s["object"], target_pose=s["target_pose"]) for s in d["steps"]
            )
        )
    return InfeasiblePlan(reason=d["reason"])


@dataclass(frozen=True, kw_only=True, eq=False)
class Edge(_Value):
    """A typed, directed relation `source --type--> target`, with optional attributes."""

    KIND: ClassVar[str] = "relations"
    source: str
    target: str
    type: str
    key: int | str | None = None
    attrs: tuple[tuple[str, Any], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = dict(self.attrs)
        d.update(type=self.type, source=self.source, target=self.target)
        if self.key is not None:
            d["key"] = self.key
        return d


@dataclass(frozen=True, kw_only=True, eq=False)
class RelationGraph(_Value):
    """The relation graph R: node-link JSON of a networkx MultiDiGraph (`edges="edges"`)."""

    KIND: ClassVar[str] = "relations"
    nodes: tuple[str, ...]
    edges: tuple[Edge, ...] = ()
    graph: tuple[tuple[str, Any], ...] = field(default=())

    def __post_init__(self) -> None:
        object.__setattr__(self, "nodes", tuple(self.nodes))
        object.__setattr__(self, "edges", tuple(self.edges))

    def to_dict(self) -> dict[str, Any]:
        return {
            "directed": True,
            "multigraph": True,
            "graph": dict(self.graph),
            "nodes": [{"id": n} for n in self.nodes],
            "edges": [e.to_dict() for e in self.edges],
        }

    @classmethod
    def from_dict(cls, data: Any) -> RelationGraph:
        d = validate(cls.KIND, data)
        edges = []
        for e in d["edges"]:
            attrs = tuple(
                sorted((k, v) for k, v in e.items() if k not in ("source", "target", "type", "key"))
            )
            edges.append(
                Edge(
                    source=e["source"],
                    target=e["target"],
                    type=e["type"],
                    key=e.get("key"),
                    attrs=attrs,
                )
            )
        return cls(
            nodes=tuple(n["id"] for n in d["nodes"]),
            edges=tuple(edges),
            graph=tuple(sorted(d.get("graph", {}).items())),
        )

    def to_networkx(self) -> nx.MultiDiGraph:
        return nx.node_link_graph(self.to_dict(), edges="edges")

    @classmethod
    def from_networkx(cls, G: nx.MultiDiGraph) -> RelationGraph:
        return cls.from_dict(nx.node_link_data(G, edges="edges"))


@dataclass(frozen=True, kw_only=True, eq=False)
class State(_Value):
    """s = (O, R): object records and their relation graph."""

    KIND: ClassVar[str] = "state"
    objects: tuple[ObjectRecord, ...]
    relations: RelationGraph

    def to_dict(self) -> dict[str, Any]:
        return {"objects": records_to_list(self.objects), "relations": self.relations.to_dict()}

    def validate(self) -> None:
        validate("records", self.to_dict()["objects"])
        validate("relations", self.relations.to_dict())
        ids = {o.id for o in self.objects}
        for i, n in enumerate(self.relations.nodes):
            if n not in ids:
                raise ContractError(f"relations.nodes[{i}].id", f"'{n}' is not an object record id")

    @classmethod
    def from_dict(cls, data: Any) -> State:
        if not isinstance(data, dict) or set(data) != {"objects", "relations"}:
            raise ContractError("", "a state is {'objects': records, 'relations': graph}")
        state = cls(
            objects=records_from_list(data["objects"]),
            relations=RelationGraph.from_dict(data["relations"]),
        )
        state.validate()
        return state
