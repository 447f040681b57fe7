"""Residual branches (issue 13): the skeleton grows into the wood its cylinders leave out,
never through air, never along a stem's own surface, and re-routes a branch whose base
the skeleton reached by a shortcut."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree.metrics import cylinder_fit, surface_distance
from biomorph.tree.pipeline import skeletonize
from biomorph.tree.residual import residual_branches
from tests.tree.test_livny import cylinder_points, make_cloud

SPACING = 0.01  # point spacing of the clouds below (m)
NODE = 0.03  # node spacing (m)


def _stem_model(top=2.0, r=0.10, step=NODE):
    z = np.arange(0.0, top + 1e-9, step)
    pos = np.c_[np.zeros_like(z), np.zeros_like(z), z]
    parent = np.arange(-1, z.size - 1)
    return BranchGraph(pos, parent, radius=np.full(z.size, r))


def _surface(a, b, r, rng, spacing=SPACING):
    """Points on a cylinder's mantle about ``spacing`` apart."""
    length = float(np.linalg.norm(np.subtract(b, a)))
    n = max(int(2 * np.pi * r * length / spacing**2), 8)
    return cylinder_points(a, b, r, n, rng, 0.001)


def test_a_shoot_the_skeleton_missed_is_grown_and_hangs_from_the_stem():
    rng = np.random.default_rng(0)
    stem = _surface((0, 0, 0), (0, 0, 2), 0.10, rng)
    shoot = _surface((0.09, 0, 1.0), (0.6, 0, 1.25), 0.012, rng)
    xyz = np.vstack([stem, shoot])
    g = _stem_model()
    before = cylinder_fit(g, xyz)["far_share"]
    grown, info = residual_branches(g, xyz, SPACING, NODE)
    assert info["pieces"] == 1 and info["nodes_added"] >= 10
    assert grown.n_nodes == g.n_nodes + info["nodes_added"]
    new = np.arange(g.n_nodes, grown.n_nodes)
    # one new tip, the shoot's end, and the new chain hangs from a stem node near z = 1
    assert grown.leaves.size == 2
    tip = grown.position[grown.leaves[grown.leaves >= g.n_nodes][0]]
    assert tip[0] > 0.45 and abs(tip[2] - 1.2) < 0.1
    roots = new[grown.parent[new] < g.n_nodes]
    assert roots.size == 1 and abs(grown.position[grown.parent[roots[0]], 2] - 1.0) < 0.1
    # every new vertex lies on the shoot's axis (within its radius + a spacing)
    d = np.cross(grown.position[new] - [0.09, 0, 1.0], np.subtract([0.6, 0, 1.25], [0.09, 0, 1.0]))
    assert np.all(np.linalg.norm(d, axis=1) / np.hypot(0.51, 0.25) < 0.012 + 2 * SPACING)
    assert np.all(grown.trees == 0)
    # with a radius the shoot's points are explained
    r = grown.radius.copy()
    r[new] = 0.012
    assert cylinder_fit(grown.with_(radius=r), xyz)["far_share"] < before / 5


def test_a_floating_cluster_is_not_bridged_to():
    rng = np.random.default_rng(1)
    stem = _surface((0, 0, 0), (0, 0, 2), 0.10, rng)
    # a twig 40 cm from the stem with nothing between: no support for a bridge
    twig = _surface((0.5, 0, 1.0), (0.9, 0, 1.2), 0.012, rng)
    grown, info = residual_branches(_stem_model(), np.vstack([stem, twig]), SPACING, NODE)
    assert info["unexplained_points"] > 100 and info["pieces"] == 0
    assert grown.n_nodes == _stem_model().n_nodes


def test_a_stem_path_off_axis_does_not_sprout_a_surface_strip():
    """The skeleton's stem runs 10 cm off the axis: the far side's bark is "unexplained"
    but stays within about a radius of the cylinder and runs along it: no branch."""
    rng = np.random.default_rng(2)
    stem = _surface((0, 0, 0), (0, 0, 2), 0.10, rng)
    g = _stem_model()
    g = g.with_(position=g.position + [0.10, 0, 0])
    grown, info = residual_branches(g, stem, SPACING, NODE)
    assert info["unexplained_points"] > 0
    assert info["pieces"] == 0 and grown.n_nodes == g.n_nodes


