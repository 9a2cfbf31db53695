# A hostile `relate` (a test draft): the record ids as nodes and 200,000 copies of one edge.
# Comparing such graphs as edge multisets, scene after scene, costs the host minutes and
# gigabytes; the checks must refuse the answer on its count, before comparing anything
# (issue 35, item 4).
"""relate(records, meshes) -> graph: one edge, 200,000 times."""

COUNT = 200_000
RELATIONS = {"on": "source rests on target"}


def relate(records, meshes):
    ids = [str(r["id"]) for r in records]
    edge = {"source": ids[0], "target": ids[-1], "type": "on"}
    return {
        "directed": True,
        "multigraph": True,
        "graph": {},
        "nodes": [{"id": i} for i in ids],
        "edges": [dict(edge) for _ in range(COUNT)],
    }
