"""Cleanup (Livny step viii): cylinder overlap, both collapse rules, false branches."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree import cleanup as cl


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def test_axis_fraction_closed_form_cases():
    z = np.array([[0.0, 0, 1]])
    o = np.zeros((1, 3))
    # collinear inside: the first 1 m of a 2 m segment lies in a 1 m cylinder
    f = cl.axis_inside_fraction(o, z, np.array([1.0]), np.array([0.1]), o, z, np.array([2.0]))
    assert f[0] == pytest.approx(0.5)
    # perpendicular: exits through the mantle at s = R
    x = np.array([[1.0, 0, 0]])
    f = cl.axis_inside_fraction(o, z, np.array([1.0]), np.array([0.2]), o, x, np.array([1.0]))
    assert f[0] == pytest.approx(0.2)
    # 45°: mantle exit at s = R / sin 45°
    d = _unit([1, 0, 1])[None]
    f = cl.axis_inside_fraction(o, z, np.array([10.0]), np.array([0.1]), o, d, np.array([1.0]))
    assert f[0] == pytest.approx(0.1 * np.sqrt(2))
    # a segment starting outside the cylinder is not inside at all
    f = cl.axis_inside_fraction(
        o, z, np.array([1.0]), np.array([0.1]), np.array([[1.0, 0, 0.5]]), z, np.array([0.2])
    )
    assert f[0] == 0.0


def test_rule1_merges_a_spur_lying_inside_the_stem_cylinder():
    # u=0 at the base, v=1 up the stem (radius 0.1), w=2 a short spur 5 cm off-axis
    pos = np.array([[0, 0, 0], [0, 0, 1.0], [0.05, 0, 0.4], [0, 0, 2]])
    g = BranchGraph(pos, np.array([-1, 0, 0, 1]), radius=np.array([0.1, 0.1, 0.02, 0.08]))
    out = cl.collapse_overlaps(g, max_edge=0.5)
    assert out.n_nodes == 3 and out.leaves.size == 1
    # a real side branch at 60° keeps its node
    pos2 = pos.copy()
    pos2[2] = [0.8, 0, 0.46]
    g2 = g.with_(position=pos2)
    out2 = cl.collapse_overlaps(g2, max_edge=0.5)
    assert out2.leaves.size == 2


def test_a_chain_running_back_down_inside_the_stem_is_merged():
    """Rule 1b: a fork's child lying inside the cylinder of the fork's own incoming edge
    (a chain on the far side of a thick stem, hanging down from a higher vertex) merges;
    rule 1 never sees it (it compares the children only). A drooping branch that leaves
    the stem's cylinder stays."""
    # stem 0 -> 1 -> 2 -> 3 up the z axis (r = 0.1); at 2 a chain 4 -> 5 back down 8 cm off
    pos = np.array(
        [[0, 0, 0], [0, 0, 0.5], [0, 0, 1.0], [0, 0, 1.5], [0.08, 0, 0.8], [0.08, 0, 0.6]]
    )
    par = np.array([-1, 0, 1, 2, 2, 4])
    rad = np.array([0.1, 0.1, 0.1, 0.1, 0.02, 0.02])
    g = BranchGraph(pos, par, radius=rad)
    out = cl.collapse_overlaps(g)
    assert out.leaves.size == 1 and out.n_nodes <= 4
    droop = pos.copy()
    droop[4:] = [[0.4, 0, 0.8], [0.7, 0, 0.6]]
    assert cl.collapse_overlaps(g.with_(position=droop)).leaves.size == 2


