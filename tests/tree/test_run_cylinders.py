"""Cylinders fitted to runs of nodes (tree.run_cylinders) where one slab is too thin (issue 13)."""

from __future__ import annotations

import dataclasses

import numpy as np

from biomorph.core.graph import BranchGraph
from biomorph.tree import radius as rd
from biomorph.tree.allometry import skeleton_distance
from biomorph.tree.run_cylinders import SEGMENT_POINTS, SegmentFit, fit_segments
from tests.tree.test_radius_taper import _fit, _tree


def _half_branch(points_per_m: int, r: float = 0.01, seed: int = 0):
    """A 1 m horizontal branch of radius ``r`` seen from +y only (a half cylinder, 1.5 mm
    noise), and its skeleton: 21 nodes 5 cm apart, sitting 0.6 r off the axis towards the
    scanner, as a contracted skeleton of a one-sided scan does."""
    rng = np.random.default_rng(seed)
    n = points_per_m
    s = rng.uniform(0.0, 1.0, n)
    th = rng.uniform(0.0, np.pi, n)  # the visible half
    pts = np.column_stack([s, r * np.cos(th), 1.0 + r * np.sin(th)])
    pts += rng.normal(0.0, 0.0015, pts.shape)
    x = np.linspace(0.0, 1.0, 21)
    pos = np.column_stack([x, np.zeros(21), np.full(21, 1.0 + 0.6 * r)])
    g = BranchGraph(pos, np.arange(-1, 20))
    return g, pts


def _segments(g, pts, estimate):
    d, near = skeleton_distance(pts, g.parent, g.position)
    bid = np.zeros(g.n_nodes, dtype=np.int64)
    radius = np.full(g.n_nodes, estimate)
    return fit_segments(g, pts, near, d, radius, bid, 0.01, rd.RELIABLE_COVERAGE)


def test_a_run_cylinder_measures_a_thin_branch_seen_from_one_side():
    """About 15 points per 10 cm of a 1 cm branch: too few for a circle in one slab; the
    runs' cylinders find the radius although the skeleton sits off the axis and the model
    estimate is twice the truth."""
    g, pts = _half_branch(150)
    seg = _segments(g, pts, 0.02)
    assert seg.ok[1:].mean() >= 0.8
    r = seg.radius[seg.ok]
    assert abs(np.median(r) - 0.01) < 0.001  # within 10 %
    assert (seg.run_points[seg.run_radius > 0] >= SEGMENT_POINTS).all()


def test_a_run_cylinder_puts_its_nodes_on_the_branch_axis():
    """The skeleton sits 6 mm off the axis towards the scanner; the feet of its nodes on
    the runs' fitted axes lie within 2 mm of the true axis (y = 0, z = 1; 1.5 mm noise)."""
    g, pts = _half_branch(150)
    seg = _segments(g, pts, 0.02)
    assert seg.centre is not None
    c = seg.centre[seg.ok]
    off = np.hypot(c[:, 1], c[:, 2] - 1.0)
    before = np.hypot(g.position[seg.ok, 1], g.position[seg.ok, 2] - 1.0)
    assert np.median(before) > 0.005 and np.median(off) < 0.002
    # the feet stay where their nodes were along the branch
    assert np.allclose(c[:, 0], g.position[seg.ok, 0], atol=0.005)


def test_a_run_with_too_few_points_is_not_used():
    g, pts = _half_branch(20)  # 4 points per run of 10 diameters: under SEGMENT_POINTS
    seg = _segments(g, pts, 0.01)
    assert not seg.ok.any()


def test_runs_not_wanted_are_not_fitted():
    g, pts = _half_branch(150)
    d, near = skeleton_distance(pts, g.parent, g.position)
    seg = fit_segments(
        g,
        pts,
        near,
        d,
        np.full(g.n_nodes, 0.02),
        np.zeros(g.n_nodes, dtype=np.int64),
        0.01,
        rd.RELIABLE_COVERAGE,
        need=np.zeros(g.n_nodes, dtype=bool),
    )
    assert not seg.ok.any() and (seg.run_radius < 0).all()


def _with_segments(g, radius, ok):
    n = g.n_nodes
    radius = np.asarray(radius, dtype=float)
    return SegmentFit(
        radius=radius,
        ok=np.asarray(ok),
        run=np.arange(n),
        run_radius=radius,
        run_points=np.full(n, 20),
        run_coverage=np.full(n, 0.5),
        run_se=0.05 * radius,
        run_tilt=np.zeros(n),
    )


