"""Limbs the skeleton hung the wrong way round (tree.limbs.reversed_limbs, the pipeline's
limbs phase): turned round where their thick base ends against the stem and they hang from
a thin branch; left alone where the skeleton is consistent, where the chain runs inside
the stem or where the fits scatter like an envelope."""

from __future__ import annotations

import numpy as np

from biomorph.core.graph import BranchGraph
from biomorph.tree.limbs import reversed_limbs
from tests.tree.limb_helpers import STEP, measured_fit, noisy_scan
from tests.tree.limb_helpers import line as _line

R_STEM, R_LIMB, R_TWIG = 0.10, 0.05, 0.01


def _stem() -> tuple[list, list, list, list]:
    """A 5 m stem of radius :data:`R_STEM`, measured so: positions, parents, model radii
    and fits, as lists to extend."""
    stem = np.vstack([[0, 0, 0], _line((0, 0, 0), (0, 0, 5))])
    n = len(stem)
    return [*stem], list(range(-1, n - 1)), [R_STEM] * n, [R_STEM] * n


def _tree(reversed_: bool = True):
    """A 5 m stem, a thin branch from 3.5 m out to (1.4, 0, 3.6), and a 1.8 m limb whose
    true base is on the stem at 1.5 m. ``reversed_``: the limb hangs from the thin
    branch's end, running down to its base, which ends against the stem (the model gives it
    the thin branch's radius); else it hangs from the stem at its base."""
    pos, parent, radius, fits = _stem()
    stem = np.asarray(pos)
    i35 = int(round(3.5 / STEP))
    thin = _line(stem[i35], (1.4, 0, 3.6))
    k0 = len(pos)
    for k, p in enumerate(thin):
        pos.append(p)
        parent.append(i35 if k == 0 else k0 + k - 1)
        radius.append(R_TWIG)
        fits.append(R_TWIG)
    thin_end = len(pos) - 1
    base = np.array([R_STEM + 0.02, 0.0, 1.5])
    top = np.array([1.35, 0.0, 3.5])
    limb = _line(base, top)
    limb = np.vstack([base, limb])
    k0 = len(pos)
    i15 = int(round(1.5 / STEP))
    for k, p in enumerate(limb):
        pos.append(p)
        if reversed_:  # top hangs from the thin branch's end, each node from the one above
            parent.append(thin_end if k == len(limb) - 1 else k0 + k + 1)
            radius.append(0.003)
        else:
            parent.append(i15 if k == 0 else k0 + k - 1)
            radius.append(R_LIMB)
        fits.append(R_LIMB)
    graph = BranchGraph(np.array(pos), np.array(parent), radius=np.array(radius))
    return graph, np.array(fits), k0, len(limb), i15


def test_a_limb_hung_the_wrong_way_round_is_turned_onto_the_stem():
    g, fits, k0, nl, i15 = _tree()
    parent, moves = reversed_limbs(g, measured_fit(fits))
    assert len(moves) == 1
    move = moves[0]
    assert move["tip"] == k0  # the limb's base, a tip against the stem
    assert abs(move["host"] - i15) <= 2  # hung from the stem where its base is
    assert abs(move["radius"] - R_LIMB) < 1e-9
    new = g.with_(parent=parent)
    assert new.roots.tolist() == [0]  # a valid tree: no cycle
    limb = np.arange(k0, k0 + nl)
    # the limb runs from its base up: each node's parent is the node below it
    assert np.all(parent[limb[1:]] == limb[:-1])
    # its top no longer hangs from the thin branch, whose nodes keep their parents
    assert not np.any(np.isin(parent[limb], np.flatnonzero(g.radius == R_TWIG)))
    thin = np.flatnonzero(g.radius == R_TWIG)
    assert np.array_equal(parent[thin], g.parent[thin])
    assert move["length"] > 1.5


def test_a_consistent_skeleton_is_left_alone():
    g, fits, *_ = _tree(reversed_=False)
    parent, moves = reversed_limbs(g, measured_fit(fits))
    assert moves == []
    assert np.array_equal(parent, g.parent)


def test_scattered_fits_are_an_envelope_not_a_limb():
    g, fits, k0, nl, _ = _tree()
    rng = np.random.default_rng(0)
    scatter = np.ones(g.n_nodes)
    scatter[k0 : k0 + nl] = np.exp(rng.normal(0.0, 0.5, nl))  # needle-envelope scatter
    _, moves = reversed_limbs(g, measured_fit(fits, scatter))
    assert moves == []


def test_a_chain_inside_the_stem_is_not_a_limb():
    """A tip chain hung from the stem at 3.5 m and running down inside it, its circles the
    stem's: not turned."""
    pos, parent, radius, fits = _stem()
    i35 = int(round(3.5 / STEP))
    inner = _line((0.03, 0, 3.45), (0.03, 0, 1.0))  # hangs from 3.5 m, runs down inside
    for k, p in enumerate(inner):
        pos.append(p)
        parent.append(i35 if k == 0 else len(pos) - 2)
        radius.append(0.003)
        fits.append(R_STEM)
    g = BranchGraph(np.array(pos), np.array(parent), radius=np.array(radius))
    parent_new, moves = reversed_limbs(g, measured_fit(np.array(fits)))
    assert moves == []
    assert np.array_equal(parent_new, g.parent)


