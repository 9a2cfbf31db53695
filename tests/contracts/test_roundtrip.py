"""Every contract type: valid values survive to_dict → JSON → from_dict unchanged."""

from __future__ import annotations

import json

import networkx as nx
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contracts import (
    Camera,
    Instance,
    ObservationMeta,
    RelationGraph,
    SceneSpec,
    plan_from_dict,
    records_from_list,
    records_to_list,
    validate,
)
from contracts import strategies as cst

EXAMPLES = settings(max_examples=300, deadline=None, derandomize=True)


def _through_json(d):
    return json.loads(json.dumps(d, allow_nan=False))


CASES = [
    ("camera", cst.cameras(), Camera.from_dict, lambda v: v.to_dict()),
    ("observation", cst.observation_metas(), ObservationMeta.from_dict, lambda v: v.to_dict()),
    ("scene", cst.scenes(), SceneSpec.from_dict, lambda v: v.to_dict()),
    ("instance", cst.instances(), Instance.from_dict, lambda v: v.to_dict()),
    ("records", cst.records(), records_from_list, records_to_list),
    ("plan", cst.plans(), plan_from_dict, lambda v: v.to_dict()),
    ("relations", cst.relation_graphs(), RelationGraph.from_dict, lambda v: v.to_dict()),
]


@pytest.mark.parametrize(
    ("kind", "strategy", "from_dict", "to_dict"), CASES, ids=[c[0] for c in CASES]
)
def test_roundtrip(kind, strategy, from_dict, to_dict):
    @EXAMPLES
    @given(strategy)
    def check(value):
        data = _through_json(to_dict(value))
        validate(kind, data)
        back = from_dict(data)
        assert back == value
        assert to_dict(back) == data

    check()


@EXAMPLES
@given(cst.relation_graphs())
def test_networkx_node_link_roundtrip(graph):
    G = graph.to_networkx()
    assert isinstance(G, nx.MultiDiGraph)
    data = _through_json(nx.node_link_data(G, edges="edges"))
    validate("relations", data)
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
    validate("relations", data)
    graph = RelationGraph.from_dict(data)
    H = graph.to_networkx()
    assert H.number_of_edges("red", "green") == 2
    assert H.edges["blue", "red", 0]["clearance"] == 0.01


@given(st.data())
@settings(max_examples=50, deadline=None, derandomize=True)
def test_state_validates_node_ids_against_records(data):
    from contracts import State

    recs = data.draw(cst.records(min_size=1))
    graph = RelationGraph(nodes=tuple(r.id for r in recs))
    State(objects=recs, relations=graph).validate()
    state = State.from_dict(
        _through_json({"objects": records_to_list(recs), "relations": graph.to_dict()})
    )
    assert state.objects == recs
