"""Broken ends (tree.limbs.broken_ends, the pipeline's limbs phase): a thick, well measured
tip whose wood goes on just beyond it, reached the long way round, is joined to it; left
alone where nothing lies ahead or what lies ahead is reached as directly."""

from __future__ import annotations

import numpy as np

from biomorph.core.graph import BranchGraph
from biomorph.tree import order
from biomorph.tree.limbs import STRETCH_RADII, broken_ends
from tests.tree.limb_helpers import STEP, measured_fit, noisy_scan
from tests.tree.limb_helpers import line as _line

R_STEM = 0.08


class _Builder:
    def __init__(self):
        self.pos: list = [np.zeros(3)]
        self.parent: list = [-1]
        self.radius: list = [R_STEM]
        self.fits: list = [R_STEM]

    def chain(self, start: int, pts, r: float, fit: float, down: bool = False) -> list[int]:
        """Nodes along ``pts`` hung from ``start`` one after the other (``down``: the last
        hangs from ``start`` and each from the next, a chain entered from its far end)."""
        ids = list(range(len(self.pos), len(self.pos) + len(pts)))
        for k, p in enumerate(pts):
            self.pos.append(np.asarray(p, float))
            if down:
                self.parent.append(start if k == len(pts) - 1 else ids[k + 1])
            else:
                self.parent.append(start if k == 0 else ids[k - 1])
            self.radius.append(r)
            self.fits.append(fit)
        return ids

    def build(self):
        g = BranchGraph(np.array(self.pos), np.array(self.parent), radius=np.array(self.radius))
        return g, measured_fit(np.array(self.fits))


def _broken_stem(gap: float = 0.1, ahead: bool = True):
    """A stem measured at 80 mm up to 4.7 m, its model thin at the end (a tip); a limb
    from 2.4 m out to (2, 0, 3.5) and a twig crossing from there to the stem at 5.3 m; the
    stem from 4.7 + ``gap`` to 5.3 m hangs from 5.3 m downwards and the stem goes on from
    5.3 to 8 m. ``ahead=False``: the stem's piece above the gap lies 0.5 m to the side."""
    b = _Builder()
    low = b.chain(0, _line((0, 0, 0), (0, 0, 4.7)), R_STEM, R_STEM)
    b.radius[low[-1]] = 0.003  # the pipe model's tip
    i24 = low[int(round(2.4 / STEP)) - 1]
    limb = b.chain(i24, _line((0, 0, 2.4), (2.0, 0, 3.5)), 0.04, 0.04)
    x = 0.0 if ahead else 0.5
    cross = b.chain(limb[-1], _line((2.0, 0, 3.5), (x, 0, 5.3)), 0.01, -1.0)
    piece = b.chain(cross[-1], _line((x, 0, 4.7 + gap), (x, 0, 5.3))[:-1], 0.003, 0.075, True)
    upper = b.chain(cross[-1], _line((x, 0, 5.3), (x, 0, 8.0)), 0.03, 0.07)
    g, fit = b.build()
    return g, fit, low, limb, cross, piece, upper


def test_a_broken_stem_is_joined_across_its_gap_and_the_trunk_runs_up_it():
    g, fit, low, limb, cross, piece, upper = _broken_stem()
    d0 = order.branch_order(g)
    assert (d0[piece] > 0).all()  # before: the stem's upper part hangs off the limb
    parent, joined = broken_ends(g, fit)
    assert len(joined) == 1 and joined[0]["tip"] == low[-1]
    assert parent[piece[0]] == low[-1]  # the piece's lowest node hangs from the tip
    assert (parent[piece[1:]] == piece[:-1]).all()  # turned round, bottom up
    assert parent[cross[-1]] == piece[-1]  # the node at 5.3 m now hangs from the piece
    g2 = g.with_(parent=parent)
    d = order.branch_order(g2)
    assert (d[low] == 0).all() and (d[piece] == 0).all() and (d[upper] == 0).all()
    assert (d[limb] == 1).all()
    assert g2.path_length()[upper[-1]] < 8.2  # base to top straight up the stem
    assert joined[0]["gap"] < 0.15 and joined[0]["saving"] > STRETCH_RADII * R_STEM


def test_no_join_without_wood_ahead_or_across_too_long_a_gap():
    # the piece above lies beside the stem's line, not ahead of it
    g, fit, *_ = _broken_stem(ahead=False)
    parent, joined = broken_ends(g, fit)
    assert joined == [] and (parent == g.parent).all()
    # the gap is longer than the measured stretch (6 radii, 0.48 m)
    g, fit, *_ = _broken_stem(gap=0.6)
    assert broken_ends(g, fit)[1] == []


def test_no_join_where_the_wood_ahead_is_reached_as_directly():
    """A consistent skeleton: the stem in one piece up to 8 m, a thick limb tip (measured)
    with its own twig ahead of it hanging from it: nothing to join."""
    b = _Builder()
    stem = b.chain(0, _line((0, 0, 0), (0, 0, 8.0)), R_STEM, R_STEM)
    i3 = stem[int(round(3.0 / STEP)) - 1]
    limb = b.chain(i3, _line((0, 0, 3.0), (1.5, 0, 3.5)), 0.04, 0.04)
    b.radius[limb[-1]] = 0.003
    b.chain(stem[40], _line((0, 0, 2.05), (1.7, 0, 3.55)), 0.01, -1.0)  # a twig from 2 m
    g, fit = b.build()
    parent, joined = broken_ends(g, fit)
    assert joined == [] and (parent == g.parent).all()


def test_the_pipeline_joins_a_stem_broken_by_occlusion():
    """Issue 13, synthetic maple (seed 3) at 240,000 points, 8 mm noise and occlusion: the
    stem's skeleton breaks at 4.7 m and its upper part was reached through a limb (the
    trunk ran 14 m out and back, its > 20 cm class 85 %); joined, the trunk stays on the
    true stem axis."""
    from scipy.spatial import cKDTree

    from biomorph.tree.pipeline import skeletonize

    truth, cloud = noisy_scan("maple", 3, 240_000)
    skel = skeletonize(cloud, method="graph")
    assert skel.info["broken_ends"] >= 1
    g = skel.world_graph()
    sn = np.flatnonzero((truth.depth == 0) & (truth.parent >= 0))
    a, b = truth.position[truth.parent[sn]], truth.position[sn]
    axis = cKDTree(np.concatenate([a + (b - a) * f for f in np.linspace(0, 1, 21)]))
    trunk = np.flatnonzero((g.depth == 0) & (g.position[:, 2] > 2.0) & (g.position[:, 2] < 5.5))
    assert trunk.size > 20
    assert np.quantile(axis.query(g.position[trunk])[0], 0.9) < 0.1