def test_the_pipeline_turns_the_noisy_maples_reversed_limb():
    """The synthetic maple (seed 0, 120,000 points, 8 mm noise, occlusion, leaves): the
    skeleton enters its 67 mm limb at 2.6 m from a branch above and runs it down to its
    base (17 m of path to a point 0.3 m up the limb, 2.9 m in the truth). Turned round,
    the limb hangs from the stem at its base and its radius follows its circle fits."""
    from biomorph.core import treeops
    from biomorph.tree import skeletonize

    truth, cloud = noisy_scan("maple", 0, 120_000)
    limb = 185  # the truth node at the limb's base; a point 0.3 m up it:
    x = limb
    for _ in range(3):
        x = int(np.flatnonzero(truth.parent == x)[0])
    up = truth.position[x]
    true_path = treeops.accumulate_down(truth.parent, truth.edge_length)[x]
    found = {}
    for on in (True, False):
        sk = skeletonize(cloud, method="graph", reversed_limbs=on)
        g = sk.world_graph()
        i = int(np.argmin(np.linalg.norm(g.position - up, axis=1)))
        assert np.linalg.norm(g.position[i] - up) < 0.03
        path = treeops.accumulate_down(g.parent, g.edge_length)[i]
        found[on] = (sk, path, g.radius[i])
    on, off = found[True], found[False]
    assert on[0].params["reversed_limbs"] is True and off[0].params["reversed_limbs"] is False
    assert on[0].info["reversed_limbs"] >= 1 and "reversed_limbs" not in off[0].info
    assert off[1] > 3 * true_path  # hung the wrong way round
    assert on[1] < 1.2 * true_path  # from the stem at its base
    assert on[2] > 3 * off[2]  # its radius no longer a twig's: its own circle fits'
    r_true = truth.radius[x]
    assert abs(on[2] / r_true - 1) < 0.2, (on[2], r_true)
    # the trunk stays (the radius passes after the limb's turn, and the side pieces inside
    # the stem's wood pruned from either skeleton, move its nodes by millimetres: 10 mm
    # over its 11.7 m since the points are put in canonical order, session 33)
    t_on, t_off = (s[0].metrics["trees"][0]["trunk_length"] for s in (on, off))
    assert abs(t_on - t_off) < 0.02


def test_no_reversed_limbs_reaches_the_summary(tmp_path, capsys):
    import json

    from biomorph.cli import run
    from tests.tree.test_cli import _write_xyz
    from tests.tree.test_livny import make_cloud

    xyz = _write_xyz(tmp_path / "tree.xyz", make_cloud(n=4000, seed=21))
    args = ["tree", "skeletonize", str(xyz), "--no-ground", "--json"]
    assert run([*args, "--no-reversed-limbs", "--out", str(tmp_path / "off")]) == 0
    assert json.loads(capsys.readouterr().out)["params"]["reversed_limbs"] is False
    assert run([*args, "--out", str(tmp_path / "on")]) == 0
    assert json.loads(capsys.readouterr().out)["params"]["reversed_limbs"] is True
    # on by default for the voxel method too (session 27), off when asked
    assert run([*args, "--method", "voxel", "--out", str(tmp_path / "vox")]) == 0
    assert json.loads(capsys.readouterr().out)["params"]["reversed_limbs"] is True
    vox_off = [*args, "--method", "voxel", "--no-reversed-limbs", "--out", str(tmp_path / "v2")]
    assert run(vox_off) == 0
    assert json.loads(capsys.readouterr().out)["params"]["reversed_limbs"] is False


def test_a_turned_limbs_radii_are_its_own_fits():
    """``taper_radii(trusted=…)``: the trusted nodes take their reliable fits, the ones
    between them (here one without a fit) the nearest such fit along the limb, whatever
    the taper model says about the length they carry."""
    import dataclasses

    from biomorph.tree.radius import taper_radii

    g, fits, k0, nl, _ = _tree(reversed_=False)
    fit = measured_fit(fits)
    gap = k0 + nl // 2
    fit = dataclasses.replace(fit, coverage=np.where(np.arange(g.n_nodes) == gap, 0.0, 1.0))
    limb = np.zeros(g.n_nodes, bool)
    limb[k0 : k0 + nl] = True
    r_model, _ = taper_radii(g, fit)
    r_own, f_own = taper_radii(g, fit, trusted=limb)
    assert np.allclose(r_own[limb], R_LIMB)  # the fits, and the gap filled from them
    assert f_own.reliable[limb].sum() == nl - 1  # all reported kept, bar the gap
    assert np.array_equal(r_own[~limb], r_model[~limb])  # nothing else moves
