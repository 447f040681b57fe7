"""Side tip chains through empty space are pruned from the finished skeleton
(tree.cleanup.empty_tips / prune_empty_tips, the pipeline's empty_tips_phase; issue 13:
tips and length on noisy, leafy scans)."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree.cleanup import EMPTY_REACH, empty_tips, prune_empty_tips

SPACING = 0.01


def _y_tree():
    """A vertical stem (nodes 0-10, 1 m) with two 10 cm side chains leaving node 5: one
    along +x (nodes 11-14), one along -x (nodes 15-18); node spacing 2.5 cm."""
    stem = np.column_stack([np.zeros(11), np.zeros(11), np.linspace(0, 1, 11)])
    right = np.column_stack([np.linspace(0.025, 0.1, 4), np.zeros(4), np.full(4, 0.5)])
    left = right * [-1, 1, 1]
    pos = np.vstack([stem, right, left])
    par = np.concatenate([[-1], np.arange(10), [5, 11, 12, 13], [5, 15, 16, 17]])
    return BranchGraph(pos, par)


def _points(graph: BranchGraph, nodes, step: float = SPACING) -> np.ndarray:
    """Points every ``step`` along the edges into ``nodes`` (a wood surface seen at that
    spacing, here on the axis itself)."""
    out = []
    for v in nodes:
        a, b = graph.position[graph.parent[v]], graph.position[v]
        n = max(int(np.linalg.norm(b - a) / step), 1)
        out.append(a + (b - a) * (np.arange(n) / n)[:, None])
    return np.vstack(out)


def test_a_chain_without_points_goes_and_one_with_points_stays():
    g = _y_tree()
    xyz = _points(g, [*range(1, 11), 11, 12, 13, 14])  # nothing along the left chain
    drop = empty_tips(g, xyz, SPACING)
    assert np.array_equal(np.flatnonzero(drop), [15, 16, 17, 18])
    pruned = prune_empty_tips(g, xyz, SPACING)
    assert pruned.n_nodes == 15 and pruned.leaves.size == 2
    assert np.allclose(pruned.weight, pruned.subtree_length())


def test_points_within_the_reach_keep_a_chain_and_half_empty_chains_stay():
    g = _y_tree()
    xyz = _points(g, [*range(1, 11), 11, 12, 13, 14])
    # the left chain's points 2.5 spacings off its axis: within EMPTY_REACH (3)
    side = _points(g, [15, 16, 17, 18]) + [0, 0, 0.9 * EMPTY_REACH * SPACING]
    assert not empty_tips(g, np.vstack([xyz, side]), SPACING).any()
    # points near two of its four nodes only: not mostly empty
    half = g.position[[15, 16]]
    assert not empty_tips(g, np.vstack([xyz, half]), SPACING).any()
    # near one of four: mostly empty
    assert empty_tips(g, np.vstack([xyz, half[:1]]), SPACING).sum() == 4


def test_long_chains_the_stem_and_bad_spacing():
    g = _y_tree()
    xyz = _points(g, range(1, 11))  # only the stem has points
    assert empty_tips(g, xyz, SPACING).sum() == 8
    assert not empty_tips(g, xyz, SPACING, max_length=0.09).any()  # both chains 10 cm
    # a tree without forks is one chain from its root: never pruned
    stem = g.subgraph(np.arange(g.n_nodes) < 11)
    assert not empty_tips(stem, xyz[:0] + 5.0, SPACING).any()
    with pytest.raises(ParameterError, match="spacing"):
        empty_tips(g, xyz, 0.0)


def test_the_pipeline_prunes_clutter_chains_and_the_option_keeps_them(noisy_conifer):
    from biomorph.tree import skeletonize
    from biomorph.tree.metrics import compare_to_truth

    truth, cloud, on = noisy_conifer
    off = skeletonize(cloud, method="graph", empty_tips=False)
    assert on.params["empty_tips"] is True and off.params["empty_tips"] is False
    assert on.info["empty_tips_removed"] > 0 and "empty_tips_removed" not in off.info
    # (a fork whose side chains all went is a tip itself)
    assert on.graph.leaves.size <= off.graph.leaves.size - on.info["empty_tips_removed"] // 2
    c_on = compare_to_truth(on.world_graph(), truth)
    c_off = compare_to_truth(off.world_graph(), truth)
    # the pruned chains lay off the true branches: precision rises, little true length goes
    assert c_on["precision"] > c_off["precision"] + 0.005, (c_on, c_off)
    assert c_on["recall"] > c_off["recall"] - 0.01, (c_on, c_off)
