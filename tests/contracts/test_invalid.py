"""Generated invalid values are rejected with a message naming the JSON path."""

from __future__ import annotations

import copy
import json
import math

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from contracts import ContractError, format_path, to_jsonable, validate
from tests.contracts import strategies as cst

EXAMPLES = settings(max_examples=300, deadline=None, derandomize=True)

VALID = {kind: strategy.map(to_jsonable) for kind, strategy in cst.KINDS.items()}
MATRIX_KEYS = {"pose", "target_pose", "K", "T_world_camera"}
POSE_KEYS = {"pose", "target_pose", "T_world_camera"}
# Objects whose fields are open by design (graph/node/edge attributes).
OPEN_OBJECTS = {"graph", "nodes", "edges"}


def _walk(value, path=()):
    yield path, value
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _walk(v, (*path, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _walk(v, (*path, i))


def _get(value, path):
    for p in path:
        value = value[p]
    return value


def _set(value, path, new):
    _get(value, path[:-1])[path[-1]] = new


def _named(path, keys):
    return bool(path) and path[-1] in keys


def _strict_dict(path):
    return not any(isinstance(p, str) and p in OPEN_OBJECTS for p in path)


def _reject(kind, data, expected_path, fragment):
    with pytest.raises(ContractError) as info:
        validate(kind, data)
    err = info.value
    assert err.path == expected_path, f"{err} (expected path {expected_path!r})"
    assert expected_path in str(err) or expected_path == ""
    assert fragment in err.problem, str(err)


MUTATIONS = ("nan", "shape", "improper", "duplicate", "unknown_node", "status", "extra")


@pytest.mark.parametrize("kind", sorted(VALID))
def test_mutations_are_rejected_with_their_path(kind):
    @EXAMPLES
    @given(st.data())
    def check(data):
        value = data.draw(VALID[kind])
        mutation = data.draw(st.sampled_from(MUTATIONS))
        bad = copy.deepcopy(value)
        nodes = list(_walk(bad))
        if mutation == "nan":
            leaves = [p for p, v in nodes if isinstance(v, float)]
            assume(leaves)
            path = data.draw(st.sampled_from(leaves))
            _set(bad, path, data.draw(st.sampled_from([math.nan, math.inf, -math.inf])))
            _reject(kind, bad, format_path(path), "finite")
        elif mutation == "shape":
            mats = [p for p, _ in nodes if _named(p, MATRIX_KEYS)]
            assume(mats)
            path = data.draw(st.sampled_from(mats))
            m = _get(bad, path)
            how = data.draw(st.sampled_from(["drop_row", "add_row", "short_row", "scalar"]))
            if how == "drop_row":
                m.pop()
            elif how == "add_row":
                m.append([0.0] * len(m[0]))
            elif how == "short_row":
                m[0].pop()
            else:
                _set(bad, path, 1.0)
            with pytest.raises(ContractError) as info:
                validate(kind, bad)
            assert info.value.path.startswith(format_path(path)), str(info.value)
        elif mutation == "improper":
            poses = [p for p, _ in nodes if _named(p, POSE_KEYS)]
            assume(poses)
            path = data.draw(st.sampled_from(poses))
            col = data.draw(st.integers(0, 2))
            for row in _get(bad, path)[:3]:
                row[col] = -row[col]
            _reject(kind, bad, format_path(path), "rotation is not proper")
        elif mutation == "duplicate":
            lists = [
                p
                for p, v in nodes
                if isinstance(v, list)
                and v
                and isinstance(v[0], dict)
                and "id" in v[0]
                and "pose" in v[0]
            ]
            assume(lists)
            path = data.draw(st.sampled_from(lists))
            lst = _get(bad, path)
            lst.append(copy.deepcopy(data.draw(st.sampled_from(lst))))
            _reject(kind, bad, format_path((*path, len(lst) - 1, "id")), "duplicate id")
        elif mutation == "unknown_node":
            assume(kind == "relations" and bad["nodes"])
            end = data.draw(st.sampled_from(["source", "target"]))
            edge = {"source": bad["nodes"][0]["id"], "target": bad["nodes"][0]["id"], "type": "on"}
            edge[end] = "zz_not_a_node"
            bad["edges"].append(edge)
            _reject(kind, bad, format_path(("edges", len(bad["edges"]) - 1, end)), "unknown node")
        elif mutation == "status":
            assume(kind == "plan")
            status = data.draw(st.text(max_size=10).filter(lambda s: s not in ("ok", "infeasible")))
            bad["status"] = status
            _reject(kind, bad, "status", "is not one of")
        elif mutation == "extra":
            dicts = [p for p, v in nodes if isinstance(v, dict) and _strict_dict(p)]
            assume(dicts)
            path = data.draw(st.sampled_from(dicts))
            _get(bad, path)["zz_extra"] = 1
            _reject(kind, bad, format_path(path), "unknown field")

    check()


@pytest.mark.parametrize(
    ("kind", "value", "message"),
    [
        (
            "scene",
            {
                "domain": "cubes",
                "objects": [
                    {
                        "id": "a",
                        "mesh": "m",
                        "pose": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
                    }
                ]
                * 2,
            },
            "scene: objects[1].id: duplicate id 'a' (also at index 0)",
        ),
        (
            "records",
            [
                {
                    "id": "a",
                    "mesh": "m",
                    "pose": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]],
                }
            ],
            "records: [0].pose: rotation is not proper (det = -1.000)",
        ),
        ("plan", {"status": "maybe"}, "plan: status: 'maybe' is not one of ['ok', 'infeasible']"),
        (
            "relations",
            {
                "directed": True,
                "multigraph": True,
                "nodes": [{"id": "a"}],
                "edges": [{"source": "a", "target": "b", "type": "on"}],
            },
            "relations: edges[0].target: edge to unknown node 'b'",
        ),
        (
            "camera",
            {
                "width": 640,
                "height": 480,
                "K": [[-1, 0, 320], [0, 500, 240], [0, 0, 1]],
                "T_world_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
            },
            "camera: K: focal lengths must be positive, got fx=-1.0, fy=500.0",
        ),
        ("camera", [], "camera: (root): [] is not of type 'object'"),
    ],
)
def test_messages_read_well(kind, value, message):
    with pytest.raises(ContractError) as info:
        validate(kind, json.loads(json.dumps(value)))
    assert str(info.value) == message


def test_instance_start_and_goal_must_hold_the_same_objects():
    pose = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    inst = {
        "domain": "cubes",
        "start": {"domain": "cubes", "objects": [{"id": "a", "mesh": "cube", "pose": pose}]},
        "goal": {"domain": "cubes", "objects": [{"id": "b", "mesh": "cube", "pose": pose}]},
    }
    with pytest.raises(ContractError, match=r"goal\.objects\[0\]\.id: 'b' is not in start"):
        validate("instance", inst)


def test_unknown_kind_lists_the_choices():
    with pytest.raises(
        ContractError, match="unknown contract 'scenes'; known: camera, observation"
    ):
        validate("scenes", {})
