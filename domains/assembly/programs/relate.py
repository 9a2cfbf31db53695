# Written by people (the RIVET team), not by a model: the hand-written reference `relate` for
# the assembly domain, the level a model's program should reach. It uses numpy, networkx and
# the toolbox's exact polyhedral geometry (toolbox.stability).
"""relate(records, meshes) -> graph: support, side contact and accessibility between parts.

Each mesh is cut into convex pieces once (`Shape.from_mesh`: the arch into its legs and the
slabs over its opening, the L-block into foot and leg), so that a part resting on the arch's
legs or standing under its opening is judged by the real shape, not its hull. Two posed parts
are compared with the separating-axis theorem: the axis of least separation says how they
touch — a nearly vertical one is a support ("on"), a horizontal one a side contact
("adjacent"). Accessibility ("blocks") is read from outlines seen from above: a part whose
outline overlaps another's and which lies entirely above it must go before the gripper can
come down on the lower one.
"""

import hashlib

import cv2
import networkx as nx
import numpy as np

from toolbox import Shape, separation
from toolbox.stability import VERTICAL  # |axis z| above which a contact is a support

RELATIONS = {
    "on": "source rests on target: source's bottom touches target's top (vertical gap at most "
    "8 mm where their outlines overlap); a beam on two pillars has two 'on' edges; nothing is "
    "'on' the table (not a node)",
    "adjacent": "source and target touch side by side (at most 5 mm apart horizontally); "
    "listed in both directions",
    "blocks": "target cannot be picked from above until source has been moved: source rests "
    "on target (every 'on' edge is also a 'blocks' edge), or lies entirely above it (its lowest "
    "point at or above target's highest, less 2 mm) with their outlines seen from above "
    "overlapping by more than 2 mm (parts higher up a stack, overhangs)",
}
ON_GAP = 0.008  # [m]
ADJACENT_GAP = 0.005  # [m]
ABOVE = 0.002  # [m] how far a blocking part may reach below the top of the one it blocks
OVERLAP = 0.002  # [m] least overlap of outlines seen from above

_SHAPES = {}  # mesh content hash → Shape


def _shape(mesh):
    v = np.ascontiguousarray(np.asarray(mesh.vertices, dtype=np.float64))
    f = np.ascontiguousarray(np.asarray(mesh.faces, dtype=np.int64))
    key = hashlib.sha1(v.tobytes() + f.tobytes()).hexdigest()
    if key not in _SHAPES:
        _SHAPES[key] = Shape.from_mesh(mesh)
    return _SHAPES[key]


def _outline(points):
    """Convex outline (k, 2) of world points seen from above."""
    xy = np.asarray(points, dtype=float)[:, :2]
    idx = cv2.convexHull(xy.astype(np.float32), returnPoints=False).ravel()
    return xy[idx]


def _outline_overlap(a, b):
    """Overlap depth [m] of two convex outlines (negative: the gap between them)."""
    best = np.inf
    for poly in (a, b):
        e = np.roll(poly, -1, axis=0) - poly
        n = np.stack([-e[:, 1], e[:, 0]], axis=1)
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        pa, pb = a @ n.T, b @ n.T
        depth = np.minimum(pa.max(axis=0) - pb.min(axis=0), pb.max(axis=0) - pa.min(axis=0))
        best = min(best, float(depth.min()))
    return best


def relate(records, meshes):
    recs = {str(r["id"]): r for r in records}
    ids = sorted(recs)
    shapes = {i: _shape(meshes[recs[i]["mesh"]]) for i in ids}
    poses = {i: np.asarray(recs[i]["pose"], dtype=float) for i in ids}
    world = {}
    for i in ids:
        pts = np.concatenate(shapes[i].pieces)
        world[i] = pts @ poses[i][:3, :3].T + poses[i][:3, 3]
    outline = {i: _outline(world[i]) for i in ids}
    g = nx.MultiDiGraph()
    g.add_nodes_from(ids)
    for k, a in enumerate(ids):
        for b in ids[k + 1 :]:
            lo_a, hi_a = world[a].min(axis=0), world[a].max(axis=0)
            lo_b, hi_b = world[b].min(axis=0), world[b].max(axis=0)
            limit = max(ON_GAP, ADJACENT_GAP)
            if np.any(lo_a > hi_b + limit) or np.any(lo_b > hi_a + limit):
                gap, axis = np.inf, np.array([0.0, 0.0, 1.0])
            else:
                gap, axis = separation(shapes[a], poses[a], shapes[b], poses[b], cutoff=limit)
            if abs(axis[2]) >= VERTICAL:
                if gap <= ON_GAP:
                    upper, lower = (a, b) if axis[2] > 0 else (b, a)
                    g.add_edge(upper, lower, type="on")
            elif gap <= ADJACENT_GAP:
                g.add_edge(a, b, type="adjacent")
                g.add_edge(b, a, type="adjacent")
    on = {(a, b) for a, b, t in g.edges(data="type") if t == "on"}
    for a in ids:
        for b in ids:
            if a == b:
                continue
            above = world[a][:, 2].min() >= world[b][:, 2].max() - ABOVE
            if (a, b) in on or (above and _outline_overlap(outline[a], outline[b]) > OVERLAP):
                g.add_edge(a, b, type="blocks")
    return nx.node_link_data(g, edges="edges")
