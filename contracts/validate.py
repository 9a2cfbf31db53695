"""The one validation entry point used at every boundary.

`validate(kind, value)` first checks the JSON Schema file `schemas/<kind>.schema.json`, then
what a schema cannot say (finite numbers, proper rotations, unique ids, edges between known
nodes, start and goal holding the same objects). It raises `ContractError` naming the JSON
path of the first problem, e.g. ``objects[2].pose: rotation is not proper (det = -1.000)``.
Values may hold numpy arrays and scalars; they are checked as their JSON form.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Sequence
from functools import cache
from importlib import resources
from typing import Any

import numpy as np
from jsonschema import Draft202012Validator
from jsonschema.exceptions import ValidationError, best_match
from referencing import Registry, Resource

from contracts import se3
from contracts.errors import ContractError
from contracts.limits import plan_problem

SCHEMA_NAMES = (
    "camera",
    "observation",
    "scene",
    "instance",
    "records",
    "relations",
    "plan",
    "check_report",
    "manifest",
)

Path = tuple[str | int, ...]


def format_path(path: Iterable[str | int]) -> str:
    """`("objects", 2, "pose")` → `objects[2].pose`."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


MAX_ARRAY_ELEMENTS = 1_000_000  # an array in a contract value is a pose or a matrix, not an image


def to_jsonable(value: Any) -> Any:
    """The JSON form of a value holding numpy arrays/scalars and tuples (nothing else converted).

    Raises:
        ContractError: an array of more than `MAX_ARRAY_ELEMENTS` (listing it would cost more
            memory than any contract value needs).
    """
    if isinstance(value, np.ndarray):
        if math.prod(max(d, 1) for d in value.shape) > MAX_ARRAY_ELEMENTS:  # (N, 0): N lists
            raise ContractError("", f"an array of shape {value.shape} where a small value belongs")
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {k: to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_jsonable(v) for v in value]
    return value


@cache
def _validator(kind: str) -> Draft202012Validator:
    base = resources.files("contracts") / "schemas"
    registry: Registry = Registry()
    for entry in base.iterdir():
        if entry.name.endswith(".schema.json"):
            contents = json.loads(entry.read_text())
            resource = Resource.from_contents(contents)
            registry = registry.with_resource(entry.name, resource)
            registry = registry.with_resource(contents["$id"], resource)
    schema = json.loads((base / f"{kind}.schema.json").read_text())
    return Draft202012Validator(schema, registry=registry)


def validate(kind: str, value: Any) -> Any:
    """Check `value` against contract `kind`; return its JSON form.

    Raises:
        ContractError: with `.path` (e.g. ``objects[2].pose``) and `.problem`.
    """
    if kind not in SCHEMA_NAMES:
        raise ContractError("", f"unknown contract '{kind}'; known: {', '.join(SCHEMA_NAMES)}")
    if kind == "plan" and (problem := plan_problem(value)):
        # before the schema, which would build a repr of every step to say "is too long"
        raise ContractError("steps", problem, kind=kind)
    data = to_jsonable(value)
    _check_finite(data, (), kind)
    errors = list(_validator(kind).iter_errors(data))
    if errors:
        # The deepest error is the most specific ("status: 'maybe' is not one of …" beats
        # "'reason' is a required property" at the root).
        depth = max(len(e.absolute_path) for e in errors)
        error = best_match(e for e in errors if len(e.absolute_path) == depth)
        raise ContractError(format_path(error.absolute_path), _describe(error), kind=kind)
    _SEMANTIC[kind](data, (), kind)
    return data


def is_valid(kind: str, value: Any) -> bool:
    try:
        validate(kind, value)
    except ContractError:
        return False
    return True


def _describe(error: ValidationError) -> str:
    if error.validator == "additionalProperties":
        return error.message.replace("Additional properties are not allowed", "unknown field")
    if error.validator in ("minItems", "maxItems") and isinstance(error.instance, list):
        most = "most" if error.validator == "maxItems" else "least"
        return f"has {len(error.instance)} items, where at {most} {error.validator_value} belong"
    return error.message  # (cut by ContractError: it may quote the whole value)


# --- what JSON Schema cannot say -----------------------------------------------------------


def _fail(path: Path, problem: str, kind: str) -> None:
    raise ContractError(format_path(path), problem, kind=kind)


def _check_finite(data: Any, path: Path, kind: str) -> None:
    if isinstance(data, float) and not math.isfinite(data):
        _fail(path, f"number must be finite, got {data}", kind)
    elif isinstance(data, dict):
        for k, v in data.items():
            _check_finite(v, (*path, k), kind)
    elif isinstance(data, list):
        for i, v in enumerate(data):
            _check_finite(v, (*path, i), kind)


def _check_pose(T: list[list[float]], path: Path, kind: str) -> None:
    M = np.asarray(T, dtype=float)
    if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], atol=se3.ROTATION_TOL):
        _fail(path, f"last row must be [0, 0, 0, 1], got {M[3].round(4).tolist()}", kind)
    ortho, det = se3.rotation_defect(M[:3, :3])
    if abs(det - 1.0) > se3.ROTATION_TOL and (det < 0 or ortho <= 10 * se3.ROTATION_TOL):
        _fail(path, f"rotation is not proper (det = {det:.3f})", kind)
    if ortho > se3.ROTATION_TOL:
        _fail(path, f"rotation is not orthonormal (max |RᵀR − I| = {ortho:.2e})", kind)