def test_rule2_collapses_straight_chains_and_keeps_bends():
    z = np.linspace(0, 1, 11)
    pos = np.column_stack([np.zeros(11), np.zeros(11), z])
    g = BranchGraph(pos, np.arange(-1, 10), radius=np.full(11, 0.05))
    out = cl.collapse_overlaps(g)
    assert out.n_nodes < 5
    assert out.position[out.roots[0]] == pytest.approx([0, 0, 0])  # root never moves
    assert out.total_length == pytest.approx(1.0, rel=0.1)
    # a right-angle bend survives as a bend (the merged corner moves to the c-weighted
    # mean with its straight neighbour, as the rule says, but the polyline still turns)
    pos_b = np.array([[0, 0, 0], [0, 0, 0.5], [0, 0, 1.0], [0.5, 0, 1.0], [1.0, 0, 1.0]])
    gb = BranchGraph(pos_b, np.arange(-1, 4), radius=np.full(5, 0.02))
    ob = cl.collapse_overlaps(gb)
    e = ob.position[ob.edges[:, 1]] - ob.position[ob.edges[:, 0]]
    e /= np.linalg.norm(e, axis=1)[:, None]
    assert np.min(e @ e[0]) < np.cos(np.radians(45))
    assert ob.leaves.size == 1 and ob.n_nodes >= 3


def test_merged_vertex_is_the_weighted_mean():
    # chain root -> a -> b -> c (b's cylinder ahead of a covers c): a and b merge
    pos = np.array([[0, 0, 0], [0, 0, 1.0], [0, 0, 1.4], [0, 0, 1.6]])
    g = BranchGraph(pos, np.array([-1, 0, 1, 2]), radius=np.full(4, 0.05))
    c = g.subtree_length()
    out = cl.collapse_overlaps(g, max_rounds=1)
    expect = (c[1] * pos[1] + (c[2] + 1e-9) * pos[2]) / (c[1] + c[2] + 1e-9)
    assert (
        np.any(np.allclose(out.position, expect, atol=1e-6), axis=None)
        or np.min(np.linalg.norm(out.position - expect, axis=1)) < 1e-6
    )


def test_false_trunk_branches_are_removed_by_radius_contrast():
    stem = np.column_stack([np.zeros(11), np.zeros(11), np.linspace(0, 2, 11)])
    spur = np.array([[0.12, 0, 1.0], [0.15, 0, 1.02]])  # 5 cm on a 10 cm stem
    branch = np.array([[0.3, 0, 1.3], [0.6, 0, 1.6], [0.9, 0, 1.9]])
    pos = np.vstack([stem, spur, branch])
    parent = np.concatenate([np.arange(-1, 10), [5, 11], [6, 13, 14]])
    r = np.concatenate([np.full(11, 0.1), [0.01, 0.01], [0.03, 0.02, 0.01]])
    g = BranchGraph(pos, parent, radius=r)
    out = cl.remove_false_branches(g)
    assert out.n_nodes == 14 and out.leaves.size == 2
    # min_length prunes any short side tip
    out2 = cl.remove_false_branches(g, radius_ratio=0.0, min_length=0.2)
    assert out2.n_nodes == 14
    out3 = cl.remove_false_branches(g, radius_ratio=0.0, min_length=0.1)
    assert out3.n_nodes == 16  # the spur (0.16 m) is longer than that
    with pytest.raises(ParameterError):
        cl.remove_false_branches(g.with_(radius=None))


def test_cleanup_requires_radii_and_valid_overlap():
    g = BranchGraph(np.zeros((1, 3)), np.array([-1]))
    with pytest.raises(ParameterError):
        cl.collapse_overlaps(g)
    g = g.with_(radius=np.ones(1))
    with pytest.raises(ParameterError):
        cl.collapse_overlaps(g, overlap=1.5)


def test_prune_small_trees():
    pos = np.array([[0, 0, 0], [0, 0, 2.0], [5, 0, 0], [5, 0, 0.05]])
    g = BranchGraph(pos, np.array([-1, 0, -1, 2]))
    out = cl.prune_small_trees(g, 0.5)
    assert out.n_nodes == 2