def test_a_branch_reached_by_a_shortcut_is_rerouted_through_its_base():
    """The skeleton joins a branch to the stem 30 cm above where its wood leaves the stem
    (a level set's shortcut). The piece of wood below is not a new tip: the branch is
    re-routed through it and the shortcut removed."""
    rng = np.random.default_rng(3)
    stem = _surface((0, 0, 0), (0, 0, 3), 0.10, rng)
    a, b = np.array([0.09, 0, 1.0]), np.array([0.8, 0, 1.5])
    branch = _surface(a, b, 0.02, rng)
    xyz = np.vstack([stem, branch])
    g = _stem_model(top=3.0)
    # the modelled branch: from stem node z = 1.32 straight to the branch at x = 0.45, then on
    s0 = int(np.argmin(np.abs(g.position[:, 2] - 1.32)))
    t = np.linspace(0.5, 1.0, 12)
    on = a + t[:, None] * (b - a)
    short = np.linspace(g.position[s0], on[0], 6)[1:-1]
    pos = np.vstack([g.position, short, on])
    n0 = g.n_nodes
    parent = np.concatenate([g.parent, [s0, n0, n0 + 1, n0 + 2], n0 + 3 + np.arange(on.shape[0])])
    model = BranchGraph(pos, parent, radius=np.r_[g.radius, np.full(short.shape[0] + 12, 0.02)])
    assert model.leaves.size == 2
    grown, info = residual_branches(model, xyz, SPACING, NODE)
    assert info["joined"] == 1 and info["shortcut_nodes_removed"] >= 3
    assert grown.leaves.size == 2  # stem top and the branch tip: no new tip
    # the branch now leaves the stem where its wood does (z ≈ 1.0), not at 1.32
    tip = grown.leaves[np.argmax(grown.position[grown.leaves, 0])]
    path = [int(tip)]
    while grown.parent[path[-1]] >= 0:
        path.append(int(grown.parent[path[-1]]))
    on_stem = [i for i in path if np.hypot(*grown.position[i, :2]) < 1e-9]
    assert abs(grown.position[on_stem[0], 2] - 1.0) < 0.12


def test_a_piece_does_not_reroute_a_branch_of_the_neighbouring_tree():
    """Two stems 1.6 m apart; a branch whose wood leaves stem A hangs in the model from
    stem B (the crown partition gave it to B). The piece at its base, hosted on A, must not
    re-route B's branch into A: a chain would cross from one tree into the other and both
    trunks would run through it (TreeLS plot, voxel method: a 24.6 m trunk on a 15.3 m
    pine)."""
    rng = np.random.default_rng(4)
    stem_a = _surface((0, 0, 0), (0, 0, 3), 0.10, rng)
    stem_b = _surface((1.6, 0, 0), (1.6, 0, 3), 0.10, rng)
    a, b = np.array([0.09, 0, 1.0]), np.array([0.8, 0, 1.5])
    xyz = np.vstack([stem_a, stem_b, _surface(a, b, 0.02, rng)])
    ga = _stem_model(top=3.0)
    gb = ga.with_(position=ga.position + [1.6, 0, 0])
    n0 = ga.n_nodes
    s0 = n0 + int(np.argmin(np.abs(gb.position[:, 2] - 1.5)))
    t = np.linspace(0.5, 1.0, 12)
    on = a + t[:, None] * (b - a)
    short = np.linspace(gb.position[s0 - n0], on[-1], 20)[1:-1]  # from B to the branch's end
    pos = np.vstack([ga.position, gb.position, short, on[::-1]])
    m = 2 * n0
    parent = np.concatenate(
        [
            ga.parent,
            np.where(gb.parent >= 0, gb.parent + n0, -1),
            [s0],
            m + np.arange(short.shape[0] - 1),
        ]
    )
    parent = np.concatenate([parent, [m + short.shape[0] - 1], m + short.shape[0] + np.arange(11)])
    model = BranchGraph(
        pos, parent, radius=np.r_[ga.radius, gb.radius, np.full(pos.shape[0] - m, 0.02)]
    )
    assert model.roots.size == 2 and np.all(model.trees[m:] == model.trees[n0])
    grown, info = residual_branches(model, xyz, SPACING, NODE)
    assert info["joined"] == 0
    c = np.flatnonzero(grown.parent >= 0)
    assert np.all(grown.trees[c] == grown.trees[grown.parent[c]])


