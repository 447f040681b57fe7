"""Branch order by weight share and angle (seed 001 §5.2), segmentation by order."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree import order


def _tree():
    """Stem 0-1-2-3 (z up), lateral branch at node 1 (60° off, short), fork at 3 into a
    continuation 4 (10°, long) and a second lateral 6."""
    pos = np.array([[0, 0, 0], [0, 0, 1.0], [0, 0, 2], [0, 0, 3],
                    [0.2, 0, 4.0], [0.4, 0, 5.0],                  # continuation (long)
                    [0.9, 0, 3.5],                                 # lateral at the fork
                    [0.87, 0, 1.5], [1.7, 0, 2.0]])                # lateral on the stem
    parent = np.array([-1, 0, 1, 2, 3, 4, 3, 1, 7])
    return BranchGraph(pos, parent)


def test_orders_follow_the_weight_and_angle_rule():
    g = _tree()
    d = order.branch_order(g)
    assert d.tolist() == [0, 0, 0, 0, 0, 0, 1, 1, 1]


def test_thresholds_are_parameters():
    g = _tree()
    # with a 5° angle limit nothing continues at the forks: every fork child is new
    d = order.branch_order(g, max_angle=np.radians(5))
    assert d[4] == 1 and d[6] == 1
    # weight share of 0.95: no child carries 95 % at the forks, so orders step up
    d2 = order.branch_order(g, weight_share=0.95)
    assert d2[4] == d2[3] + 1 and d2[2] == 1
    with pytest.raises(ParameterError):
        order.branch_order(g, weight_share=1.5)
    with pytest.raises(ParameterError):
        order.branch_order(g, max_angle=0)


def test_segments_are_branches_of_constant_order():
    g = _tree()
    seg = order.segments(g)
    d = order.branch_order(g)
    assert np.unique(seg).size == 3
    for s in np.unique(seg):
        assert np.unique(d[seg == s]).size == 1
    assert seg[0] == 0 and (seg[:6] == 0).all()


def test_second_order_branches():
    g = _tree()
    pos = np.vstack([g.position, [[1.3, 0.5, 2.0]]])                 # a twig off the lateral
    parent = np.concatenate([g.parent, [7]])
    g2 = BranchGraph(pos, parent)
    d = order.with_order(g2).depth
    assert d.max() == 2 or d[-1] >= 1
    assert d[0] == 0