def test_smooth_chains_removes_zigzag_and_keeps_ends():
    from biomorph.tree.cleanup import smooth_chains

    n = 41
    z = np.linspace(0, 2, n)
    straight = np.column_stack([np.zeros(n), np.zeros(n), z])
    parent = np.arange(-1, n - 1)
    g = BranchGraph(straight, parent)
    # a straight, evenly spaced chain is a fixed point
    assert np.allclose(smooth_chains(g, 3).position, straight, atol=1e-15)
    # an alternating ±5 mm zig-zag on 5 cm steps: two sweeps remove it and its extra length
    zig = straight + np.column_stack([0.005 * (-1.0) ** np.arange(n), np.zeros(n), np.zeros(n)])
    zig[0, 0] = zig[-1, 0] = 0.0
    gz = BranchGraph(zig, parent)
    sm = smooth_chains(gz, 2)
    assert gz.total_length > 2.009  # the zig-zag is 0.5 % longer
    assert sm.total_length == pytest.approx(2.0, abs=1e-3)
    assert np.allclose(sm.position[[0, -1]], zig[[0, -1]])  # root and tip stay
    # forks stay too
    fork_parent = np.array([-1, 0, 1, 1])
    fork = np.array([[0, 0, 0], [0, 0, 1.0], [1, 0, 2], [-1, 0, 2]])
    assert np.array_equal(smooth_chains(BranchGraph(fork, fork_parent), 2).position, fork)
    with pytest.raises(ParameterError):
        smooth_chains(g, -1)


def test_min_radius_merges_a_parallel_noise_spur_beside_a_thin_twig():
    # twig 0 -> 1 -> 2 along z (radius 4 mm); spur from 1 running 1.2 cm beside it
    pos = np.array([[0, 0, 0], [0, 0, 0.2], [0, 0, 0.4], [0.012, 0, 0.3], [0.012, 0, 0.38]])
    g = BranchGraph(pos, np.array([-1, 0, 1, 1, 3]), radius=np.full(5, 0.004))
    assert cl.collapse_overlaps(g).leaves.size == 2  # thesis rule: two tips
    out = cl.collapse_overlaps(g, min_radius=0.01)
    assert out.leaves.size == 1
    # a real side branch leaving at 60 degrees is kept with the floor
    pos2 = pos.copy()
    pos2[3:] = [[0.09, 0, 0.25], [0.17, 0, 0.3]]
    assert cl.collapse_overlaps(g.with_(position=pos2), min_radius=0.01).leaves.size == 2
    with pytest.raises(ParameterError, match="minimum cylinder radius"):
        cl.collapse_overlaps(g, min_radius=-0.01)


def _fork_graph():
    # stem 0-1-2-3 (z), side chain A 4-5 from node 1 (x), side chain B 6-7 from node 2 (y)
    pos = np.array(
        [
            [0, 0, 0],
            [0, 0, 0.1],
            [0, 0, 0.2],
            [0, 0, 0.3],
            [0.1, 0, 0.1],
            [0.2, 0, 0.1],
            [0, 0.1, 0.2],
            [0, 0.2, 0.2],
        ],
        float,
    )
    par = np.array([-1, 0, 1, 2, 1, 4, 2, 6])
    return BranchGraph(pos, par)


def test_tip_chains_labels_unbranched_runs_to_their_top():
    lab = cl.tip_chains(_fork_graph())
    assert lab.tolist() == [-1, -1, -1, 3, 4, 4, 6, 6]
    single = BranchGraph(np.eye(3), np.array([-1, 0, 1]))
    assert cl.tip_chains(single).tolist() == [0, 0, 0]


def test_prune_unsupported_tips_removes_the_chain_without_points():
    g = _fork_graph()
    rng = np.random.default_rng(1)
    dense = [g.position[i] + rng.normal(0, 0.005, (20, 3)) for i in (0, 1, 2, 3, 4, 5)]
    sparse = [g.position[7] + rng.normal(0, 0.005, (2, 3))]  # chain B: 2 points, 2 nodes
    xyz = np.vstack(dense + sparse)
    out = cl.prune_unsupported_tips(g, xyz, 0.3)
    assert out.n_nodes == 6 and out.leaves.size == 2
    assert not np.any(np.all(np.isclose(out.position, [0, 0.2, 0.2]), axis=1))
    # chains longer than max_length are never judged
    assert cl.prune_unsupported_tips(g, xyz, 0.3, max_length=0.05).n_nodes == 8
    with pytest.raises(ParameterError, match="tip support ratio"):
        cl.prune_unsupported_tips(g, xyz, 1.5)
