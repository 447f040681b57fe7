"""Trunk detours out along a branch and back (cleanup.trunk_shortcuts / reroute_detours,
the pipeline's detour phase): taken out of the trunk only where the stem's points cover the
straight way."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.tree.cleanup import reroute_detours, trunk_shortcuts

SPACING = 0.017


def _stem_points(r: float, z0: float, z1: float, gap: tuple[float, float] | None = None):
    zs = np.arange(z0, z1, SPACING)
    th = np.arange(0, 2 * np.pi, SPACING / r)
    z, t = np.meshgrid(zs, th, indexing="ij")
    pts = np.stack([r * np.cos(t), r * np.sin(t), z], axis=-1).reshape(-1, 3)
    if gap is not None:
        pts = pts[(pts[:, 2] < gap[0]) | (pts[:, 2] > gap[1])]
    return pts


def _detour_tree(r: float = 0.10):
    """A 10 m trunk skeleton whose path leaves the stem at 3.0 m, runs 0.5 m out along a
    branch and comes back at 3.6 m; a side branch hangs off the way back."""
    step = 0.05
    low = [(0.0, 0.0, z) for z in np.arange(0.0, 3.0 + 1e-9, step)]
    out = [(0.1 * k, 0.0, 3.0 + 0.03 * k) for k in range(1, 6)]  # out to x = 0.5
    back = [(0.5 - 0.1 * k, 0.0, 3.15 + 0.09 * k) for k in range(1, 5)]  # back to x = 0.1
    high = [(0.0, 0.0, z) for z in np.arange(3.6, 10.0 + 1e-9, step)]
    pos = np.array(low + out + back + high)
    n = len(pos)
    parent = np.arange(-1, n - 1)
    twig = np.array([[0.3, 0.2, 3.35], [0.3, 0.3, 3.4]])
    i_back = len(low) + len(out) + 1  # a node of the way back
    pos = np.vstack([pos, twig])
    parent = np.concatenate([parent, [i_back, n]])
    radius = np.full(len(pos), r)
    radius[n:] = 0.01
    return BranchGraph(pos, parent, radius=radius), len(low), len(out), len(back)


def test_a_detour_beside_a_scanned_stem_is_taken_out_of_the_trunk():
    g, nl, no, nb = _detour_tree()
    xyz = np.vstack([_stem_points(0.10, 0.0, 10.0), g.position[nl : nl + no + nb]])
    pairs = trunk_shortcuts(g, xyz, SPACING)
    assert len(pairs) == 1
    parent, keep, n = reroute_detours(g, xyz, SPACING)
    assert n == 1
    new = g.with_(parent=parent).subgraph(keep)  # a valid forest: no cycle, one root
    ids = np.flatnonzero(keep)
    assert new.roots.tolist() == [0]
    # the trunk (the heaviest path) now runs up the stem: within its radius of the axis
    carried = new.subtree_length() + new.edge_length
    indptr, idx = new.children_csr
    path = [0]
    while indptr[path[-1] + 1] > indptr[path[-1]]:
        kids = idx[indptr[path[-1]] : indptr[path[-1] + 1]]
        path.append(int(kids[np.argmax(carried[kids])]))
    trunk = new.position[path]
    path = ids[path]  # back to the ids of g
    assert np.abs(trunk[:, 0]).max() <= 0.1 + 1e-9
    assert trunk[-1, 2] == pytest.approx(10.0)
    # the way out is still a branch of the stem; the way back crossed over to the stem:
    # dropped up to the node the twig hangs from, the rest turned round into a branch of
    # the stem above (no wood lost)
    out_far = nl + no - 1
    assert out_far not in path and parent[nl + 1] == nl
    back = np.arange(nl + no, nl + no + nb - 1)  # its last node, 10 cm out, is stem again
    assert not np.isin(back, path).any()
    assert not keep[back[0]] and keep[back[1:]].all()
    assert parent[back[2]] == back[2] + 1 and parent[back[1]] == back[2]
    assert parent[-2] == g.parent[-2] and keep[-2:].all()
    # the trunk runs up the stem: 10.6 m of path became 10.1 (the way back's last node, 10 cm
    # out, is still on the stem and stays on the trunk)
    length = lambda q: float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum())  # noqa: E731
    assert length(g.position[: len(g.position) - 2]) > 10.5
    assert 10.0 <= length(trunk) < 10.15


def test_no_shortcut_through_a_gap_in_the_scan():
    g, nl, no, nb = _detour_tree()
    xyz = np.vstack(
        [_stem_points(0.10, 0.0, 10.0, gap=(2.95, 3.65)), g.position[nl : nl + no + nb]]
    )
    assert trunk_shortcuts(g, xyz, SPACING) == []
    parent, keep, n = reroute_detours(g, xyz, SPACING)
    assert n == 0 and np.array_equal(parent, g.parent) and keep.all()


def test_no_shortcut_where_the_stem_is_a_few_points_across():
    g, nl, no, nb = _detour_tree(r=0.02)  # about one point spacing: twigs, not a stem
    xyz = np.vstack([_stem_points(0.02, 0.0, 10.0), g.position[nl : nl + no + nb]])
    assert trunk_shortcuts(g, xyz, SPACING) == []


def test_the_spruce_trunk_runs_up_its_stem(tmp_path):
    from biomorph.io import read_points
    from biomorph.tree import skeletonize
    from tests.conftest import shared_file

    cloud = read_points(shared_file("trees", "treels_spruce.laz"))
    on = skeletonize(cloud, method="graph")
    off = skeletonize(cloud, method="graph", detours=False)
    assert on.params["detours"] is True and off.params["detours"] is False
    assert on.info["trunk_detours"] >= 1 and "trunk_detours" not in off.info
    t_on, t_off = on.metrics["trees"][0], off.metrics["trees"][0]
    assert t_on["trunk_length"] < t_off["trunk_length"]
    # the RANSAC seed alone moves this trunk 1.03-1.07x the height (seeds 0-3, 2 to 4
    # detours); without the detours it is 1.30x (21.7 m)
    assert t_on["height"] <= t_on["trunk_length"] < 1.1 * t_on["height"]
    assert t_on["trunk_top_gap"] < 1.0


def test_no_detours_reaches_the_summary(tmp_path, capsys):
    from biomorph.cli import run
    from tests.tree.test_cli import _write_xyz
    from tests.tree.test_livny import make_cloud

    xyz = _write_xyz(tmp_path / "tree.xyz", make_cloud(n=4000, seed=21))
    args = ["tree", "skeletonize", str(xyz), "--no-ground", "--json"]
    assert run([*args, "--no-detours", "--out", str(tmp_path / "off")]) == 0
    assert json.loads(capsys.readouterr().out)["params"]["detours"] is False


def test_the_bulk_gap_search_finds_exactly_the_stem_tests_empty_balls():
    """cleanup._slab_gaps (one query for all of a trunk node's candidate lines) flags a
    line exactly when one of _stem_support's slab balls holds no point, where that test
    answers False: a line through the scanned stem is never flagged, one through the gap
    always, and the search's shortcuts are the same with and without it."""
    from scipy.spatial import cKDTree

    from biomorph.tree import cleanup
    from biomorph.tree.cleanup import SHORTCUT_REACH, _slab_gaps, _stem_support

    xyz = _stem_points(0.10, 0.0, 4.0, gap=(1.5, 2.2))
    kd = cKDTree(xyz)
    rng = np.random.default_rng(3)
    a = np.array([0.0, 0.0, 0.2])
    ends = np.column_stack(
        [rng.uniform(-0.4, 0.4, 60), rng.uniform(-0.4, 0.4, 60), rng.uniform(0.3, 3.9, 60)]
    )
    rb = rng.uniform(0.05, 0.12, 60)

    def check(slabs):
        """Each line flagged exactly when one of its slab balls (half-thickness ``h``) is
        empty, and a flagged line fails the stem test at that thickness."""
        gaps = _slab_gaps(kd, a, ends, 0.10, rb, SPACING, slabs)
        for b, r, h, flagged in zip(ends, rb, slabs, gaps, strict=True):
            k = max(2, int(np.ceil(float(np.linalg.norm(b - a)) / (2 * h))) + 1)
            ts = np.linspace(0.0, 1.0, k)
            ball = np.hypot(0.10 + ts * (r - 0.10) + SHORTCUT_REACH * SPACING, h)
            counts = kd.query_ball_point(a + ts[:, None] * (b - a), ball, return_length=True)
            assert bool(flagged) == bool((counts == 0).any())
            if flagged:
                assert not _stem_support(kd, xyz, a, b, 0.10, r, SPACING, h)
        return gaps

    gaps = check(np.full(rb.size, SPACING))
    assert (gaps == _slab_gaps(kd, a, ends, 0.10, rb, SPACING)).all()  # the default slabs
    # up the axis through the scanned stem: not flagged; across the gap: flagged
    up = np.array([[0.0, 0.0, 1.4], [0.0, 0.0, 3.0]])
    assert _slab_gaps(kd, a, up, 0.10, np.array([0.10, 0.10]), SPACING).tolist() == [False, True]
    assert 0 < gaps.sum() < gaps.size
    # the detour search finds the same shortcuts whether or not it skips the flagged lines
    g, nl, no, nb = _detour_tree()
    pts = np.vstack([_stem_points(0.10, 0.0, 10.0), g.position[nl : nl + no + nb]])
    with_gaps = {sp: trunk_shortcuts(g, pts, SPACING, sparse=sp) for sp in (False, True)}
    orig = cleanup._slab_gaps
    try:
        cleanup._slab_gaps = lambda kd, a, b, ra, rb, sp, slab=None: np.zeros(len(b), bool)
        for sp in (False, True):
            assert trunk_shortcuts(g, pts, SPACING, sparse=sp) == with_gaps[sp]
    finally:
        cleanup._slab_gaps = orig
    # thick slabs: the same flags as the slab balls of the stem test at that thickness
    check(np.maximum(SPACING, 0.5 * np.minimum(0.10, rb)))


def test_a_sparse_stem_is_seen_in_slabs_a_share_of_its_radius_thick():
    """The stem around a detour seen from below through a crown: a few points per slab of
    a point spacing (the TreeLS spruce at 11-12.6 m), so no slab-by-slab ring. In slabs of
    half its radius (``sparse``) the ring shows; a gap in the scan stays a gap."""
    g, nl, no, nb = _detour_tree()
    stem = _stem_points(0.10, 0.0, 10.0)
    rng = np.random.default_rng(3)
    band = (stem[:, 2] > 2.5) & (stem[:, 2] < 4.1)
    thin = ~band | (rng.random(len(stem)) < 0.04)
    xyz = np.vstack([stem[thin], g.position[nl : nl + no + nb]])
    assert trunk_shortcuts(g, xyz, SPACING) == []
    assert len(trunk_shortcuts(g, xyz, SPACING, sparse=True)) == 1
    parent, keep, n = reroute_detours(g, xyz, SPACING, sparse=True)
    assert n == 1 and not keep.all()
    gap = np.vstack(
        [_stem_points(0.10, 0.0, 10.0, gap=(2.95, 3.65)), g.position[nl : nl + no + nb]]
    )
    assert trunk_shortcuts(g, gap, SPACING, sparse=True) == []
