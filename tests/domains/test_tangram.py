"""Tangram specifics: the figure library, tight tilings, the parallelogram's handedness."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

import domains
from domains._meshing import polygon_area
from domains.tangram.figures import PIECES, SILHOUETTES, UNIT, canonical, cells, solve


@pytest.fixture(scope="module")
def tangram():
    return domains.load("tangram")


def _norm(cs):
    """A silhouette's cells up to translation, quarter turns and mirroring."""
    best = None
    for mirror in (False, True):
        pts = [(-i - 1, j, {0: 0, 1: 3, 2: 2, 3: 1}[q]) for i, j, q in cs] if mirror else list(cs)
        for _ in range(4):
            pts = [(-j - 1, i, (q + 1) % 4) for i, j, q in pts]
            mi, mj = min(p[0] for p in pts), min(p[1] for p in pts)
            key = tuple(sorted((a - mi, b - mj, c) for a, b, c in pts))
            best = key if best is None or key < best else best
    return best


def test_at_least_25_distinct_figures(tangram):
    assert len(tangram.figures) >= 25
    assert list(tangram.figures) == list(SILHOUETTES)
    keys = {_norm(cells([np.asarray(p, float) for p in polys])) for polys in SILHOUETTES.values()}
    assert len(keys) == len(SILHOUETTES)
    assert {"square", "house", "boat", "cat", "arrow"} <= set(SILHOUETTES)


def test_pieces_cut_a_160mm_square():
    total = sum(
        polygon_area(PIECES[m])
        for m in ("large_triangle", "medium_triangle", "small_triangle", "square", "parallelogram")
    )
    total += polygon_area(PIECES["large_triangle"]) + polygon_area(PIECES["small_triangle"])
    assert np.isclose(total * UNIT**2, 0.16**2)


@pytest.mark.parametrize("name", list(SILHOUETTES)[:6])
def test_solver_tiles_a_silhouette(name):
    assert solve(SILHOUETTES[name]) is not None


def test_figures_are_tight_and_exact(tangram):
    """Pieces of a figure never overlap, cover its silhouette, and touch edge to edge."""
    for name in tangram.figures:
        recs = tangram.figure_records(name, np.eye(4))
        polys = []
        for r in recs:
            p = canonical(r["mesh"]) * UNIT
            polys.append(p @ r["pose"][:2, :2].T + r["pose"][:2, 3])
        sil = cells([np.asarray(p, float) for p in SILHOUETTES[name]])
        centre = np.asarray(tangram.figures[name]["centre"])
        got = cells([p / UNIT + centre for p in polys])
        assert got == sil, name
        g = nx.node_link_graph(tangram.reference_relations(recs), edges="edges")
        adj = nx.Graph((u, v) for u, v, t in g.edges(data="type") if t == "adjacent")
        assert adj.number_of_nodes() == 7 and nx.is_connected(adj), name


def test_parallelogram_keeps_its_handedness(tangram):
    """Goals only rotate the parallelogram: its outline is never the mirror image."""
    base = canonical("parallelogram")

    def turn(p):  # z of the cross product of two outline edges
        a, b = p[1] - p[0], p[2] - p[1]
        return a[0] * b[1] - a[1] * b[0]

    lean = turn(base)  # > 0: counter-clockwise outline
    for inst in tangram.benchmark():
        for scene in (inst.start, inst.goal):
            (r,) = [o for o in scene["objects"] if o["id"] == "parallelogram"]
            assert np.isclose(r["pose"][2, 2], 1.0)  # lying flat, knob up
            p = base @ r["pose"][:2, :2].T
            assert np.sign(turn(p)) == np.sign(lean)


def test_some_starts_put_pieces_inside_the_goal_area(tangram):
    from geometry import bodies_of, body_separation

    count = 0
    for inst in tangram.benchmark():
        start = bodies_of(inst.start["objects"], tangram.parts)
        goal = bodies_of(inst.goal["objects"], tangram.parts)
        count += any(body_separation(s, g)[0] < 0 for s in start for g in goal)
    assert count >= 10
