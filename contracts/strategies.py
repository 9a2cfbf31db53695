"""Hypothesis strategies for valid contract values (used by tests and by the check suites)."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from contracts import se3
from contracts.types import (
    Camera,
    Edge,
    InfeasiblePlan,
    Instance,
    ObjectRecord,
    ObservationMeta,
    OkPlan,
    PlanStep,
    RelationGraph,
    SceneSpec,
)

ids = st.from_regex(r"[a-z][a-z0-9_]{0,11}", fullmatch=True)
finite = st.floats(min_value=-2.0, max_value=2.0, allow_nan=False, allow_infinity=False)


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
def records(draw, min_size: int = 0, max_size: int = 8) -> tuple[ObjectRecord, ...]:
    names = draw(st.lists(ids, min_size=min_size, max_size=max_size, unique=True))
    return tuple(ObjectRecord(id=n, mesh=draw(ids), pose=draw(poses())) for n in names)


@st.composite
def cameras(draw) -> Camera:
    w, h = draw(st.integers(16, 4096)), draw(st.integers(16, 4096))
    fx, fy = draw(st.floats(10, 5000)), draw(st.floats(10, 5000))
    K = [[fx, 0.0, draw(st.floats(0, w))], [0.0, fy, draw(st.floats(0, h))], [0.0, 0.0, 1.0]]
    return Camera(width=w, height=h, K=np.array(K), T_world_camera=draw(poses()))


@st.composite
def observation_metas(draw) -> ObservationMeta:
    return ObservationMeta(camera=draw(cameras()), depth_scale=draw(st.floats(0.01, 100)))


@st.composite
def scenes(draw, domain: str | None = None) -> SceneSpec:
    return SceneSpec(domain=domain or draw(ids), objects=draw(records()))


@st.composite
def plan_steps(draw, objects: list[str] | None = None) -> PlanStep:
    name = draw(st.sampled_from(objects)) if objects else draw(ids)
    return PlanStep(object=name, target_pose=draw(poses()))


@st.composite
def instances(draw) -> Instance:
    start = draw(scenes())
    goal = SceneSpec(
        domain=start.domain,
        objects=tuple(
            ObjectRecord(id=o.id, mesh=o.mesh, pose=draw(poses())) for o in start.objects
        ),
    )
    names = [o.id for o in start.objects]
    order = None
    if names and draw(st.booleans()):
        order = tuple(draw(st.lists(plan_steps(names), max_size=6)))
    return Instance(
        domain=start.domain,
        start=start,
        goal=goal,
        name=draw(st.none() | ids),
        seed=draw(st.none() | st.integers(0, 2**31)),
        order=order,
    )


@st.composite
def plans(draw) -> OkPlan | InfeasiblePlan:
    if draw(st.booleans()):
        return InfeasiblePlan(reason=draw(st.text(min_size=1, max_size=40)))
    return OkPlan(steps=tuple(draw(st.lists(plan_steps(), max_size=6))))


edge_types = st.from_regex(r"[a-z][a-z0-9_]{0,9}", fullmatch=True)


@st.composite
def relation_graphs(draw) -> RelationGraph:
    nodes = draw(st.lists(ids, min_size=0, max_size=6, unique=True))
    edges = []
    if nodes:
        for key, (s, t, ty) in enumerate(
            draw(
                st.lists(
                    st.tuples(st.sampled_from(nodes), st.sampled_from(nodes), edge_types),
                    max_size=10,
                )
            )
        ):
            attrs = (("weight", draw(finite)),) if draw(st.booleans()) else ()
            edges.append(Edge(source=s, target=t, type=ty, key=key, attrs=attrs))
    return RelationGraph(nodes=tuple(nodes), edges=tuple(edges))
