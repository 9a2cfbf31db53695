"""Every contract kind: valid values validate, and their JSON form survives a round trip.

Values are plain dicts and lists holding numpy arrays (as programs return them);
`to_jsonable` gives the JSON form, which `validate` returns and which comes back unchanged —
every float bit for bit — from `json.dumps` / `json.loads`.
"""

from __future__ import annotations

import copy
import json

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings

from contracts import to_jsonable, validate
from tests.contracts import strategies as cst

EXAMPLES = settings(max_examples=300, deadline=None, derandomize=True)


def _through_json(d):
    return json.loads(json.dumps(d, allow_nan=False))


def _arrays(value, path=()):
    """(path, array) of every numpy array inside `value`."""
    if isinstance(value, np.ndarray):
        yield path, value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _arrays(v, (*path, k))
    elif isinstance(value, list | tuple):
        for i, v in enumerate(value):
            yield from _arrays(v, (*path, i))


def _get(value, path):
    for p in path:
        value = value[p]
    return value


@pytest.mark.parametrize("kind", sorted(cst.KINDS))
def test_roundtrip(kind):
    @EXAMPLES
    @given(cst.KINDS[kind])
    def check(value):
        before = copy.deepcopy(value)
        data = to_jsonable(value)
        assert validate(kind, value) == data  # the numpy form validates as its JSON form
        back = _through_json(data)
        assert back == data
        assert validate(kind, back) == back
        for path, array in _arrays(value):
            assert np.array_equal(np.asarray(_get(back, path), dtype=float), array), path
        assert all(  # validation leaves the value alone
            np.array_equal(a, _get(before, p)) for p, a in _arrays(value)
        ) and len(list(_arrays(value))) == len(list(_arrays(before)))

    check()


def _edges(data):
    return sorted(
        (json.dumps(e, sort_keys=True) for e in data["edges"]),
    )


@EXAMPLES
@given(cst.relation_graphs())
def test_networkx_node_link_roundtrip(graph):
    G = nx.node_link_graph(graph, edges="edges")
    assert isinstance(G, nx.MultiDiGraph)
    data = _through_json(nx.node_link_data(G, edges="edges"))
    validate("relations", data)
    assert [n["id"] for n in data["nodes"]] == [n["id"] for n in graph["nodes"]]
    assert _edges(data) == _edges(graph)  # every edge with its key and attributes
    H = nx.node_link_graph(data, edges="edges")
    assert sorted(H.nodes) == sorted(G.nodes)
    assert sorted((u, v, k, d["type"]) for u, v, k, d in H.edges(keys=True, data=True)) == sorted(
        (u, v, k, d["type"]) for u, v, k, d in G.edges(keys=True, data=True)
    )


def test_hand_built_multidigraph_validates_and_loads_back():
    G = nx.MultiDiGraph()
    G.add_nodes_from(["red", "green", "blue"])
    G.add_edge("red", "green", type="on")
    G.add_edge("red", "green", type="adjacent")
    G.add_edge("blue", "red", type="blocks", clearance=0.01)
    data = _through_json(nx.node_link_data(G, edges="edges"))
    assert validate("relations", data) == data
    H = nx.node_link_graph(data, edges="edges")
    assert H.number_of_edges("red", "green") == 2
    assert H.edges["blue", "red", 0]["clearance"] == 0.01


@EXAMPLES
@given(cst.records(min_size=1))
def test_records_hold_numpy_poses_and_tuples(recs):
    # programs return numpy arrays and tuples; both validate as the same JSON
    as_tuples = [{**r, "pose": tuple(tuple(row) for row in r["pose"])} for r in recs]
    assert validate("records", as_tuples) == validate("records", recs) == to_jsonable(recs)
