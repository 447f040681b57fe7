"""Voxel method (Gorte & Pfeifer): domain, preprocessing, graph, end-to-end on synthetic trees."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError
from biomorph.tree.metrics import compare_to_truth
from biomorph.tree.synthetic import generate_tree, simulate_scan
from biomorph.tree.voxel import (
    _offsets,
    _sparse_closing,
    preprocess_volume,
    skeleton_graph,
    skeletonize_voxel,
    voxelize,
)


def test_voxel_domain_centred_and_counts():
    xyz = np.array([[0, 0, 0], [1.0, 0.5, 0.25], [0.99, 0.49, 0.24]])
    counts, origin = voxelize(xyz, 0.3)
    assert counts.shape == (4, 2, 1)  # ceil(1/0.3), ceil(0.5/0.3), ceil(0.25/0.3)
    np.testing.assert_allclose(origin + np.array(counts.shape) * 0.15, [0.5, 0.25, 0.125])
    assert counts.sum() == 3 and counts.max() == 2
    with pytest.raises(ParameterError, match="cell_size"):
        voxelize(xyz, 0)


def test_sparse_closing_matches_scipy():
    from scipy import ndimage

    rng = np.random.default_rng(0)
    v = rng.random((20, 20, 20)) < 0.15
    for kind, r in (("ball", 1), (6, 1), (26, 1), ("ball", 2), ("disc", 3)):
        offs = _offsets(kind, r)
        st = np.zeros((2 * r + 1,) * 3, bool)
        st[tuple((offs + r).T)] = True
        p = 2 * r + 1
        ref = ndimage.binary_closing(np.pad(v, p), structure=st)[p:-p, p:-p, p:-p] | v
        assert np.array_equal(_sparse_closing(v, offs), ref), (kind, r)


def test_preprocess_removes_small_components_and_fills_hollow_stem():
    x, y, z = np.mgrid[:30, :30, :30]
    ring = ((x - 15) ** 2 + (y - 15) ** 2 <= 36) & ((x - 15) ** 2 + (y - 15) ** 2 >= 20)
    counts = ring.astype(np.int32)
    counts[2, 2, 2] = 1  # isolated noise voxel
    vol, stats = preprocess_volume(counts, min_size=5, closing=None, disc_radius=0)
    assert not vol[2, 2, 2] and stats["filtered"] == ring.sum()
    assert vol[15, 15, 15]  # hollow stem filled (closed rings)
    # a ring with a gap is closed by the disc
    gap = ring & ~((x > 18) & (np.abs(y - 15) <= 1))
    v2, _ = preprocess_volume(gap.astype(np.int32), closing=None, disc_radius=6, fill_slices=True)
    assert v2[15, 15, 15]
    v3, _ = preprocess_volume(gap.astype(np.int32), closing=None, disc_radius=0)
    assert not v3[15, 15, 15]  # without the disc the open ring stays hollow


def test_disc_closing_fills_hollow_stems_not_the_crotches_of_forks():
    """The disc closing is there for hollow stems (a ring in every slice); the crotch of a
    fork in the crown is no ring, and welding its arms into a sheet made the skeleton run
    arcs through the air (TreeLS spruce: 25 % of the points > 10 cm from every cylinder)."""
    x, y, z = np.mgrid[:30, :30, :8]
    d2 = (x - 15) ** 2 + (y - 15) ** 2
    ring = (d2 <= 36) & (d2 >= 20) & ~((x > 18) & (np.abs(y - 15) <= 1))  # one gap
    fork = np.zeros_like(ring)
    fork[5:28, 5, :] = True
    fork[5, 5:28, :] = True  # two arms at a right angle
    for shape, inside in ((ring, (15, 15, 4)), (fork, (7, 7, 4))):
        (welded, _), (vol, stats) = (
            preprocess_volume(
                shape.astype(np.int32),
                closing=None,
                disc_radius=6,
                fill_slices=False,
                disc_enclosed=enc,
            )
            for enc in (False, True)
        )
        assert welded[inside]  # the plain disc fills both
        if shape is ring:
            assert vol[inside] and stats["disc_added"] > 50  # the stem's inside is filled
        else:
            assert not vol[inside] and stats["disc_added"] == 0  # the arms stay apart


def test_enclosure_counts_rays_that_meet_the_scan():
    from biomorph.tree.voxel import _enclosed

    v = np.zeros((11, 11, 1), bool)
    v[0, :, 0] = v[10, :, 0] = v[:, 0, 0] = v[:, 10, 0] = True  # a square frame
    centre = np.array([[5, 5, 0]])
    assert _enclosed(v, centre, 6, need=8)[0]
    assert not _enclosed(v, centre, 4)[0]  # the frame lies beyond the reach
    u = v.copy()
    u[1:10, 10, 0] = False  # one side open (a U): the ray through it escapes
    assert _enclosed(u, centre, 6)[0] and not _enclosed(u, centre, 6, need=8)[0]
    corner = np.zeros_like(v)
    corner[0, :, 0] = corner[:, 0, 0] = True  # the crotch of two arms: three rays escape
    assert not _enclosed(corner, np.array([[3, 3, 0]]), 6, need=6)[0]
    # a diamond whose voxels touch only at their corners: a digital diagonal would slip
    # between two of them; the ray looks at the voxels it passes between
    d = np.zeros((13, 13, 1), bool)
    for k in range(7):
        for a, b in ((6 + k, k), (6 - k, k), (6 + k, 12 - k), (6 - k, 12 - k)):
            d[a, b, 0] = True
    assert _enclosed(d, np.array([[6, 7, 0]]), 8, need=8)[0]


def test_skeleton_graph_weights_roots_components():
    skel = np.zeros((10, 10, 12), bool)
    skel[2, 2, 1:11] = True  # vertical line, lowest voxel (2,2,1)
    skel[7, 7, 3:6] = True  # a second, smaller component
    ijk, parent, comp = skeleton_graph(skel)
    assert (comp == 0).sum() == 10 and (comp == 1).sum() == 3
    roots = ijk[parent < 0]
    assert {tuple(r) for r in roots} == {(2, 2, 1), (7, 7, 3)}
    ijk2, _, _ = skeleton_graph(skel, keep_largest=1)
    assert len(ijk2) == 10
    # bridging joins pieces separated by a small gap
    skel2 = np.zeros((5, 5, 20), bool)
    skel2[2, 2, 0:8] = True
    skel2[2, 2, 11:19] = True
    _, par, comp2 = skeleton_graph(skel2, bridge_gap=4)
    assert (par < 0).sum() == 1 and comp2.max() == 0


@pytest.mark.parametrize("preset", ["aspen", "conifer"])
def test_voxel_skeleton_of_synthetic_tree(preset):
    truth = generate_tree(preset, seed=0)
    scan = simulate_scan(truth, n_points=30000, seed=0, ground=False, noise=0.003)
    vs = skeletonize_voxel(scan, cell_size=0.05)
    g = vs.graph
    assert set(vs.timings) >= {"t1", "t2", "t3", "t4"}
    assert vs.grid["cell_size"] == 0.05 and g.radius is not None and g.tree_id is not None
    m = compare_to_truth(g, truth, tolerance=0.1)
    assert m["f1"] > 0.85, m
    assert 0.6 < m["tbl_ratio"] < 1.2 and 0.6 < m["nob_ratio"] < 1.6
    # the largest tree starts at the stem base
    root = g.roots[np.argmin(g.trees[g.roots])]
    assert np.linalg.norm(g.position[root] - [0, 0, 0]) < 0.3
    # spur pruning and smoothing change the result in the documented direction
    raw = skeletonize_voxel(scan, cell_size=0.05, prune_length=0, smooth_iterations=0)
    assert raw.graph.leaves.size >= g.leaves.size
    assert raw.graph.total_length >= g.total_length


def test_voxel_bad_inputs():
    rng = np.random.default_rng(0)
    with pytest.raises(InputError):
        skeletonize_voxel(PointCloud(np.zeros((0, 3))))
    scatter = PointCloud(rng.uniform(0, 10, (50, 3)), source="dust.xyz")
    with pytest.raises(InputError, match="dust.xyz"):
        skeletonize_voxel(scatter, cell_size=0.05)
    with pytest.raises(ParameterError, match="closing"):
        skeletonize_voxel(PointCloud(rng.normal(size=(500, 3))), cell_size=0.2, closing=7)


def test_octagon_disc_closes_wide_gapped_ring():
    from biomorph.tree.voxel import _octagon_factors

    x, y = np.mgrid[:40, :40]
    d2 = (x - 20) ** 2 + (y - 20) ** 2
    ring = (d2 <= 100) & (d2 >= 70) & ~((x > 25) & (np.abs(y - 20) <= 1))
    v = np.zeros((40, 40, 3), bool)
    v[:, :, 1] = ring
    closed = _sparse_closing(v, _octagon_factors(11))
    assert closed[20, 20, 1] and (closed[:, :, 1] >= ring).all()
    assert not closed[:, :, 0].any()  # horizontal element: other slices untouched
    assert closed[:, :, 1].sum() < 1.2 * (d2 <= 100).sum()  # filled, not inflated


def test_stem_radius_estimate():
    from biomorph.tree.voxel import _estimate_stem_radius

    rng = np.random.default_rng(0)
    n = 3000
    a = rng.uniform(0, 1.6 * np.pi, n)  # an occluded stem: 290° visible
    z = rng.uniform(0, 2, n)
    stem = np.c_[0.23 * np.cos(a), 0.23 * np.sin(a), z] + rng.normal(0, 0.004, (n, 3))
    twig = np.c_[np.linspace(0.5, 2, 200), np.linspace(0, 1, 200), np.full(200, 0.3)]
    r = _estimate_stem_radius(np.r_[stem, twig], 0.03)
    assert r == pytest.approx(0.23, abs=0.02)


def test_real_coffee_tree_against_qsm():
    from biomorph.tree.cloud import prepare
    from tests.conftest import shared_file

    xyz = np.loadtxt(shared_file("trees", "rtwig_cloud.txt"), usecols=(0, 1, 2))
    p = prepare(PointCloud(xyz, source="rtwig_cloud.txt"))
    vs = skeletonize_voxel(p.cloud)
    g = vs.graph
    assert vs.grid["components"] == 1
    # SimpleForest QSM of the same cloud: 69 tips, 31.43 m (a model, not truth)
    assert 0.6 * 31.43 < g.total_length < 1.1 * 31.43
    assert 20 <= g.leaves.size <= 100
    assert g.position[g.roots[0], 2] < 0.2  # rooted at the stem base


def test_each_stem_roots_its_own_tree_and_a_low_branch_is_not_a_tree():
    """Two stems whose crowns touch (one skeleton component) and a branch piece lying low,
    2 m from either stem, cut off by an occlusion gap: with the stems found in the points
    each stem roots a tree (no tree spans two stems) and the piece is no tree."""
    skel = np.zeros((40, 12, 30), bool)
    skel[5, 5, 0:25] = True  # stem A
    skel[25, 5, 0:25] = True  # stem B
    skel[5:26, 5, 24] = True  # crowns touching at the top
    skel[30:38, 5, 4] = True  # a low branch piece, 5 voxels from B, on no stem
    stems = np.array([[5.0, 5.0], [25.0, 5.0]])
    ijk, parent, comp = skeleton_graph(skel, base_height=10.0, stems=stems, stem_reach=2.0)
    roots = {tuple(v) for v in ijk[parent < 0]}
    assert roots == {(5, 5, 0), (25, 5, 0)}
    for t in np.unique(comp):  # each tree holds one stem only
        on = ijk[comp == t]
        assert len({x for x in on[on[:, 2] < 20][:, 0]} & {5, 25}) == 1
    piece = (ijk[:, 0] >= 30) & (ijk[:, 2] == 4)  # joined to B's tree (or dropped)
    assert (comp[piece] == comp[(ijk[:, 0] == 25) & (ijk[:, 2] == 0)]).all()
    # without the stems (the thesis' lowest-voxel rule) the piece is a tree of its own and
    # the two stems one tree
    ijk, parent, comp = skeleton_graph(skel, base_height=10.0)
    assert (parent < 0).sum() == 2 and ((ijk[:, 0] >= 30) & (comp == comp.max())).any()


def test_a_crown_goes_to_the_stem_its_points_belong_to():
    """Stem B's skeleton breaks at 8 voxels (a sparse stem the thinning cut); its crown
    (z 12-20) touches stem A's top through a twig. Along the skeleton the crown is A's;
    the points say B's (the graph method's segmentation): with them the crown joins B's
    stem at their nearest voxels and A keeps only its own wood."""
    skel = np.zeros((20, 8, 24), bool)
    skel[2, 4, 0:21] = True  # stem A, z 0-20
    skel[14, 4, 0:9] = True  # stem B, broken above z 8
    skel[14, 4, 12:21] = True  # B's crown
    skel[3:14, 4, 20] = True  # a twig of A touching B's crown at the top
    stems = np.array([[2.0, 4.0], [14.0, 4.0]])
    ijk = np.argwhere(skel)
    tree = np.where(ijk[:, 0] == 14, 1, 0)  # points on every voxel: B's column is B's
    tree[(ijk[:, 0] == 14) & (ijk[:, 2] == 20)] = 1
    pts = ijk + 0.5
    crown = lambda v: (v[:, 0] == 14) & (v[:, 2] >= 12)  # noqa: E731
    base_b = lambda v: (v[:, 0] == 14) & (v[:, 2] == 0)  # noqa: E731
    base_a = lambda v: (v[:, 0] == 2) & (v[:, 2] == 0)  # noqa: E731
    plain, _, comp0 = skeleton_graph(skel, stems=stems, stem_reach=2.0)
    assert (comp0[crown(plain)] == comp0[base_a(plain)][0]).all()  # nearest along it: A
    ijk2, parent, comp = skeleton_graph(skel, stems=stems, stem_reach=2.0, labelled=(pts, tree))
    assert (comp[crown(ijk2)] == comp[base_b(ijk2)][0]).all()
    assert not (comp[ijk2[:, 0] == 2] == comp[base_b(ijk2)][0]).any()
    assert (parent < 0).sum() == 2


def test_a_stem_roots_on_its_own_wood_not_at_a_shrub_or_a_lost_voxel_beside_it():
    """Within the stem's reach a shrub (another tree by the points' segmentation) and an
    isolated voxel (a component too small to keep) start lower than the stem's skeleton:
    the stem roots on its own wood (before: at the shrub, the stem hung from it; or at the
    lone voxel, dropped with it, and the stem was lost)."""
    skel = np.zeros((14, 8, 24), bool)
    skel[4, 4, 3:22] = True  # the stem's skeleton starts 3 voxels up
    skel[8, 4, 0:5] = True  # a shrub beside it, from the ground
    skel[5:8, 4, 4] = True  # touching the stem
    skel[3, 3, 0] = True  # a lone voxel
    stems = np.array([[4.0, 4.0], [8.0, 4.0]])
    ijk = np.argwhere(skel)
    tree = np.where(ijk[:, 0] >= 7, 1, 0)  # the shrub's points are the second stem's
    kw = dict(stems=stems[:1], stem_reach=6.0, min_component_voxels=2)
    ijk2, parent, _ = skeleton_graph(skel, labelled=(ijk + 0.5, tree), **kw)
    assert [tuple(v) for v in ijk2[parent < 0]] == [(4, 4, 3)]
    ijk3, parent3, _ = skeleton_graph(skel, **kw)  # no segmentation: the lowest voxel
    assert [tuple(v) for v in ijk3[parent3 < 0]] == [(8, 4, 0)]


def test_no_disc_enclosed_reaches_the_voxel_run_from_the_cli(tmp_path, capsys):
    import json

    from biomorph.cli import run
    from tests.tree.test_cli import _write_xyz
    from tests.tree.test_livny import make_cloud

    xyz = _write_xyz(tmp_path / "tree.xyz", make_cloud(n=4000, seed=21))
    args = ["tree", "skeletonize", str(xyz), "--no-ground", "--json", "--method", "voxel"]
    assert run([*args, "--no-disc-enclosed", "--out", str(tmp_path / "off")]) == 0
    off = json.loads(capsys.readouterr().out)
    assert off["params"]["voxel"] == {"disc_enclosed": False}
    assert run([*args, "--out", str(tmp_path / "on")]) == 0
    on = json.loads(capsys.readouterr().out)
    assert on["params"]["voxel"] == {}  # the default: inside rings only
