"""`Domain.compose` / `composed_instance`: the goals the plan checks meet beyond the generator's
catalogue (docs/checks.md, "Inputs, seeds and budgets")."""

from __future__ import annotations

import numpy as np
import pytest

import domains


@pytest.mark.parametrize("name", domains.names())
def test_composed_instances_carry_an_executable_order(name):
    """`Domain.composed_instance`: the plan checks' composed goals come with an order the
    robot's hand model accepts step by step."""
    from benchmarks.compositions_bench import hand_problem
    from checks.inputs import composed

    domain = domains.load(name)
    got = composed(domain, np.random.default_rng(5), 2)
    assert [i.name.split("/")[0] for i in got] == ["composed", "composed"]
    for inst in got:
        assert inst.order and hand_problem(domain, inst.start["objects"], inst.order) is None


def test_composed_tangram_figures_are_packed_edge_to_edge_and_never_a_catalogue_outline():
    """`Tangram.compose`: seven pieces, each touching another, none overlapping (the scene
    checks), in an outline no dev or test figure has, turned or mirrored."""
    import numpy as np

    from domains.generation import geometric_problems
    from domains.tangram import figures
    from geometry import body_separation, place

    tangram = domains.load("tangram")
    keys = figures.catalogue_keys()
    seen = set()
    for seed in range(1, 9):
        drawn = tangram.compose(seed)
        assert drawn is not None, seed
        start, goal = drawn
        assert geometric_problems(tangram, tangram.scene(goal)) == []
        assert geometric_problems(tangram, tangram.scene(start)) == []
        bodies = [place(r["id"], tangram.parts[r["mesh"]], r["pose"]) for r in goal]
        assert len(bodies) == 7
        for b in bodies:  # every piece 0.5 mm from a neighbour, as the task text packs them
            gap = min(body_separation(b, o)[0] for o in bodies if o is not b)
            assert 0.0 < gap < 0.001, (seed, b.id, gap)
        fig = figures.compose_figure(np.random.default_rng(seed))
        key = figures.shape_key(fig["silhouette"])
        assert key not in keys
        seen.add(key)
    assert len(seen) == 8  # eight seeds, eight outlines
    # what compose refuses: every test figure's outline, also turned a quarter and mirrored
    from domains.tangram import _CATALOGUE

    for polys in figures.TEST_SILHOUETTES.values():
        assert figures.shape_key([[(-y, -x) for x, y in p] for p in polys]) in _CATALOGUE


def test_composed_cubes_goals_are_never_a_test_family():
    """The test split stays held out: a drawn structure shaped like a test family (turned,
    mirrored or shifted) gives no composed goal."""
    import numpy as np

    from domains.cubes import TEST_FAMILIES, TEST_SHAPES, shape_key, task_structure

    cubes = domains.load("cubes")
    ell = TEST_FAMILIES["ell"][0]
    turned = [(-j + 3, i - 1.5, lv) for i, j, lv in ell]  # a quarter turn and a shift
    assert shape_key(turned) in TEST_SHAPES
    assert shape_key([(i, -j, lv) for i, j, lv in ell]) in TEST_SHAPES  # mirrored
    test_shaped = [
        s
        for s in range(1, 41)
        if (c := task_structure(np.random.default_rng(s))) is not None
        and shape_key(c) in TEST_SHAPES
    ]
    assert test_shaped  # the draw does produce them ...
    assert all(cubes.compose(s) is None for s in test_shaped)  # ... and compose drops them


def test_composed_assembly_goals_stand_and_are_never_built_on_a_test_structure():
    """`Assembly.compose`: structures the task text allows beyond the dev catalogue's (pillars
    standing on a part, a part between pillars, towers of three parts and more), valid scenes,
    and none of them contains a test split's main structure: its support graph holds none
    (`networkx` subgraph monomorphism on the reference relations, mesh by mesh — another
    reading than the composer's own `structure_key`)."""
    import networkx as nx
    import numpy as np

    from domains.assembly import MESH, TEST_GOALS, _test_main, task_structure
    from domains.generation import geometric_problems

    assembly = domains.load("assembly")

    def support(members) -> nx.DiGraph:
        recs = [{"id": i, "mesh": MESH[i], "pose": T} for i, T in members]
        g = nx.DiGraph()
        g.add_nodes_from((i, {"mesh": MESH[i]}) for i, _ in members)
        for e in assembly.reference_relations(recs)["edges"]:
            if e["type"] == "on":
                g.add_edge(e["source"], e["target"])
        return g

    def holds(big: nx.DiGraph, small: nx.DiGraph) -> bool:
        match = nx.algorithms.isomorphism.DiGraphMatcher(
            big, small, node_match=lambda a, b: a["mesh"] == b["mesh"]
        )
        return match.subgraph_is_monomorphic()

    tests = [support(_test_main(k, None)) for k in {g[0] for g in TEST_GOALS}]
    drawn = [(s, m) for s in range(1, 301) if (m := task_structure(np.random.default_rng(s)))]
    kept = [(s, m) for s, m in drawn if assembly.compose(s) is not None]
    assert len(kept) >= 150
    on_a_part = 0
    for s, members in kept:
        graph = support(members)
        for t in tests:
            # a test structure with two supporters under one part (tiered, portal-based ones)
            # or a chain of three is what the test split holds out
            if t.number_of_edges() >= 3:
                assert not holds(graph, t), s
        on_a_part += any(MESH[a] == "pillar" and MESH[b] != "pillar" for a, b in graph.edges)
    assert on_a_part >= 10  # pillars standing on another part, which the dev goals never do
    for s, _ in kept[:10]:
        start, goal = assembly.compose(s)
        assert geometric_problems(assembly, assembly.scene(goal)) == [], s
        assert geometric_problems(assembly, assembly.scene(start)) == [], s
