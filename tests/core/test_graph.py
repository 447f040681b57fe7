"""BranchGraph: structure and lengths against networkx on random forests."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from biomorph.core.graph import BranchGraph
from biomorph.errors import InputError
from tests.core.test_treeops import random_forest


@st.composite
def graphs(draw):
    n = draw(st.integers(1, 50))
    roots = min(draw(st.integers(1, 3)), n)
    seed = draw(st.integers(0, 10**6))
    parent = random_forest(n, roots, seed)
    pos = np.random.default_rng(seed).normal(size=(n, 3))
    return BranchGraph(pos, parent, radius=np.abs(pos[:, 0]) + 0.01)


def to_nx(g):
    d = nx.DiGraph()
    d.add_nodes_from(range(g.n_nodes))
    for p, c in g.edges:
        d.add_edge(int(p), int(c), length=float(np.linalg.norm(g.position[c] - g.position[p])))
    return d


@settings(max_examples=50, deadline=None)
@given(graphs())
def test_graph_queries_match_networkx(g):
    d = to_nx(g)
    assert g.total_length == pytest.approx(sum(w for *_, w in d.edges(data="length")))
    assert sorted(g.leaves.tolist()) == sorted(i for i in d if d.out_degree(i) == 0)
    assert sorted(g.roots.tolist()) == sorted(i for i in d if d.in_degree(i) == 0)
    vals = np.arange(g.n_nodes, dtype=float)
    sub = g.subtree_sum(vals)
    sublen = g.subtree_length()
    path = g.path_length()
    for i in range(g.n_nodes):
        desc = nx.descendants(d, i) | {i}
        assert sub[i] == pytest.approx(vals[list(desc)].sum())
        assert sublen[i] == pytest.approx(sum(g.edge_length[j] for j in desc if j != i))
        root = [r for r in g.roots if i in nx.descendants(d, int(r)) | {int(r)}][0]
        assert path[i] == pytest.approx(nx.shortest_path_length(d, int(root), i, weight="length"))
        assert g.node_depth[i] == nx.shortest_path_length(d, int(root), i)
        assert g.root_index[i] == root
        assert sorted(g.children(i).tolist()) == sorted(d.successors(i))
    # trees: one label per weakly connected component
    comps = list(nx.weakly_connected_components(d))
    assert len(np.unique(g.trees)) == len(comps)
    for comp in comps:
        assert len({int(g.trees[i]) for i in comp}) == 1
    pos = np.empty(g.n_nodes, int)
    pos[g.order] = np.arange(g.n_nodes)
    assert all(pos[p] < pos[c] for p, c in g.edges)


@settings(max_examples=30, deadline=None)
@given(graphs(), st.integers(0, 10**6))
def test_subgraph_keeps_attributes_and_cuts_edges(g, seed):
    keep = np.random.default_rng(seed).random(g.n_nodes) < 0.6
    s = g.subgraph(keep)
    assert s.n_nodes == keep.sum()
    assert np.allclose(s.position, g.position[keep])
    assert np.allclose(s.radius, g.radius[keep])
    kept_edges = sum(1 for p, c in g.edges if keep[p] and keep[c])
    assert s.edges.shape[0] == kept_edges


def test_invalid_graphs_raise():
    with pytest.raises(InputError, match="cycle"):
        BranchGraph(np.zeros((3, 3)), [-1, 2, 1])
    with pytest.raises(InputError):
        BranchGraph(np.zeros((2, 3)), [-1, 1])
    with pytest.raises(InputError, match="NaN"):
        BranchGraph([[0, 0, np.nan], [0, 0, 1]], [-1, 0])
    with pytest.raises(InputError, match="radius"):
        BranchGraph(np.zeros((2, 3)), [-1, 0], radius=[1.0])
    with pytest.raises(InputError, match="parents"):
        BranchGraph(np.zeros((2, 3)), [-1])


def test_immutability_and_tree_ids():
    g = BranchGraph([[0, 0, 0], [0, 0, 1], [5, 0, 0]], [-1, 0, -1])
    with pytest.raises(ValueError):
        g.position[0, 0] = 1.0
    assert g.trees.tolist() == [0, 0, 1]
    g2 = g.with_(tree_id=[7, 7, 9])
    assert g2.trees.tolist() == [7, 7, 9]
    assert g.total_length == pytest.approx(1.0)
