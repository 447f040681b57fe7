"""Real clouds from ``../shared/data/trees`` (skipped with a reason when absent).

References: rTwig's SimpleForest QSM of the coffee-tree cloud and plantscan3d's MTG of the
A3B4 branch (both models, not field truth). Thresholds are set below the agreement we
measure (see docs/tree.md) so that a regression fails, not noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.io import read_graph, read_points
from biomorph.tree.pipeline import skeletonize
from biomorph.tree.reference import compare_to_reference, read_qsm_csv
from tests.conftest import shared_file


@pytest.fixture(scope="module")
def rtwig():
    cloud = read_points(shared_file("trees", "rtwig_cloud.txt"))
    qsm = read_qsm_csv(shared_file("trees", "rtwig_QSM_simpleforest.csv"))
    return cloud, qsm, skeletonize(cloud)


def test_rtwig_qsm_reference_numbers():
    qsm = read_qsm_csv(shared_file("trees", "rtwig_QSM_simpleforest.csv"))
    assert qsm.n_nodes == 1149 + 1  # cylinder ends + one base node
    assert qsm.leaves.size == 69
    assert qsm.total_length == pytest.approx(31.43, abs=0.01)
    assert qsm.radius[qsm.roots[0]] == pytest.approx(0.0472, abs=1e-4)


def test_rtwig_agrees_with_the_simpleforest_qsm(rtwig):
    cloud, qsm, skel = rtwig
    c = compare_to_reference(skel.world_graph(), qsm, tolerance=0.05)
    assert c["f1"] >= 0.85
    # SimpleForest models short twigs our cleanup drops (tips ~40 vs 69): the skeleton has
    # 80-90 % of the QSM's length once the re-centred nodes' zig-zag is smoothed out
    # (without smoothing the zig-zag added ~18 % and the ratio was ~1.0 by compensation)
    assert 0.80 <= c["length_ratio"] <= 1.15
    assert c["base_radius"] == pytest.approx(c["base_radius_reference"], rel=0.15)
    # SimpleForest's twigs are the thickest model of this tree (10 mm at the tips; rTwig's
    # authors show uncorrected QSM twigs overestimated): the pipe-model taper (e = 2) sits
    # 0.34 below its profile and 0.16 from TreeQSM's (tests/tree/test_reference_treeqsm.py)
    assert c["radius_profile_error"] < 0.4
    assert c["tips_ratio"] >= 0.5
    assert skel.metrics["n_trees"] == 1


def test_plantscan3d_branch_agrees_with_its_mtg():
    pts = read_points(shared_file("trees", "plantscan3d_A3B4.asc"))
    mtg = read_graph(shared_file("trees", "plantscan3d_A3B4.mtg"))
    ref = mtg.with_(position=mtg.position + pts.xyz.mean(axis=0))  # README alignment
    d = np.linalg.norm(
        ref.position
        - pts.xyz[
            np.argmin(np.linalg.norm(pts.xyz[None, :50] - ref.position[:50, None], axis=2), axis=1)
        ][:1],
        axis=1,
    )
    assert np.isfinite(d).all()
    skel = skeletonize(pts)
    c = compare_to_reference(skel.world_graph(), ref, tolerance=0.05)
    assert c["f1"] >= 0.85
    assert 0.85 <= c["length_ratio"] <= 1.4
    assert skel.metrics["n_trees"] == 1
    # the MTG's 2.5-7 cm branches are over-thick (their points lie at ~3/4 of its radius
    # from its axes), which the nearest-surface residual hides and the nearest-axis one
    # shows (-4 % / -25 % measured); ours fit the points by either (+2 % / -1 %)
    from biomorph.tree.metrics import cylinder_fit

    theirs = cylinder_fit(ref, pts)["classes"]["2.5-7cm"]
    ours = cylinder_fit(skel.world_graph(), pts)["classes"]["2.5-7cm"]
    assert theirs["residual"] > -0.10 and theirs["axis_residual"] < -0.18
    assert abs(ours["residual"]) < 0.10 and abs(ours["axis_residual"]) < 0.10


@pytest.mark.parametrize("name, min_pieces", [("adtree_tree1.xyz", 9), ("adtree_tree7.xyz", 13)])
def test_gappy_adtree_clouds_are_bridged(name, min_pieces):
    cloud = read_points(shared_file("trees", name))
    skel = skeletonize(cloud, outliers=False)
    assert skel.info["components"] >= min_pieces  # README: 9 and 13 pieces at k = 10
    assert skel.metrics["n_trees"] == 1
    g = skel.graph
    top = skel.cloud.xyz[:, 2].max()
    assert g.position[:, 2].max() > 0.9 * top  # the skeleton reaches the crown top
    assert skel.graph.leaves.size > 20


def test_single_trees_in_las_and_laz():
    for name, height in (("treels_spruce.laz", 17.0), ("archi_tree2.las", 6.2)):
        cloud = read_points(shared_file("trees", name))
        skel = skeletonize(cloud)
        assert skel.metrics["n_trees"] == 1, name
        g = skel.graph
        assert np.ptp(g.position[:, 2]) == pytest.approx(height, rel=0.1), name
        r0 = skel.metrics["trunk_radius"][0]
        assert 0.02 < r0 < 0.4, name


def test_pine_plot_ground_removal_and_tree_segmentation():
    cloud = read_points(shared_file("trees", "treels_pine_plot.laz"))
    skel = skeletonize(cloud)
    assert skel.ground is not None and skel.ground.n_points > 5000
    n = skel.metrics["n_trees"]
    assert 15 <= n <= 32  # ~20 pine stems in the 10 x 10 m plot
    # understorey pieces are reported as fragments, not trees: 16 measured pine stems
    # (11.9-16.6 m since session 16's crown partition) and 8 understorey pieces
    trees = skel.metrics["trees"]
    stems = [t for t in trees if t["kind"] == "tree"]
    frags = [t for t in trees if t["kind"] == "fragment"]
    assert skel.metrics["n_stems"] == len(stems) and skel.metrics["n_fragments"] == len(frags)
    assert 12 <= len(stems) <= 20 and len(stems) + len(frags) == n
    # fragments stay in the understorey: the tallest, a sapling at (-3.9, 4.5) whose
    # sparse upper stem the crown partition adopts (session 16), reaches 3.2 m
    assert min(t["height"] for t in stems) > 5.0 and max(t["height"] for t in frags) < 4.0
    g = skel.world_graph()
    roots = g.position[g.roots]
    # stems stand apart: no two roots closer than 0.5 m
    from scipy.spatial.distance import pdist

    assert pdist(roots[:, :2]).min() > 0.5
    # the skeletons are in the original (projected) coordinates of the LAZ file
    assert np.allclose(
        np.median(roots[:, :2], axis=0), np.median(cloud.world_xyz[:, :2], axis=0), atol=3.0
    )


def test_the_voxel_method_roots_each_pine_at_its_stem():
    """The voxel skeleton of the plot joins crowns into one component; the stems found in
    the points root one tree each (before: 4 trees, one spanning several stems, a 27 m
    trunk and order 8)."""
    from scipy.spatial.distance import pdist

    skel = skeletonize(read_points(shared_file("trees", "treels_pine_plot.laz")), method="voxel")
    assert 15 <= skel.metrics["n_trees"] <= 32
    g = skel.graph
    # no chain crosses from one tree into another (a residual piece of one pine once
    # re-routed its neighbour's limb, and both trunks ran through it: 24.6 m on 15.3 m)
    c = np.flatnonzero(g.parent >= 0)
    assert np.all(g.trees[c] == g.trees[g.parent[c]])
    assert pdist(g.position[g.roots][:, :2]).min() > 0.5
    big = [t for t in skel.metrics["trees"] if t["height"] > 10]
    assert len(big) >= 10
    assert all(t["trunk_length"] < 1.4 * t["height"] and t["max_order"] <= 8 for t in big)
    # every trunk of a tree over 10 m reaches within 1 m of its top (session 27: one
    # ended at 0.47 m, a limb lying from its base had taken it) -- the edge pine at
    # (-4.5, 3.2) within 1.5 m: its sparse tops hang from straight 4-5 m edges, and in
    # canonical order (session 33) a heavier piece hanging down from 10.45 m took its
    # trunk there, 5.3 m under its top, until the trunk turned back at its highest point
    # into the child that climbs (order._turn_point): 1.25 m under the top
    z = g.position[:, 2]
    for t in np.unique(g.trees):
        m = g.trees == t
        if np.ptp(z[m]) > 10:
            gap = z[m].max() - z[m & (g.depth == 0)].max()
            xy = g.position[g.roots[g.trees[g.roots] == t][0], :2]
            edge = np.hypot(*(xy - (-4.5, 3.2))) < 0.6
            assert gap < (1.5 if edge else 1.0), (t, xy, gap)
    # two 15 m pines the graph method finds (session 15: one rooted at a shrub beside it and
    # hung from a neighbour, one lost under its neighbour's crown) stand on their own stems
    for xy in ((1.2, -4.0), (4.3, 2.5)):
        d = np.hypot(*(g.position[g.roots][:, :2] - xy).T)
        assert d.min() < 0.6, xy
        t = skel.metrics["trees"][int(g.tree_id[g.roots[np.argmin(d)]])]
        assert t["kind"] == "tree" and t["height"] > 12, (xy, t["height"])


def test_the_voxel_method_roots_the_spruce_at_its_stem_not_a_low_branch():
    """A low branch's tip is the spruce's lowest skeleton voxel; rooted there the trunk ran
    out along the branch and its stem taper put 0.53 m³ in the > 20 cm class (graph
    method 0.15 m³)."""
    skel = skeletonize(read_points(shared_file("trees", "treels_spruce.laz")), method="voxel")
    t = skel.metrics["trees"][0]
    assert skel.metrics["n_trees"] == 1
    assert t["trunk_length"] < 1.15 * t["height"]
    assert skel.metrics["classes"][">20cm"]["volume"] < 0.25


def test_the_voxel_disc_closing_inside_rings_only_models_the_spruce_whorls():
    """``--disc-enclosed``: the hollow-stem disc closing fills rings only. Applied
    everywhere it welds the whorls into sheets whose thinned arcs run through the air, and
    26 % of the wood points lie > 10 cm from every cylinder (10 % with it; the graph
    method 4 %). Bound: the issue's 12 %. Until session 30 the spruce's spacing read
    17.3 mm, a median on its 1 cm grid's √3 step, and its voxels were 52 mm (6 % far);
    without its 3,242 duplicate points and with the grid's median smoothed
    (neighbours.smooth_median) it reads 15.4 mm and its voxels are 46 mm."""
    from biomorph.tree.metrics import cylinder_fit

    cloud = read_points(shared_file("trees", "treels_spruce.laz"))
    far = {}
    for enc in (False, True):
        skel = skeletonize(cloud, method="voxel", voxel={"disc_enclosed": enc})
        assert skel.cloud is not None
        far[enc] = cylinder_fit(skel.graph, skel.cloud.xyz)["far_share"]
    assert far[True] < 0.12 < far[False] - 0.05, far


def test_the_spruce_reads_one_spacing_with_or_without_its_duplicate_points():
    """The TreeLS spruce lies on a 1 cm grid and holds 3,242 exact duplicates: its median
    nearest-neighbour distance sat on the grid's step (17.3 mm with them, 14.1 mm
    without); the smoothed median reads 15.4 mm either way."""
    from biomorph.tree.cloud import duplicate_points
    from biomorph.tree.neighbours import estimate_spacing

    xyz = read_points(shared_file("trees", "treels_spruce.laz")).xyz
    dup = duplicate_points(xyz)
    assert dup.sum() == 3242
    a, b = estimate_spacing(xyz), estimate_spacing(xyz[~dup])
    assert a == pytest.approx(b, rel=0.01) and 0.0145 < b < 0.0165


def test_a_quarter_of_the_spruce_anchors_on_its_stem_not_on_its_whorls():
    """The density table's quarter of the TreeLS spruce (`bench/tree.py --only density`:
    random draws of 100 %, 50 %, 25 % from seed 0): its skeleton's stem path circles out
    through the whorls, half its anchor's fits were needle envelopes, and the model held
    2,706 L for the full cloud's 491 (session 30). The stem followed through the points
    (tree.stem) anchors it: 468 L, DBH 22 cm (full cloud 23.9)."""
    cloud = read_points(shared_file("trees", "treels_spruce.laz"))
    rng = np.random.default_rng(0)
    for frac in (1.0, 0.5, 0.25):
        n = int(round(frac * cloud.n_points))
        keep = np.sort(rng.choice(cloud.n_points, n, replace=False))
    skel = skeletonize(cloud.select(keep))
    trees = skel.metrics["trees"]
    volume = sum(t["total_volume"] for t in trees)
    assert 0.35 < volume < 0.65  # m³; the full cloud's model 0.49
    main = max(trees, key=lambda t: t["total_volume"])
    assert 0.18 < main["dbh"] < 0.3
    # anchored on its stem, by the tracked stem where the stem path's fits are envelopes
    # (this draw's path since the points are put in canonical order, session 33, has
    # stem fits of its own that agree with the track)
    assert skel.info["taper_model"][main["tree"]]["anchor"] in (
        "stem",
        "stem (tracked)",
        "stem (fits on the track)",
    )


def test_a_quarter_of_the_spruce_whose_path_leaves_its_stem_keeps_no_envelopes():
    """Another quarter of the spruce (random draws of 50 % then 25 % from seed 101): the
    stem path's level agrees with the tracked stem's, but under half of its nodes lie on
    the stem and its fits scatter 0.39 (needle envelopes), a band that kept envelopes up to
    2x the model: 813 L. The band takes the tracked stem's scatter there: 445 L."""
    cloud = read_points(shared_file("trees", "treels_spruce.laz"))
    rng = np.random.default_rng(101)
    for frac in (0.5, 0.25):
        n = int(round(frac * cloud.n_points))
        keep = np.sort(rng.choice(cloud.n_points, n, replace=False))
    skel = skeletonize(cloud.select(keep))
    volume = sum(t["total_volume"] for t in skel.metrics["trees"])
    assert 0.35 < volume < 0.65


def test_the_same_scan_in_another_order_and_frame_gives_the_same_model():
    """AdTree tree7 is stored in millimetres. Its points listed in another order and moved
    by a georeferencing offset (the same scan exported by another tool) gave models of
    88 L (shuffled) and 95 L (moved) for the file's 111 L before the points were put in
    canonical order on their lattice (session 33); now the very same model."""
    cloud = read_points(shared_file("trees", "adtree_tree7.xyz"))
    other = cloud.select(np.random.default_rng(5).permutation(cloud.n_points))
    other = other.with_(xyz=other.xyz + (512345.678, 5401234.567, 300.0))
    a, b = skeletonize(cloud), skeletonize(other)
    np.testing.assert_array_equal(a.graph.position, b.graph.position)
    np.testing.assert_array_equal(a.graph.radius, b.graph.radius)
    np.testing.assert_array_equal(a.graph.parent, b.graph.parent)
    np.testing.assert_allclose(b.offset - a.offset, (512345.678, 5401234.567, 300.0), atol=1e-6)
    assert a.metrics["trees"][0]["total_volume"] == b.metrics["trees"][0]["total_volume"]
