"""Tip chains lying inside another edge's cylinder (``cleanup.merge_inside_tips``, issue 13).

On clean dense stems the contraction leaves pieces of the stem surface that give short
chains beside the stem's path (parallel paths) or beside a branch's last edge (split
branch ends); a real twig leaves the parent's point envelope and stays.
"""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree import cleanup as cl
from biomorph.tree import livny
from tests.tree.test_livny import cylinder_points, make_cloud

SPACING = 0.01


def _ring_points(a, b, r, rng, step=SPACING):
    """Points on the mantle of the cylinder a→b, about one per ``step``²."""
    length = float(np.linalg.norm(np.subtract(b, a)))
    return cylinder_points(a, b, r, int(length * 2 * np.pi * r / step**2), rng)


def _stem_graph(extra: list[tuple[int, list[tuple[float, float, float]]]]):
    """A 1 m stem along z, nodes every 5 cm; ``extra``: chains (fork node, positions)."""
    pos = [(0.0, 0.0, z) for z in np.arange(0, 1.0001, 0.05)]
    par = [-1] + list(range(len(pos) - 1))
    for fork, pts in extra:
        prev = fork
        for p in pts:
            pos.append(p)
            par.append(prev)
            prev = len(pos) - 1
    pos = np.asarray(pos, float)
    return BranchGraph(pos, np.asarray(par), radius=np.full(len(pos), 0.04))


def test_a_surface_chain_beside_the_stem_is_removed():
    rng = np.random.default_rng(0)
    xyz = _ring_points((0, 0, 0), (0, 0, 1), 0.1, rng)
    # a chain from z = 0.5 up along the stem surface, 9 cm off the axis
    chain = [(0.09, 0.0, z) for z in (0.55, 0.6, 0.65, 0.7, 0.75)]
    g = _stem_graph([(10, chain)])
    assert g.leaves.size == 2
    out, index = cl.merge_inside_tips_mapped(g, xyz, SPACING)
    assert out.leaves.size == 1 and out.n_nodes == 21
    # the chain's nodes map to the fork it left
    assert (index[21:] == 10).all() and (index[:21] == np.arange(21)).all()


def test_a_chain_back_down_the_stem_is_removed():
    rng = np.random.default_rng(1)
    xyz = _ring_points((0, 0, 0), (0, 0, 1), 0.1, rng)
    chain = [(0.0, -0.08, z) for z in (0.55, 0.5, 0.45, 0.4)]
    g = _stem_graph([(12, chain)])
    assert cl.merge_inside_tips(g, xyz, SPACING).leaves.size == 1


def test_a_twig_leaving_the_stem_stays():
    rng = np.random.default_rng(2)
    xyz = np.vstack(
        [
            _ring_points((0, 0, 0), (0, 0, 1), 0.1, rng),
            _ring_points((0.1, 0, 0.5), (0.4, 0, 0.7), 0.01, rng, step=0.004),
        ]
    )
    twig = [(x, 0.0, 0.5 + (x - 0.1) * 2 / 3) for x in (0.1, 0.175, 0.25, 0.325, 0.4)]
    g = _stem_graph([(10, twig)])
    out = cl.merge_inside_tips(g, xyz, SPACING)
    assert out.leaves.size == 2 and out.n_nodes == g.n_nodes
    # also a short twig, 6 cm beyond the stem surface
    short = [(0.12, 0.0, 0.52), (0.16, 0.0, 0.55)]
    rng = np.random.default_rng(3)
    xyz = np.vstack(
        [
            _ring_points((0, 0, 0), (0, 0, 1), 0.1, rng),
            _ring_points((0.1, 0, 0.5), (0.16, 0, 0.55), 0.01, rng, step=0.004),
        ]
    )
    assert cl.merge_inside_tips(_stem_graph([(10, short)]), xyz, SPACING).leaves.size == 2


def test_a_split_branch_end_keeps_the_longer_chain():
    rng = np.random.default_rng(4)
    xyz = _ring_points((0, 0, 0), (0, 0, 1), 0.1, rng)
    # the stem's top node (20, z = 1) forks into two pieces of the top ring
    g = _stem_graph([(19, [(0.05, 0.0, 0.98), (0.06, 0.0, 1.0)])])
    out = cl.merge_inside_tips(g, xyz, SPACING)
    assert out.leaves.size == 1
    assert out.position[:, 2].max() == pytest.approx(1.0)


def test_merge_inside_tips_checks_its_input():
    g = _stem_graph([])
    with pytest.raises(ParameterError):
        cl.merge_inside_tips(g, np.zeros((3, 3)), 0.0)
    with pytest.raises(ParameterError):
        cl.merge_inside_tips(g.with_(radius=None), np.zeros((3, 3)), SPACING)
    assert cl.merge_inside_tips(g, np.zeros((0, 3)), SPACING).n_nodes == g.n_nodes


def test_graph_inside_tips_keeps_every_point_on_a_vertex():
    xyz = make_cloud(n=4000, seed=1)
    on = livny.skeletonize_graph(xyz, level_merge="adaptive", inside_tips=True)
    off = livny.skeletonize_graph(xyz, level_merge="adaptive", inside_tips=False)
    assert on.timings["inside_tips_removed"] > 0
    assert on.graph.n_nodes < off.graph.n_nodes
    assert on.point_node.min() >= 0 and on.point_node.max() < on.graph.n_nodes
    # every point's vertex is its own or the fork its removed chain left
    assert np.median(np.linalg.norm(xyz - on.graph.position[on.point_node], axis=1)) < 0.1