def _check_unique(ids: Sequence[str], path: Path, field: str, kind: str) -> None:
    seen: dict[str, int] = {}
    for i, ident in enumerate(ids):
        if ident in seen:
            _fail((*path, i, field), f"duplicate id '{ident}' (also at index {seen[ident]})", kind)
        seen[ident] = i


def _records(data: list[dict], path: Path, kind: str) -> None:
    for i, rec in enumerate(data):
        _check_pose(rec["pose"], (*path, i, "pose"), kind)
    _check_unique([r["id"] for r in data], path, "id", kind)


def _scene(data: dict, path: Path, kind: str) -> None:
    _records(data["objects"], (*path, "objects"), kind)


def _instance(data: dict, path: Path, kind: str) -> None:
    for side in ("start", "goal"):
        _scene(data[side], (*path, side), kind)
        if data[side]["domain"] != data["domain"]:
            _fail(
                (*path, side, "domain"),
                f"'{data[side]['domain']}' differs from the instance's domain '{data['domain']}'",
                kind,
            )
    start = {o["id"]: o["mesh"] for o in data["start"]["objects"]}
    goal = {o["id"]: o["mesh"] for o in data["goal"]["objects"]}
    for i, obj in enumerate(data["goal"]["objects"]):
        if obj["id"] not in start:
            _fail((*path, "goal", "objects", i, "id"), f"'{obj['id']}' is not in start", kind)
        if start[obj["id"]] != obj["mesh"]:
            _fail(
                (*path, "goal", "objects", i, "mesh"),
                f"'{obj['mesh']}' differs from start's mesh '{start[obj['id']]}'",
                kind,
            )
    for i, obj in enumerate(data["start"]["objects"]):
        if obj["id"] not in goal:
            _fail((*path, "start", "objects", i, "id"), f"'{obj['id']}' is not in goal", kind)
    for i, step in enumerate((data.get("order") or {}).get("steps", [])):
        _step(step, (*path, "order", "steps", i), start, kind)


def _step(step: dict, path: Path, known: dict[str, Any] | None, kind: str) -> None:
    _check_pose(step["target_pose"], (*path, "target_pose"), kind)
    if known is not None and step["object"] not in known:
        _fail((*path, "object"), f"unknown object '{step['object']}'", kind)


def _plan(data: dict, path: Path, kind: str) -> None:
    for i, step in enumerate(data.get("steps", [])):
        _step(step, (*path, "steps", i), None, kind)


def _relations(data: dict, path: Path, kind: str) -> None:
    nodes = [n["id"] for n in data["nodes"]]
    _check_unique(nodes, (*path, "nodes"), "id", kind)
    known = set(nodes)
    keys: set[tuple[str, str, Any]] = set()
    for i, edge in enumerate(data["edges"]):
        for end in ("source", "target"):
            if edge[end] not in known:
                _fail((*path, "edges", i, end), f"edge to unknown node '{edge[end]}'", kind)
        if "key" in edge:
            triple = (edge["source"], edge["target"], edge["key"])
            if triple in keys:
                _fail((*path, "edges", i, "key"), f"duplicate edge key {triple}", kind)
            keys.add(triple)


def _camera(data: dict, path: Path, kind: str) -> None:
    K = np.asarray(data["K"], dtype=float)
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        _fail((*path, "K"), f"focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}", kind)
    if not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0:
        _fail((*path, "K"), "must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]", kind)
    _check_pose(data["T_world_camera"], (*path, "T_world_camera"), kind)


def _check_report(data: dict, path: Path, kind: str) -> None:
    names = [c["name"] for c in data["checks"]]
    failing = [c["name"] for c in data["checks"] if c["status"] in ("failed", "error")]
    if data["passed"] != (not failing):
        _fail((*path, "passed"), f"is {data['passed']} but failing checks are {failing}", kind)
    first = data.get("first_failure")
    if first is not None and first not in names:
        _fail((*path, "first_failure"), f"'{first}' is not a check of this report", kind)


def _manifest(data: dict, path: Path, kind: str) -> None:
    for name, entry in data["functions"].items():
        if entry["file"] != f"{name}.py":
            _fail((*path, "functions", name, "file"), f"must be '{name}.py'", kind)
        for j, dep in enumerate(entry["depends_on"]):
            if dep not in data["functions"]:
                _fail(
                    (*path, "functions", name, "depends_on", j),
                    f"depends on '{dep}', which the manifest does not hold",
                    kind,
                )


_SEMANTIC: dict[str, Callable[[Any, Path, str], None]] = {
    "camera": _camera,
    "observation": _camera,
    "scene": _scene,
    "instance": _instance,
    "records": _records,
    "relations": _relations,
    "plan": _plan,
    "check_report": _check_report,
    "manifest": _manifest,
}