def test_surface_distance_looks_past_branch_bases_on_a_thick_stem():
    """At a whorl the 8 nearest axis samples can all be thin branch bases; the refined
    look finds the stem's own surface."""
    g = _stem_model()
    pos = [g.position]
    parent = [g.parent]
    n = g.n_nodes
    s0 = int(np.argmin(np.abs(g.position[:, 2] - 1.0)))
    for k in range(8):  # eight short branches leaving z = 1 in all directions
        ang = 2 * np.pi * k / 8
        d = np.array([np.cos(ang), np.sin(ang), 0.0])
        seg = np.array([d * 0.10 + [0, 0, 1.0], d * 0.14 + [0, 0, 1.0], d * 0.18 + [0, 0, 1.0]])
        pos.append(seg)
        parent.append(np.array([s0, n, n + 1]))
        n += 3
    model = BranchGraph(np.vstack(pos), np.concatenate(parent), radius=None)
    model = model.with_(radius=np.r_[g.radius, np.full(24, 0.005)])
    p = np.array([[0.0, 0.101, 1.0 + 0.06]])  # on the stem's bark between branch bases
    sd, _, _ = surface_distance(model, p, k=2)
    sd_r, rad_r, _ = surface_distance(model, p, k=2, refine=0.005)
    assert sd_r[0] == pytest.approx(0.001, abs=1e-3) and rad_r[0] == pytest.approx(0.10)
    assert sd[0] >= sd_r[0]


def test_parameters_and_pipeline_switch():
    g = _stem_model()
    with pytest.raises(ParameterError, match="radii"):
        residual_branches(g.with_(radius=None), np.zeros((5, 3)), SPACING, NODE)
    with pytest.raises(ParameterError, match="spacing"):
        residual_branches(g, np.zeros((5, 3)), 0.0, NODE)
    pts = make_cloud(n=5000, seed=7)
    on = skeletonize(pts, ground=None)
    off = skeletonize(pts, ground=None, residual=False)
    assert on.params["residual"] is True and off.params["residual"] is False
    assert "residual_pieces" in on.info and "residual_pieces" not in off.info
    # the toy Y keeps its three tips either way (no strips of the stem become branches)
    assert on.graph.leaves.size == off.graph.leaves.size == 3


def test_main_child_is_the_one_carrying_the_most_length():
    from biomorph.tree.residual import _main_child

    # 0 - 1 - 2 - 3 (long) and 1 - 4 (short); 2 has one child
    pos = np.array([[0, 0, 0], [0, 0, 1], [0, 0, 2], [0, 0, 4], [0.5, 0, 1.2]], float)
    g = BranchGraph(pos, np.array([-1, 0, 1, 2, 1]), radius=np.full(5, 0.01))
    assert _main_child(g).tolist() == [1, 2, 3, -1, -1]


def test_cli_switch(tmp_path, capsys):
    import json

    from biomorph.cli import run
    from tests.tree.test_cli import _write_xyz

    src = _write_xyz(tmp_path / "y.xyz", make_cloud(n=4000, seed=21))
    args = ["tree", "skeletonize", str(src), "--json", "--no-ground", "--out"]
    assert run([*args, str(tmp_path / "a"), "--no-residual"]) == 0
    off = json.loads(capsys.readouterr().out)
    assert run([*args, str(tmp_path / "b")]) == 0
    on = json.loads(capsys.readouterr().out)
    assert off["params"]["residual"] is False and "residual_pieces" not in off["info"]
    assert on["params"]["residual"] is True and on["info"]["residual_unexplained_points"] >= 0


def test_a_finer_threshold_grows_a_shorter_shoot(tmp_path, capsys):
    """``--residual-threshold`` scales the threshold and the shoot's reach (node
    spacings): a shoot standing 15 cm off a 10 cm stem (5 cm beyond one radius) is left
    out at 1 (it must reach 2 node spacings = 6 cm) and grown at 0.5 (3 cm)."""
    rng = np.random.default_rng(3)
    stem = _surface((0, 0, 0), (0, 0, 2), 0.10, rng)
    shoot = _surface((0.09, 0, 1.0), (0.25, 0, 1.05), 0.012, rng)
    xyz = np.vstack([stem, shoot])
    g = _stem_model()
    _, coarse = residual_branches(g, xyz, SPACING, NODE)
    _, fine = residual_branches(g, xyz, SPACING, NODE, threshold=NODE / 2, min_length=NODE / 2)
    assert coarse["pieces"] == 0 and coarse["nodes_added"] == 0
    assert fine["pieces"] == 1 and fine["nodes_added"] >= 1
    # the option reaches the pipeline from the CLI, in node spacings
    import json

    from biomorph.cli import run
    from tests.tree.test_cli import _write_xyz

    src = _write_xyz(tmp_path / "y.xyz", make_cloud(n=4000, seed=21))
    args = ["tree", "skeletonize", str(src), "--json", "--no-ground", "--out", str(tmp_path / "o")]
    assert run([*args, "--residual-threshold", "0.5"]) == 0
    out = json.loads(capsys.readouterr().out)
    ns = out["params"]["node_spacing"]
    assert out["params"]["residual_threshold"] == 0.5
    assert out["info"]["residual_threshold"] == pytest.approx(0.5 * ns)
    assert out["info"]["residual_min_length"] == pytest.approx(0.5 * ns)
    assert run([*args, "--residual-threshold", "0"]) == 2  # must be > 0
    assert "residual-threshold" in capsys.readouterr().err


