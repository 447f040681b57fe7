"""Gap bridging that follows the wood (issue 13 item 3): a gap is bridged when it is
short, covered by points, continues its piece's axis, or is small beside a long piece; a
fragment hanging in the air beyond its own length is not bridged."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components

from biomorph.errors import ParameterError
from biomorph.tree import livny
from biomorph.tree.neighbours import (
    BridgeRule,
    bridge_components,
    bridge_supported,
    neighbour_graph,
)
from tests.tree.test_livny import cylinder_points, make_cloud


def _pieces(*clouds):
    pts = np.vstack(clouds)
    lab = np.concatenate([np.full(len(c), i) for i, c in enumerate(clouds)])
    return pts, lab


def test_axis_continuation_is_bridged_a_lateral_jump_is_not():
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(0)
    stem = cylinder_points((0, 0, 0), (0, 0, 2), 0.05, 3000, rng)
    # a 60 cm branch piece pointing at the stem across a 30 cm gap (occlusion at its base)
    branch = cylinder_points((0.35, 0, 1.0), (0.95, 0, 1.3), 0.02, 600, rng)
    # a 20 cm blob 30 cm beside the stem, its long axis parallel to it (no continuation)
    blob = cylinder_points((0.35, 0.3, 1.5), (0.35, 0.3, 1.7), 0.02, 200, rng)
    pts, lab = _pieces(stem, branch, blob)
    kd = cKDTree(pts)
    rule = BridgeRule(short=0.1, spacing=0.01)
    a = np.array([3000 + int(np.argmin(pts[3000:3600, 0])), 3600 + int(np.argmin(pts[3600:, 0]))])
    b = np.array([int(kd.query(pts[a[0]], k=1)[1]), int(kd.query(pts[a[1]], k=1)[1])])
    b = np.array([int(np.argmin(np.linalg.norm(stem - pts[x], axis=1))) for x in a])
    ok, _, _ = bridge_supported(pts, a, b, lab, kd, rule)
    assert ok.tolist() == [True, False]
    # the same gaps below the short limit are bridged without further support
    ok, _, _ = bridge_supported(pts, a, b, lab, kd, BridgeRule(short=0.6, spacing=0.01))
    assert ok.all()


def test_floating_fragment_is_left_out_of_the_tree():
    rng = np.random.default_rng(1)
    tree = make_cloud(n=6000, seed=7)
    # a 15 cm cluster hanging 1 m beside the trunk, in empty air
    frag = cylinder_points((1.0, -0.6, 1.0), (1.0, -0.6, 1.15), 0.03, 150, rng)
    pts = np.vstack([tree, frag])
    res = livny.skeletonize_graph(pts)
    assert res.info["unbridged_points"] >= 150
    assert (res.point_node[-150:] < 0).all()  # not part of the skeleton
    assert (res.point_node[:-150] >= 0).mean() > 0.99
    # the earlier behaviour bridged it anyway
    old = livny.skeletonize_graph(pts, bridge_gap=np.inf)
    assert old.info["unbridged_points"] == 0 and (old.point_node >= 0).all()
    with pytest.raises(ParameterError, match="bridge_gap"):
        livny.skeletonize_graph(pts, bridge_gap=-1.0)


def test_occlusion_gaps_in_real_branches_are_bridged():
    pts = make_cloud(n=6000, seed=4)
    # 25 cm shadow across the lateral branch (long piece beyond it) and 10 cm in the trunk
    lateral = (pts[:, 1] > 0.2) & (pts[:, 1] < 0.45) & (pts[:, 2] < 1.8)
    trunk = (pts[:, 2] > 0.9) & (pts[:, 2] < 1.0) & (np.abs(pts[:, 1]) < 0.15)
    res = livny.skeletonize_graph(pts[~(lateral | trunk)])
    assert res.info["components"] >= 2
    assert res.info["unbridged_points"] == 0


def test_pieces_holding_roots_are_always_joined():
    rng = np.random.default_rng(2)
    base = cylinder_points((0, 0, 0), (0, 0, 0.1), 0.05, 300, rng)
    crown = cylinder_points((0, 0, 0.9), (0, 0, 3.0), 0.05, 3000, rng)
    pts = np.vstack([base, crown])
    g = neighbour_graph(pts, k=8)
    rule = BridgeRule(short=0.05, spacing=0.01)
    g2, n0 = bridge_components(pts, g, rule=rule, anchors=np.arange(50))
    assert n0 == 2 and connected_components(g2, directed=False)[0] == 1


def test_voxel_fragments_join_their_tree_or_drop():
    from biomorph.core.pointcloud import PointCloud
    from biomorph.tree.voxel import skeletonize_voxel

    rng = np.random.default_rng(3)
    pts = make_cloud(n=8000, seed=8)
    # occlusion shadow across the lateral branch: its outer part is a fragment
    shadow = (pts[:, 1] > 0.25) & (pts[:, 1] < 0.4) & (pts[:, 2] < 1.8) & (pts[:, 2] > 1.3)
    frag = cylinder_points((1.2, -0.8, 2.0), (1.2, -0.8, 2.5), 0.03, 600, rng)  # in the air
    cloud = PointCloud(np.vstack([pts[~shadow], frag]))
    kw = dict(cell_size=0.04, bridge_gap=0.0, min_component_voxels=5)
    thesis = skeletonize_voxel(cloud, root_slice=None, **kw)
    assert thesis.grid["components"] >= 2  # fragments are separate "trees"
    one = skeletonize_voxel(cloud, **kw)
    assert one.grid["components"] == 1
    g = one.graph
    assert g.roots.size == 1 and (g.tree_id == 0).all()
    # the lateral branch's outer part is kept (joined), the floating cluster is not
    assert (np.linalg.norm(g.position - [0, 0.6, 1.7], axis=1) < 0.1).any()
    assert not (np.linalg.norm(g.position - [1.2, -0.8, 2.25], axis=1) < 0.3).any()