def test_the_taper_model_takes_a_run_radius_where_no_circle_was_kept():
    """The side branch has no circle fit; its runs measure it at half the pipe model: the
    radii follow the runs. Runs three times above the model (a needle envelope) are not
    taken: the same one-sided test as circle fits."""
    g = _tree()
    carried = g.subtree_length() + g.edge_length
    model = 0.02 * carried**0.5
    ok = np.zeros(g.n_nodes, dtype=bool)
    ok[:40] = True  # the stem is measured
    fit = _fit(g, model, ok)
    plain, _ = rd.taper_radii(g, fit)
    thin = _with_segments(g, 0.5 * model, np.arange(g.n_nodes) >= 51)
    r, out = rd.taper_radii(g, fit, segments=thin)
    assert out.segment is not None and out.segment[51:].all() and not out.segment[:51].any()
    assert np.allclose(r[52:], 0.5 * model[52:], rtol=0.1)
    assert np.all(r[52:] < 0.7 * plain[52:])
    assert out.model[0]["segments"] == 10
    thick = _with_segments(g, 3.0 * model, np.arange(g.n_nodes) >= 51)
    r3, out3 = rd.taper_radii(g, fit, segments=thick)
    assert not out3.segment.any()
    assert np.allclose(r3, plain)
    # the circle fits' reliability is unchanged by the runs
    assert np.array_equal(out.reliable, rd.taper_radii(g, fit)[1].reliable)


def test_run_cylinders_bring_the_birch_preset_s_mid_class_towards_the_truth():
    """The birch preset at 60,000 points: its 1.25–3.5 cm branches hold too few points per
    slab for circles; with the runs' cylinders their class (2.5–7 cm diameter) comes within
    35 % of the truth's volume (the taper model alone: 1.7×), the total within 10 %."""
    from biomorph.tree.metrics import volume_by_class
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    truth = generate_tree("birch", seed=0)
    cloud = simulate_scan(
        truth, n_points=60000, seed=0, ground=True, noise=0.002, occlusion=False, scanners=4
    )
    vt = volume_by_class(truth)
    out = {}
    for on in (True, False):
        sk = skeletonize(cloud, method="graph", run_cylinders=on)
        assert sk.params["run_cylinders"] is on
        vc = volume_by_class(sk.world_graph())
        total = sum(v["volume"] for v in vc.values()) / sum(v["volume"] for v in vt.values())
        out[on] = (vc["2.5-7cm"]["volume"] / vt["2.5-7cm"]["volume"], total, sk.info)
        if on:  # the QSM table counts a run's cylinder as measured, not added
            from biomorph.tree.qsm import cylinder_table

            q = sk.quality
            assert q is not None and q["segment"].sum() > 500
            tab = cylinder_table(sk.graph, sk.segment, q)
            rows = sk.graph.order[sk.graph.parent[sk.graph.order] >= 0]
            measured = q["reliable"][rows] | q["segment"][rows]
            assert np.array_equal(tab["added"], (~measured).astype(np.int64))
    mid, total, info = out[True]
    assert abs(mid - 1) < 0.35 and abs(mid - 1) < abs(out[False][0] - 1) - 0.2
    assert abs(total - 1) < 0.1
    assert sum(t.get("segments", 0) for t in info["taper_model"].values()) > 500
    rc = info["run_cylinders"]  # the runs' change on the twigs they measured
    assert rc["nodes"] > 500 and 0 < rc["twig_nodes"] <= rc["nodes"]
    assert rc["twig_shift"] is not None and abs(rc["twig_shift"]) < 0.01
    assert "run_cylinders" not in out[False][2]
    assert "segments" not in str(out[False][2]["taper_model"])


def test_run_cylinders_are_on_for_both_methods_and_the_cli_turns_them_off(tmp_path, capsys):
    import json

    from biomorph.cli import run
    from tests.tree.test_cli import _write_xyz
    from tests.tree.test_livny import make_cloud

    src = _write_xyz(tmp_path / "y.xyz", make_cloud(n=4000, seed=21))
    args = ["tree", "skeletonize", str(src), "--json", "--no-ground"]
    assert run([*args, "--out", str(tmp_path / "on")]) == 0
    on = json.loads(capsys.readouterr().out)
    assert run([*args, "--out", str(tmp_path / "off"), "--no-run-cylinders"]) == 0
    off = json.loads(capsys.readouterr().out)
    assert on["params"]["run_cylinders"] is True and off["params"]["run_cylinders"] is False
    assert on["metrics"]["nob"] == off["metrics"]["nob"] == 3  # the same Y
    # the voxel method has them too (session 27), and turns them off the same way
    vox = [*args, "--method", "voxel"]
    assert run([*vox, "--out", str(tmp_path / "v0")]) == 0
    assert json.loads(capsys.readouterr().out)["params"]["run_cylinders"] is True
    assert run([*vox, "--out", str(tmp_path / "v1"), "--no-run-cylinders"]) == 0
    assert json.loads(capsys.readouterr().out)["params"]["run_cylinders"] is False


