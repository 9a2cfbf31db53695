# Written by people (the RIVET team), not by a model: the hand-written reference `relate` for
# the cubes domain, the level a model's program should reach. It uses numpy, networkx and the
# toolbox's VERTICAL.
"""relate(records, meshes) -> graph: support and adjacency between cubes, from geometry.

Each record's mesh is placed at its pose; two convex bodies are compared with the
separating-axis theorem (face normals and edge-pair cross products). The axis of least
separation says how they touch: a nearly vertical axis is a support contact ("on"), a
horizontal one a side contact ("adjacent").
"""

import networkx as nx
import numpy as np

from toolbox.stability import VERTICAL  # |axis z| above which a contact is a support

RELATIONS = {
    "on": "source rests on target: source's bottom touches target's top (vertical gap at most "
    "8 mm); a cube on two cubes has two 'on' edges; nothing is 'on' the table (not a node)",
    "adjacent": "source and target stand side by side with at most 12 mm between their side "
    "faces; listed in both directions",
}
ON_GAP = 0.008  # [m]
ADJACENT_GAP = 0.012  # [m]


def _body(mesh, pose):
    pose = np.asarray(pose, dtype=float)
    v = np.asarray(mesh.vertices, dtype=float) @ pose[:3, :3].T + pose[:3, 3]
    normals = np.asarray(mesh.face_normals, dtype=float) @ pose[:3, :3].T
    e = np.asarray(mesh.edges_unique, dtype=int)
    d = v[e[:, 1]] - v[e[:, 0]]
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    return v, _unique(normals), _unique(d)


def _unique(d):
    d = np.where((np.round(d, 6) @ [1e6, 1e3, 1.0] < 0)[:, None], -d, d)  # ±d: one axis
    _, idx = np.unique(np.round(d, 6), axis=0, return_index=True)
    return d[np.sort(idx)]


def _separation(a, b):
    """Signed gap [m] between two convex bodies and its axis, pointing from b to a."""
    (va, na, ea), (vb, nb, eb) = a, b
    cross = np.cross(ea[:, None, :], eb[None, :, :]).reshape(-1, 3)
    n = np.linalg.norm(cross, axis=1)
    axes = np.concatenate([na, nb, cross[n > 1e-6] / n[n > 1e-6, None]])
    pa, pb = va @ axes.T, vb @ axes.T
    up = pa.min(axis=0) - pb.max(axis=0)
    down = pb.min(axis=0) - pa.max(axis=0)
    gaps = np.maximum(up, down)
    i = int(np.argmax(gaps))
    return float(gaps[i]), axes[i] * (1.0 if up[i] >= down[i] else -1.0)


def relate(records, meshes):
    ids = [str(r["id"]) for r in records]
    bodies = {str(r["id"]): _body(meshes[r["mesh"]], r["pose"]) for r in records}
    g = nx.MultiDiGraph()
    g.add_nodes_from(sorted(ids))
    order = sorted(ids)
    for i, a in enumerate(order):
        for b in order[i + 1 :]:
            gap, axis = _separation(bodies[a], bodies[b])
            if abs(axis[2]) >= VERTICAL:
                if gap <= ON_GAP:
                    upper, lower = (a, b) if axis[2] > 0 else (b, a)
                    g.add_edge(upper, lower, type="on")
            elif gap <= ADJACENT_GAP:
                g.add_edge(a, b, type="adjacent")
                g.add_edge(b, a, type="adjacent")
    return nx.node_link_data(g, edges="edges")
