"""Hypothesis strategies for valid contract values, as plain JSON-style values.

Every strategy draws what `contracts.validate(kind, value)` accepts: dicts and lists whose
poses and matrices are numpy arrays (as programs return them); `contracts.to_jsonable` turns
a drawn value into its JSON form. `KINDS` maps each contract kind to its strategy.
"""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from contracts import se3

ids = st.from_regex(r"[a-z][a-z0-9_]{0,11}", fullmatch=True)
finite = st.floats(min_value=-2.0, max_value=2.0, allow_nan=False, allow_infinity=False)
edge_types = st.from_regex(r"[a-z][a-z0-9_]{0,9}", fullmatch=True)


@st.composite
def rotations(draw) -> np.ndarray:
    """Uniform-ish random proper rotation (3, 3) from a unit quaternion."""
    q = np.array([draw(st.floats(-1, 1)) for _ in range(4)])
    n = float(np.linalg.norm(q))
    if n < 1e-3:
        return np.eye(3)
    w, x, y, z = q / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@st.composite
def poses(draw) -> np.ndarray:
    """A rigid transform (4, 4) with translation in [-2, 2]^3 [m]."""
    return se3.make(draw(rotations()), [draw(finite) for _ in range(3)])


@st.composite
def records(draw, min_size: int = 0, max_size: int = 8) -> list[dict]:
    """Object records `[{"id", "mesh", "pose"}]` with unique ids."""
    names = draw(st.lists(ids, min_size=min_size, max_size=max_size, unique=True))
    return [{"id": n, "mesh": draw(ids), "pose": draw(poses())} for n in names]


@st.composite
def cameras(draw) -> dict:
    """A pinhole camera `{"width", "height", "K", "T_world_camera"}` (OpenCV convention)."""
    w, h = draw(st.integers(16, 4096)), draw(st.integers(16, 4096))
    fx, fy = draw(st.floats(10, 5000)), draw(st.floats(10, 5000))
    K = [[fx, 0.0, draw(st.floats(0, w))], [0.0, fy, draw(st.floats(0, h))], [0.0, 0.0, 1.0]]
    return {"width": w, "height": h, "K": np.array(K), "T_world_camera": draw(poses())}


@st.composite
def observation_metas(draw) -> dict:
    """An observation folder's `camera.json`: a camera plus the depth PNG's scale."""
    return {**draw(cameras()), "depth_scale": draw(st.floats(0.01, 100))}


@st.composite
def scenes(draw, domain: str | None = None) -> dict:
    return {"domain": domain or draw(ids), "objects": draw(records())}


@st.composite
def plan_steps(draw, objects: list[str] | None = None) -> dict:
    name = draw(st.sampled_from(objects)) if objects else draw(ids)
    return {"object": name, "target_pose": draw(poses())}


@st.composite
def instances(draw) -> dict:
    """A start/goal pair over the same objects, with optional name, seed and order."""
    start = draw(scenes())
    goal = {
        "domain": start["domain"],
        "objects": [{**o, "pose": draw(poses())} for o in start["objects"]],
    }
    inst: dict = {"domain": start["domain"]}
    name, seed = draw(st.none() | ids), draw(st.none() | st.integers(0, 2**31))
    if name is not None:
        inst["name"] = name
    if seed is not None:
        inst["seed"] = seed
    inst.update(start=start, goal=goal)
    names = [o["id"] for o in start["objects"]]
    if names and draw(st.booleans()):
        inst["order"] = {"status": "ok", "steps": draw(st.lists(plan_steps(names), max_size=6))}
    return inst


@st.composite
def plans(draw) -> dict:
    if draw(st.booleans()):
        return {"status": "infeasible", "reason": draw(st.text(min_size=1, max_size=40))}
    return {"status": "ok", "steps": draw(st.lists(plan_steps(), max_size=6))}


@st.composite
def relation_graphs(draw) -> dict:
    """Node-link JSON of a networkx MultiDiGraph (`edges="edges"`), keyed edges."""
    nodes = draw(st.lists(ids, min_size=0, max_size=6, unique=True))
    edges = []
    if nodes:
        triples = draw(
            st.lists(
                st.tuples(st.sampled_from(nodes), st.sampled_from(nodes), edge_types), max_size=10
            )
        )
        for key, (s, t, ty) in enumerate(triples):
            edge = {"type": ty, "source": s, "target": t, "key": key}
            if draw(st.booleans()):
                edge["weight"] = draw(finite)
            edges.append(edge)
    return {
        "directed": True,
        "multigraph": True,
        "graph": {},
        "nodes": [{"id": n} for n in nodes],
        "edges": edges,
    }


KINDS = {
    "camera": cameras(),
    "observation": observation_metas(),
    "scene": scenes(),
    "instance": instances(),
    "records": records(),
    "plan": plans(),
    "relations": relation_graphs(),
}