def test_a_run_too_thin_for_the_scan_s_noise_only_bounds_the_radius():
    """Runs under SEGMENT_NOISE_RADII times the scan's surface scatter are upper bounds: the
    taper model takes them where they are thinner than the model, never where thicker."""
    g, pts = _half_branch(150)
    d, near = skeleton_distance(pts, g.parent, g.position)
    args = (g, pts, near, d, np.full(g.n_nodes, 0.02), np.zeros(g.n_nodes, np.int64), 0.01)
    quiet = fit_segments(*args, rd.RELIABLE_COVERAGE, noise=0.001)
    loud = fit_segments(*args, rd.RELIABLE_COVERAGE, noise=0.004)  # 4 x 4 mm > 1 cm
    assert quiet.bound is not None and not quiet.bound[quiet.ok].any()
    assert loud.bound is not None and loud.bound[loud.ok].all()
    tree = _tree()
    carried = tree.subtree_length() + tree.edge_length
    model = 0.02 * carried**0.5
    ok = np.zeros(tree.n_nodes, dtype=bool)
    ok[:40] = True
    scatter = np.exp(np.random.default_rng(0).normal(0.0, 0.2, tree.n_nodes))
    fit = _fit(tree, model * scatter, ok)  # stem fits scattered as on real stems
    on_branch = np.arange(tree.n_nodes) >= 51
    for factor, taken in ((0.5, True), (1.5, False)):
        seg = _with_segments(tree, factor * model, on_branch)
        seg = dataclasses.replace(seg, bound=on_branch.copy())
        _, out = rd.taper_radii(tree, fit, segments=seg)
        assert bool(out.segment[51:].all()) is taken and not out.segment[:51].any()
        free = dataclasses.replace(seg, bound=np.zeros(tree.n_nodes, bool))
        assert rd.taper_radii(tree, fit, segments=free)[1].segment[51:].all()


def test_without_a_measure_of_the_noise_or_the_taper_model_runs_change_nothing():
    """No three reliable circles (nothing tells the scan's noise): the taper model alone.
    Without the taper model (``taper=False``) the option is inert."""
    from biomorph.tree.options import SkeletonizeOptions
    from biomorph.tree.pipeline import skeletonize
    from tests.tree.test_livny import make_cloud

    g, pts = _half_branch(150)
    g = g.with_(radius=np.full(g.n_nodes, 0.02))
    fit = _fit(g, np.full(g.n_nodes, 0.02), np.zeros(g.n_nodes, dtype=bool))
    r, out = rd.segment_radii(g, pts, fit, 0.01)
    r0, _ = rd.taper_radii(g, fit)
    assert np.allclose(r, r0) and not out.segment.any()
    cloud = make_cloud(n=3000, seed=3)
    base = SkeletonizeOptions()
    flat = dataclasses.replace(base.radius, taper=False)
    on = skeletonize(
        cloud,
        options=dataclasses.replace(base, radius=dataclasses.replace(flat, run_cylinders=True)),
    )
    off = skeletonize(cloud, options=dataclasses.replace(base, radius=flat))
    assert on.params["run_cylinders"] is True and on.params["taper"] is False
    assert np.allclose(on.graph.radius, off.graph.radius)


def test_fit_run_cylinders_measures_each_run_and_flags_what_cannot_be_measured():
    """Two runs in one call: a 2 cm cylinder seen all round (radius within 2 %, usable) and
    five points (no fit: radius -1, infinite standard error, not usable)."""
    from biomorph.tree.run_cylinders import fit_run_cylinders

    rng = np.random.default_rng(1)
    s = rng.uniform(0.0, 0.2, 40)
    th = rng.uniform(0.0, 2 * np.pi, 40)
    full = np.column_stack([s, 0.02 * np.cos(th), 0.02 * np.sin(th)])
    full += rng.normal(0.0, 0.0005, full.shape)
    few = full[:5] + [1.0, 0.0, 0.0]
    xyz = np.vstack([full, few])
    fits = fit_run_cylinders(
        xyz,
        np.array([0, 40, 45]),
        np.arange(45),
        np.array([[0.1, 0.01, 0.0], [1.1, 0.0, 0.0]]),
        np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
        np.array([0.04, 0.04]),
    )
    assert abs(fits.radius[0] - 0.02) < 0.0004 and fits.coverage[0] > 0.9
    assert fits.radius[1] == -1.0 and np.isinf(fits.se[1])
    assert fits.usable(rd.RELIABLE_COVERAGE).tolist() == [True, False]
