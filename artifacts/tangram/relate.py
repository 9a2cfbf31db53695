# Written by people (the RIVET team), not by a model: the hand-written reference `relate` for
# the tangram domain, the level a model's program should reach. It uses numpy, networkx and
# toolbox.packing.
"""relate(records, meshes) -> graph: how flat pieces touch, and whose knob is in whose way.

Pieces are 15 mm plates carrying a 16 mm square knob, 20 mm tall, at their centroid; the
gripper takes the knob between its two fingers, closing along one of the knob's two axes.
Everything is decided from above, in the table plane:

- `adjacent`: the pieces' footprints (convex hulls of the posed meshes) are at most 8 mm
  apart, edge to edge or corner to corner. In a figure, neighbours; listed both ways.
- `on`: one piece rests on another (its bottom within 5 mm of the other's top and their
  footprints overlapping). Never in a valid tangram state; reported so that a plan can refuse.
- `blocks`: the source's knob stands where a finger must go to take the target's knob closing
  along the target's knob axis `axis` ("x" or "y", the target's own frame): the fingers are
  17 mm thick beyond their pads, 24 mm wide, and open to 24 mm around the 16 mm knob; a
  neighbour's plate is lower than the fingertips, its knob is not. With the source in place,
  the target can be gripped only along its other axis; when both axes of a piece are blocked
  by pieces already placed, it can no longer be put down (or picked up) there. So in a goal
  state these edges say which placements must come first: a piece goes in before the last
  of its blockers on one of its axes.
"""

import networkx as nx
import numpy as np

from toolbox.packing import finger_footprints, footprint, polygon_gap
from toolbox.robot import GRASP_MARGINS, JAW_CLEARANCES
from toolbox.stability import TOUCHING

RELATIONS = {
    "adjacent": "the two pieces' footprints are at most 8 mm apart (edge to edge or corner to "
    "corner); listed in both directions",
    "on": "source rests on target (source's bottom within 5 mm of target's top, footprints "
    "overlapping); never in a valid tangram state",
    "blocks": "source's knob is in the way of a finger when the gripper takes target's knob "
    "closing along target's knob axis given by the edge attribute 'axis' ('x' or 'y', target's "
    "own frame); with every blocker of both axes in place, target cannot be gripped where it is",
}
ADJACENT_GAP = 0.008  # [m]
ON_GAP = 0.005  # [m]
KNOB_FROM = 0.016  # the knob is what stands above this height [m]
KNOB = 0.016  # the knob's side (the task text) [m]
# jaw opening around the knob for the approach, the jaws' narrower clearance on each side [m]
OPENING = KNOB + 2 * JAW_CLEARANCES[-1]
FINGER_MARGIN = GRASP_MARGINS[-1]  # the least clearance the hand keeps around its fingers [m]


def _heights(mesh, pose):
    z = np.asarray(mesh.vertices, dtype=float) @ np.asarray(pose, float)[2, :3] + pose[2, 3]
    return float(z.min()), float(z.max())


def relate(records, meshes):
    ids = sorted(str(r["id"]) for r in records)
    by_id = {str(r["id"]): r for r in records}
    poses = {i: np.asarray(by_id[i]["pose"], dtype=float) for i in ids}
    mesh = {i: meshes[by_id[i]["mesh"]] for i in ids}
    plate = {i: footprint(mesh[i], poses[i]) for i in ids}
    z = {i: _heights(mesh[i], poses[i]) for i in ids}
    knob = {}
    for i in ids:
        lo = z[i][0] + KNOB_FROM
        knob[i] = footprint(mesh[i], poses[i], z_range=(lo, np.inf)) if z[i][1] > lo else None
    g = nx.MultiDiGraph()
    g.add_nodes_from(ids)
    for k, a in enumerate(ids):
        for b in ids[k + 1 :]:
            gap, _ = polygon_gap(plate[a], plate[b])
            if gap <= -TOUCHING and abs(z[a][0] - z[b][0]) > 0.005:  # stacked, not side by side
                upper, lower = (a, b) if z[a][0] > z[b][0] else (b, a)
                if abs(z[upper][0] - z[lower][1]) <= ON_GAP:
                    g.add_edge(upper, lower, type="on")
            elif gap <= ADJACENT_GAP:
                g.add_edge(a, b, type="adjacent")
                g.add_edge(b, a, type="adjacent")
    for b in ids:
        if knob[b] is None:
            continue
        centre = knob[b].mean(axis=0)
        for axis, column in (("x", 0), ("y", 1)):
            fingers = finger_footprints(centre, poses[b][:2, column], OPENING, margin=FINGER_MARGIN)
            for a in ids:
                if a == b or knob[a] is None:
                    continue
                if any(polygon_gap(f, knob[a])[0] < 0 for f in fingers):
                    g.add_edge(a, b, type="blocks", axis=axis)
    return nx.node_link_data(g, edges="edges")
