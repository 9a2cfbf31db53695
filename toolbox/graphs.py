"""Relation graphs: the `R` of the scene representation, as networkx multigraphs.

Design rule: a relation graph is a `networkx.MultiDiGraph` whose nodes are record ids and whose
edges carry a `type` (e.g. an edge a → b of type "on" reads "a is on b"). On the wire it is
node-link JSON with key "edges" (`graph_to_json` / `graph_from_json`). Functions never mutate
their input graphs except `add_relation`.
"""

from __future__ import annotations

from collections.abc import Iterable

import networkx as nx

from toolbox.errors import ToolboxError

__all__ = [
    "add_relation",
    "graph_from_json",
    "graph_to_json",
    "has_relation",
    "is_clear",
    "new_relation_graph",
    "objects_above",
    "relation_changes",
    "relations_of_type",
    "removal_order",
]


def new_relation_graph(ids: Iterable[str]) -> nx.MultiDiGraph:
    """An empty relation graph with one node per record id."""
    G = nx.MultiDiGraph()
    G.add_nodes_from(ids)
    return G


def add_relation(G: nx.MultiDiGraph, source: str, target: str, type: str, **attrs) -> None:
    """Add the edge source → target of `type` (no duplicate of the same type is added).

    Raises ToolboxError when source or target is not a node (ids come from the records).
    """
    for node in (source, target):
        if node not in G:
            raise ToolboxError(f"{node!r} is not a node of the relation graph")
    if not has_relation(G, source, target, type):
        G.add_edge(source, target, type=type, **attrs)


def has_relation(G: nx.MultiDiGraph, source: str, target: str, type: str) -> bool:
    """True when G has an edge source → target of `type`."""
    data = G.get_edge_data(source, target) or {}
    return any(d.get("type") == type for d in data.values())


def relations_of_type(G: nx.MultiDiGraph, type: str) -> list[tuple[str, str]]:
    """Sorted (source, target) pairs of every edge of `type`."""
    return sorted({(u, v) for u, v, t in G.edges(data="type") if t == type})


def graph_to_json(G: nx.MultiDiGraph) -> dict:
    """Node-link JSON dict of the graph (`networkx.node_link_data(G, edges="edges")`)."""
    return nx.node_link_data(G, edges="edges")


def graph_from_json(data: dict) -> nx.MultiDiGraph:
    """Relation graph from node-link JSON (key "edges"); raises ToolboxError when malformed."""
    try:
        G = nx.node_link_graph(data, directed=True, multigraph=True, edges="edges")
    except (KeyError, TypeError, AttributeError, ValueError, nx.NetworkXError) as e:
        raise ToolboxError(f"not a node-link relation graph: {e!r}") from None
    return nx.MultiDiGraph(G)


def objects_above(G: nx.MultiDiGraph, node: str, type: str = "on") -> set[str]:
    """Every object resting directly or indirectly on `node` (ancestors along `type` edges)."""
    if node not in G:
        raise ToolboxError(f"{node!r} is not a node of the relation graph")
    return set(nx.ancestors(_typed(G, type), node))


def is_clear(G: nx.MultiDiGraph, node: str, type: str = "on") -> bool:
    """True when nothing rests on `node` (no incoming edge of `type`): it can be picked up."""
    if node not in G:
        raise ToolboxError(f"{node!r} is not a node of the relation graph")
    return not any(t == type for _, _, t in G.in_edges(node, data="type"))


def removal_order(G: nx.MultiDiGraph, type: str = "on") -> list[str]:
    """All nodes ordered so that each comes before anything it rests on (unstacking order);
    reverse it for a building order. Ties are broken by node name (deterministic).

    Raises ToolboxError when the `type` edges contain a cycle.
    """
    try:
        return list(nx.lexicographical_topological_sort(_typed(G, type), key=str))
    except nx.NetworkXUnfeasible:
        cycle = nx.find_cycle(_typed(G, type))
        raise ToolboxError(f"'{type}' relations contain a cycle: {cycle}") from None


def relation_changes(
    G_from: nx.MultiDiGraph, G_to: nx.MultiDiGraph
) -> dict[str, list[tuple[str, str, str]]]:
    """Edges to add and remove to turn one graph into the other.

    Returns:
        {"added": [(source, target, type), ...] in G_to only, "removed": [...] in G_from
        only}, each sorted.
    """

    def edges(G):
        return {(u, v, t) for u, v, t in G.edges(data="type")}

    a, b = edges(G_from), edges(G_to)
    return {"added": sorted(b - a), "removed": sorted(a - b)}


def _typed(G: nx.MultiDiGraph, type: str) -> nx.DiGraph:
    D = nx.DiGraph()
    D.add_nodes_from(G.nodes)
    D.add_edges_from((u, v) for u, v, t in G.edges(data="type") if t == type)
    return D
