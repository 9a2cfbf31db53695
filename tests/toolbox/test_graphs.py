"""Relation-graph helpers."""

from __future__ import annotations

import json

import networkx as nx
import pytest

from toolbox.errors import ToolboxError
from toolbox.graphs import (
    add_relation,
    graph_from_json,
    graph_to_json,
    has_relation,
    is_clear,
    new_relation_graph,
    objects_above,
    relation_changes,
    relations_of_type,
    removal_order,
)


def tower():
    G = new_relation_graph(["a", "b", "c", "d"])
    add_relation(G, "b", "a", "on")
    add_relation(G, "c", "b", "on")
    add_relation(G, "d", "a", "adjacent")
    add_relation(G, "c", "b", "on")  # duplicates are ignored
    return G


def test_relations_and_queries():
    G = tower()
    assert G.number_of_edges() == 3
    assert relations_of_type(G, "on") == [("b", "a"), ("c", "b")]
    assert has_relation(G, "c", "b", "on") and not has_relation(G, "b", "c", "on")
    assert objects_above(G, "a") == {"b", "c"}
    assert is_clear(G, "c") and not is_clear(G, "a") and is_clear(G, "d")
    order = removal_order(G)
    assert order.index("c") < order.index("b") < order.index("a")
    assert removal_order(G) == order  # deterministic


def test_json_round_trip_is_the_design_wire_format():
    G = tower()
    data = json.loads(json.dumps(graph_to_json(G)))
    assert "edges" in data and data["directed"] and data["multigraph"]
    H = graph_from_json(data)
    assert isinstance(H, nx.MultiDiGraph)
    assert relation_changes(G, H) == {"added": [], "removed": []}
    with pytest.raises(ToolboxError, match="node-link"):
        graph_from_json({"nodes": "x"})


def test_relation_changes_and_errors():
    G, H = tower(), tower()
    H.remove_edge("c", "b")
    add_relation(H, "c", "d", "on")
    assert relation_changes(G, H) == {"added": [("c", "d", "on")], "removed": [("c", "b", "on")]}
    with pytest.raises(ToolboxError, match="'z' is not a node"):
        add_relation(G, "z", "a", "on")
    add_relation(G, "a", "c", "on")
    with pytest.raises(ToolboxError, match="cycle"):
        removal_order(G)
