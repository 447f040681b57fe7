"""Contraction of the graph method (issue 13): level pieces that follow the wood.

With ``merge="overlap"`` two twigs side by side in one geodesic level stay two vertices
(the default ``"adjacent"`` puts one centroid between them, > 10 cm from the wood on real
crowns); the optional reach bound keeps refined vertices on their points.
"""

from __future__ import annotations

import numpy as np

from biomorph.tree import livny
from biomorph.tree.allometry import skeleton_distance
from biomorph.tree.neighbours import (
    bridge_components,
    contract,
    neighbour_graph,
    shortest_path_forest,
)

from .test_livny import cylinder_points


def _twins(gap: float = 0.08, seed: int = 0):
    """A 5 cm stem forking into two parallel 1 cm twigs ``gap`` apart (axis to axis)."""
    rng = np.random.default_rng(seed)
    h = gap / 2
    parts = [
        ((0, 0, 0), (0, 0, 0.5), 0.05, 2500),
        ((0, 0, 0.5), (-h, 0, 0.6), 0.01, 120),
        ((0, 0, 0.5), (h, 0, 0.6), 0.01, 120),
        ((-h, 0, 0.6), (-h, 0, 1.6), 0.01, 900),
        ((h, 0, 0.6), (h, 0, 1.6), 0.01, 900),
    ]
    return np.vstack([cylinder_points(a, b, r, n, rng, 0.001) for a, b, r, n in parts])


def _levels(xyz, spacing, merge):
    g, _ = bridge_components(xyz, neighbour_graph(xyz, k=10))
    roots = np.flatnonzero(xyz[:, 2] < 0.02)
    geo = g.copy()
    geo.data = np.sqrt(geo.data)
    plen, _ = shortest_path_forest(geo, roots)
    tree = np.where(np.isfinite(plen), 0, -1)
    return contract(xyz, g, plen, tree, spacing, merge=merge)


def test_twigs_side_by_side_stay_two_vertices():
    xyz = _twins()
    con = _levels(xyz, 0.03, "overlap")
    high = con.position[:, 2] > 0.9
    assert high.sum() >= 20  # both twigs reached
    # every vertex of the twin section sits on one twig (|x| ≈ 4 cm), none between them
    assert np.all(np.abs(np.abs(con.position[high, 0]) - 0.04) < 0.015)
    # the default joins every voxel-adjacent piece: centroids between the twigs
    merged = _levels(xyz, 0.03, "adjacent")
    hm = merged.position[:, 2] > 0.9
    assert np.median(np.abs(merged.position[hm, 0])) < 0.01


def test_reach_keeps_refined_twigs_on_their_points():
    xyz = _twins(gap=0.3)
    free = livny.skeletonize_graph(xyz, reach=None)
    bound = livny.skeletonize_graph(xyz)  # reach=REACH by default
    d_free, _ = skeleton_distance(xyz, free.graph.parent, free.graph.position)
    d_bound, _ = skeleton_distance(xyz, bound.graph.parent, bound.graph.position)
    twig = xyz[:, 2] > 0.7
    assert np.quantile(d_bound[twig], 0.95) < 0.03
    assert np.quantile(d_bound[twig], 0.95) <= np.quantile(d_free[twig], 0.95) + 1e-9
    c = livny.clamp_to_points(np.array([[3.0, 0, 0]]), np.zeros((1, 3)), np.array([0.5]))
    assert np.allclose(c, [[0.5, 0, 0]])