def test_the_threshold_is_finer_only_where_the_twigs_present_a_surface():
    """``--residual-threshold auto`` (session 29): half a node spacing where the points
    about the twigs are a surface, never under 6 × the scan's scatter, else one."""
    from biomorph.tree.residual import RESIDUAL_FINE, RESIDUAL_NOISE, residual_factor

    assert residual_factor(False, 0.0005, 0.03) == 1.0  # an envelope: needles, leaves
    assert residual_factor(True, 0.0005, 0.03) == RESIDUAL_FINE  # a clean scan's bark
    assert residual_factor(True, 0.004, 0.03) == pytest.approx(RESIDUAL_NOISE * 0.004 / 0.03)
    assert residual_factor(True, 0.008, 0.03) == 1.0  # 8 mm of noise: no finer than 1
    assert residual_factor(True, 0.001, 0.0) == 1.0


def test_the_surface_test_pools_the_trees_by_their_points():
    from biomorph.tree.radius import twig_surface
    from tests.tree.test_twig_offset import _model, _scan

    rng = np.random.default_rng(4)
    # twig 0 scanned as bark (a surface), twig 1 inside a 4-12 mm shell (an envelope)
    bark = _scan([0.006])

    def shell(n):
        rad = rng.uniform(0.004, 0.012, n)
        a = rng.uniform(0, 2 * np.pi, n)
        return np.column_stack([rng.uniform(0, 0.5, n), 0.2 + rad * np.cos(a), rad * np.sin(a)])

    g = _model(0.004, n_twigs=2)
    free = np.zeros(g.n_nodes, bool)
    few, many = shell(bark.shape[0] // 4), shell(4 * bark.shape[0])
    surface, info = twig_surface(g, np.vstack([bark, few]), free, 0.004)
    assert surface is True and info[0]["surface"] and not info[1]["surface"]
    surface, info = twig_surface(g, np.vstack([bark, many]), free, 0.004)
    assert surface is False and info[0]["points"] < info[1]["points"]
    # no twig with enough points: no surface
    assert twig_surface(g, bark[:10], free, 0.004)[0] is False


@pytest.mark.parametrize(("name", "factor"), [("rtwig_cloud.txt", 0.5), ("adtree_tree1.xyz", 1.0)])
def test_the_pipeline_reads_the_threshold_from_the_scan(name, factor):
    # rTwig: bark twigs, a clean scan (1.3 mm scatter, 29 mm node spacing): half a node
    # spacing, the twiglets TreeQSM models grow (58 -> 80 tips; TreeQSM 82); AdTree tree1:
    # leaves about its twigs, an envelope: one node spacing, as before session 29
    from biomorph.io import read_points
    from tests.conftest import shared_file

    cloud = read_points(shared_file("trees", name))
    skel = skeletonize(cloud, method="graph")
    assert skel.params["residual_threshold"] is None  # auto
    assert skel.params["residual_factor"] == pytest.approx(factor)
    assert skel.info["residual_surface"] is (factor < 1)
    ns = skel.params["node_spacing"]
    assert skel.info["residual_threshold"] == pytest.approx(factor * ns)
    if factor < 1:
        assert skel.graph.leaves.size >= 70  # 58 at one node spacing


def test_without_circle_fits_the_threshold_stays_one_node_spacing():
    # --radius allometric: no circle fits, no twig model to test: the fixed threshold
    cloud = make_cloud(n=4000, seed=21)
    skel = skeletonize(cloud, method="graph", radius="allometric")
    assert skel.params["residual_factor"] == 1.0
    assert "residual_surface" not in skel.info
    # an explicit threshold is taken as given, the test is not run
    fixed = skeletonize(cloud, method="graph", residual_threshold=0.7)
    assert fixed.params["residual_factor"] == 0.7 and "residual_surface" not in fixed.info
