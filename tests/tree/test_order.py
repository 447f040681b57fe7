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
    pos = np.array(
        [
            [0, 0, 0],
            [0, 0, 1.0],
            [0, 0, 2],
            [0, 0, 3],
            [0.2, 0, 4.0],
            [0.4, 0, 5.0],  # continuation (long)
            [0.9, 0, 3.5],  # lateral at the fork
            [0.87, 0, 1.5],
            [1.7, 0, 2.0],
        ]
    )  # lateral on the stem
    parent = np.array([-1, 0, 1, 2, 3, 4, 3, 1, 7])
    return BranchGraph(pos, parent)


def test_orders_follow_the_weight_and_angle_rule():
    g = _tree()
    d = order.branch_order(g)
    assert d.tolist() == [0, 0, 0, 0, 0, 0, 1, 1, 1]


def test_thresholds_are_parameters_of_the_angle_rule():
    g = _tree()
    # with a 5° angle limit nothing continues at the forks: every fork child is new
    d = order.branch_order(g, max_angle=np.radians(5), rule="angle")
    assert d[4] == 1 and d[6] == 1
    # weight share of 0.95: no child carries 95 % at the forks, so orders step up
    d2 = order.branch_order(g, weight_share=0.95, rule="angle")
    assert d2[4] == d2[3] + 1 and d2[2] == 1
    with pytest.raises(ParameterError):
        order.branch_order(g, weight_share=1.5, rule="angle")
    with pytest.raises(ParameterError):
        order.branch_order(g, max_angle=0, rule="angle")
    with pytest.raises(ParameterError):
        order.branch_order(g, rule="tallest")
    with pytest.raises(ParameterError):
        order.branch_order(g, tie=0)
    # the supported rule ignores the angle: the same trunk at any limit
    assert order.branch_order(g, max_angle=np.radians(5)).tolist() == order.branch_order(g).tolist()


def _bent_stem(n_whorls=6):
    """A leaning stem that bends 60° at z = 2 m (a hard 45° cut loses it), with a short
    side branch at every stem node above the bend (a whorl of one)."""
    pos = [[0, 0, 0], [0, 0, 1.0], [0, 0, 2.0]]
    parent = [-1, 0, 1]
    d = np.array([np.sin(np.radians(60)), 0, np.cos(np.radians(60))])
    for i in range(n_whorls):
        pos.append(list(np.array(pos[2]) + (i + 1) * 0.5 * d))
        parent.append(2 if i == 0 else len(pos) - 3)
        stem_node = len(pos) - 1
        pos.append(list(np.array(pos[stem_node]) + [0, 0.3, 0.0]))  # 0.3 m side twig
        parent.append(stem_node)
    pos.append(list(np.array(pos[-2]) + 0.5 * d))  # the leader's tip
    parent.append(len(pos) - 3)
    pos.append([0, 0.3, 2.0])  # a twig at the bend
    parent.append(2)
    return BranchGraph(np.array(pos, dtype=float), np.array(parent))


def test_the_trunk_follows_the_most_wood_however_it_bends():
    g = _bent_stem()
    stem = [0, 1, 2] + list(range(3, g.n_nodes - 2, 2)) + [g.n_nodes - 2]
    d = order.branch_order(g)
    assert (d[stem] == 0).all() and (np.delete(d, stem) == 1).all()
    # the seed's rule loses the stem at the bend (orders climb along it)
    assert order.branch_order(g, rule="angle").max() > 1


def test_a_codominant_fork_continues_into_the_straighter_child():
    # fork at node 1: a child 30° off carrying 1.0 m, one 5° off carrying 0.8 m (tie 0.5)
    a30, a5 = np.radians(30), np.radians(5)
    pos = np.array(
        [
            [0, 0, 0],
            [0, 0, 1.0],
            [np.sin(a30), 0, 1 + np.cos(a30)],
            [-0.8 * np.sin(a5), 0, 1 + 0.8 * np.cos(a5)],
        ]
    )
    g = BranchGraph(pos, np.array([-1, 0, 1, 1]))
    assert order.branch_order(g).tolist() == [0, 0, 1, 0]
    # with a strict tie share the heavier one wins
    assert order.branch_order(g, tie=0.9).tolist() == [0, 0, 0, 1]


def test_order_and_continuation_from_segments_round_trip():
    g = _tree()
    seg = order.segments(g)
    assert order.order_from_segments(g, seg).tolist() == order.branch_order(g).tolist()
    assert order.continuation_from_segments(g, seg).tolist() == order.continuation(g).tolist()


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
    pos = np.vstack([g.position, [[1.3, 0.5, 2.0]]])  # a twig off the lateral
    parent = np.concatenate([g.parent, [7]])
    g2 = BranchGraph(pos, parent)
    d = order.with_order(g2).depth
    assert d.max() == 2 or d[-1] >= 1
    assert d[0] == 0


def _stem_into_limb():
    """A vertical 3 m stem (0.1 m edges) whose heaviest child bends over into a 1.5 m
    horizontal limb (with side twigs, so it carries the most wood), while a thin 0.3 m
    twig continues upwards: a decurrent crown's top, as on rTwig's coffee tree."""
    pos = [[0.0, 0.0, 0.1 * i] for i in range(31)]
    parent = [-1] + list(range(30))
    top = 30
    for i in range(1, 16):  # the limb, 85° off the vertical
        pos.append([0.1 * i * np.sin(np.radians(85)), 0, 3 + 0.1 * i * np.cos(np.radians(85))])
        parent.append(top if i == 1 else len(pos) - 2 - (1 if i > 2 else 0))
        if i > 1:  # a 0.2 m side twig at every limb node
            pos.append([pos[-1][0], 0.2, pos[-1][2]])
            parent.append(len(pos) - 2)
    for i in range(1, 4):  # the thin leader
        pos.append([0, 0, 3 + 0.1 * i])
        parent.append(top if i == 1 else len(pos) - 2)
    return BranchGraph(np.array(pos), np.array(parent))


def test_the_trunk_ends_where_the_stem_bends_over_into_a_limb():
    g = _stem_into_limb()
    d = order.branch_order(g)
    assert (d[:31] == 0).all() and (d[31:] >= 1).all()  # the limb and the twig are branches
    # without the axis rule the trunk follows the most wood along the limb
    d_free = order.branch_order(g, trunk_angle=None)
    assert d_free[31] == 0 and d_free[32] == 0
    with pytest.raises(ParameterError):
        order.branch_order(g, trunk_angle=0.0)


def test_a_short_skeleton_detour_does_not_end_the_trunk():
    """At 4 m the skeleton's stem steps 0.3 m sideways and back (a kink at a whorl) with a
    lighter side branch there; the trunk stays on the stem up to the top at 8 m."""
    pos = [[0.0, 0.0, 0.1 * i] for i in range(41)]
    parent = [-1] + list(range(40))
    for dx in (0.1, 0.2, 0.3, 0.3, 0.2, 0.1):  # the detour, nearly horizontal
        pos.append([dx, 0, pos[-1][2] + 0.02])
        parent.append(len(pos) - 2)
    z0 = pos[-1][2]
    for i in range(1, 40):  # and up again
        pos.append([0, 0, z0 + 0.1 * i])
        parent.append(len(pos) - 2)
    for i in range(1, 11):  # a 1 m side branch at the kink
        pos.append([0, 0.1 * i, 4.0])
        parent.append(40 if i == 1 else len(pos) - 2)
    g = BranchGraph(np.array(pos), np.array(parent))
    d = order.branch_order(g)
    assert (d[: 41 + 6 + 39] == 0).all() and (d[41 + 6 + 39 :] == 1).all()


def _whorl_fork():
    """A 6 m stem (0.1 m edges) forking at a whorl: the leader kinks 0.3 m sideways (45°
    for three edges, the skeleton routed through the whorl) and climbs to 10 m; a limb
    leaves straighter (35°) and carries about as much (3.5 m) but tops out at 8.9 m."""
    pos = [[0.0, 0.0, 0.1 * i] for i in range(61)]
    parent = [-1] + list(range(60))
    for i in range(1, 4):  # the kink
        pos.append([0.07 * i, 0, 6 + 0.07 * i])
        parent.append(60 if i == 1 else len(pos) - 2)
    z0 = pos[-1][2]
    for i in range(1, 39):  # and the leader up to the top
        pos.append([0.21, 0, z0 + 0.1 * i])
        parent.append(len(pos) - 2)
    n_leader = len(pos)
    a = np.radians(35)
    for i in range(1, 36):  # the limb
        pos.append([-0.1 * i * np.sin(a), 0, 6 + 0.1 * i * np.cos(a)])
        parent.append(60 if i == 1 else len(pos) - 2)
    return BranchGraph(np.array(pos), np.array(parent)), n_leader


def test_the_trunk_follows_the_leader_to_the_top_through_a_whorl():
    """Issue 13, pine plot: at a codominant whorl fork the trunk continues into the child
    that climbs to the top, not the one turning least over its first edges."""
    g, n_leader = _whorl_fork()
    d = order.branch_order(g)
    assert (d[:n_leader] == 0).all() and (d[n_leader:] == 1).all()
    assert metrics_top_gap(g, d) == pytest.approx(0.0)
    # without the axis rule the supported rule's angle tie-break takes the limb
    d_free = order.branch_order(g, trunk_angle=None)
    assert (d_free[n_leader:] == 0).all()


def test_of_two_arms_climbing_alike_the_trunk_takes_the_one_holding_the_top():
    """Issue 13, rTwig: a fork at 5 m whose two arms both climb within a heading's reach
    of the top (9.63 and 9.97 m) and carry about as much; the arm turning least (10°) is
    not the one reaching the tree's top (30°, then upright): the trunk runs to the top."""
    pos = [[0.0, 0.0, 0.1 * i] for i in range(51)]
    parent = [-1] + list(range(50))
    a = np.radians(10)
    for i in range(1, 48):  # arm A: straight on, leaning 10°
        pos.append([0.1 * i * np.sin(a), 0, 5 + 0.1 * i * np.cos(a)])
        parent.append(50 if i == 1 else len(pos) - 2)
    n_a = len(pos)
    b = np.radians(30)
    for i in range(1, 11):  # arm B: 30° off for 1 m ...
        pos.append([-0.1 * i * np.sin(b), 0, 5 + 0.1 * i * np.cos(b)])
        parent.append(50 if i == 1 else len(pos) - 2)
    x, z = pos[-1][0], pos[-1][2]
    for i in range(1, 42):  # ... then upright to the top
        pos.append([x, 0, z + 0.1 * i])
        parent.append(len(pos) - 2)
    g = BranchGraph(np.array(pos), np.array(parent))
    assert g.position[n_a:, 2].max() - g.position[51:n_a, 2].max() < 0.05 * 10
    d = order.branch_order(g)
    assert (d[n_a:] == 0).all() and (d[51:n_a] == 1).all()
    assert metrics_top_gap(g, d) == pytest.approx(0.0)


def test_the_trunk_reaches_a_top_held_by_a_child_heading_off_at_first():
    """The stem's skeleton leaves a whorl nearly horizontally for 1.5 m (further than a
    heading's reach) through a limb's wood and only then climbs to the top: the child holds
    the tree's top, so the trunk continues into it."""
    pos = [[0.0, 0.0, 0.1 * i] for i in range(51)]
    parent = [-1] + list(range(50))
    for i in range(1, 16):  # out along the whorl
        pos.append([0.1 * i, 0, 5 + 0.01 * i])
        parent.append(50 if i == 1 else len(pos) - 2)
    elbow = len(pos) - 1
    for i in range(1, 46):  # the limb goes on 4.5 m, drooping a little (the heavier path)
        pos.append([1.5 + 0.1 * i, 0, 5.15 - 0.01 * i])
        parent.append(elbow if i == 1 else len(pos) - 2)
    for i in range(1, 41):  # the stem climbs back up from the elbow to 9.15 m
        pos.append([1.5 - 0.03 * i, 0.0, 5.15 + 0.1 * i])
        parent.append(elbow if i == 1 else len(pos) - 2)
    for i in range(1, 8):  # a short twig at the whorl, the other child
        pos.append([0, -0.1 * i, 5.0])
        parent.append(50 if i == 1 else len(pos) - 2)
    g = BranchGraph(np.array(pos), np.array(parent))
    d = order.branch_order(g)
    climb = np.arange(elbow + 46, elbow + 86)
    assert metrics_top_gap(g, d) == pytest.approx(0.0) and (d[climb] == 0).all()
    assert (d[elbow + 1 : elbow + 46] == 1).all()  # the limb is a branch


def metrics_top_gap(g: BranchGraph, d: np.ndarray) -> float:
    """The tree's top minus the trunk's highest node (``trunk_top_gap``)."""
    return float(g.position[:, 2].max() - g.position[d == 0, 2].max())


def _overtopping_branch(drop: float):
    """A 10.2 m stem with a branch leaving at 6 m: 2 m out at 45°, then ``drop`` m down
    (across the twigs of the crown) and up again to 11 m, above the stem's top."""
    pos = [[0.0, 0.0, 0.1 * i] for i in range(103)]
    parent = [-1] + list(range(102))
    s = np.sqrt(0.5)
    for i in range(1, 21):
        pos.append([0.1 * i * s, 0, 6 + 0.1 * i * s])
        parent.append(60 if i == 1 else len(pos) - 2)
    x, z = pos[-1][0], pos[-1][2]
    k = 10
    for i in range(1, k + 1):
        pos.append([x + 0.05 * i, 0, z - drop * i / k])
        parent.append(len(pos) - 2)
    x, z = pos[-1][0], pos[-1][2]
    while pos[-1][2] < 11.0:
        pos.append([pos[-1][0] + 0.01, 0, pos[-1][2] + 0.1])
        parent.append(len(pos) - 2)
    return BranchGraph(np.array(pos), np.array(parent))


def test_the_trunk_does_not_follow_a_branch_down_and_up_to_an_overtopping_tip():
    """The demo's birch: a branch leaving the stem runs out, drops across the crown's
    twigs and climbs to a tip above the stem's top. Holding the tree's top is no reason
    to take the trunk there: the way drops 1 m (10 node spacings; a stem does not go
    down), so the trunk stays on the stem. Without the drop it takes the branch."""
    g = _overtopping_branch(drop=1.0)
    d = order.branch_order(g)
    assert (d[:103] == 0).all() and (d[103:] == 1).all()
    g = _overtopping_branch(drop=0.0)
    d = order.branch_order(g)
    assert (d[103:] == 0).all()


def test_the_trunk_ends_at_its_top_not_down_a_branch_hanging_from_it():
    """A pine's leader merged with a drooping branch (no fork between them): the chain
    climbs to 10 m, then hangs 1 m down to a twig's tip. The trunk ends at the top; the
    tail is a branch of it (order 1)."""
    pos = [[0.0, 0.0, 0.1 * i] for i in range(101)]
    for i in range(1, 16):  # over the top and 1 m down, 0.1 m apart
        pos.append([0.05 * i, 0.0, 10.0 - 1.0 * i / 15])
    g = BranchGraph(np.array(pos), np.arange(-1, len(pos) - 1))
    d = order.branch_order(g)
    assert (d[:101] == 0).all() and (d[101:] == 1).all()
    # a tail that only sags a node spacing or two stays the trunk's
    pos = [[0.0, 0.0, 0.1 * i] for i in range(101)] + [[0.05, 0.0, 9.95], [0.1, 0.0, 9.9]]
    d = order.branch_order(BranchGraph(np.array(pos), np.arange(-1, len(pos) - 1)))
    assert (d == 0).all()


def test_below_breast_height_the_trunk_takes_the_child_that_climbs_past_it():
    """At the base a 20 m limb lies along the ground (a fallen branch, a root flare the
    scan caught) and carries more than twice the wood of the 8 m stem: the trunk still
    climbs the stem. Before, it ran along the limb (a pine of the TreeLS plot, voxel
    method: a 9.3 m limb from the base took the trunk, which ended 11.3 m under the top)."""
    stem = [[0.0, 0.0, 0.1 * i] for i in range(81)]  # base, then 8 m up
    limb = [[0.1 * i, 0.0, 0.05] for i in range(1, 201)]  # 20 m along the ground
    pos = np.array(stem + limb)
    parent = np.r_[np.arange(-1, 80), 0, 81 + np.arange(199)]
    d = order.branch_order(BranchGraph(pos, parent))
    assert (d[:81] == 0).all() and (d[81:] == 1).all()
    # a limb that climbs past breast height keeps the supported rule's choice
    limb = [[0.1 * i, 0.0, 0.05 + 0.02 * i] for i in range(1, 201)]  # rises to 4 m
    d = order.branch_order(BranchGraph(np.array(stem + limb), parent))
    assert (d[81:] == 0).all() and (d[1:81] == 1).all()


def test_a_trunk_that_went_on_past_its_highest_point_turns_there():
    """``order._turn_point``: the chain's highest node, where the trunk turns into another
    child, when the way on drops more than ``drop`` below it or stays short of the tree's
    top (``short``); -1 when the chain ends at its highest node or goes on as a stem."""
    chain = list(range(6))
    h = np.array([0.0, 1.0, 2.0, 1.9, 1.8, 1.7])
    assert order._turn_point(chain, h, drop=0.5, short=1.5) == -1  # sags 0.3, reached 1.5
    assert order._turn_point(chain, h, drop=0.5, short=3.0) == 2  # the top is 1 m higher
    assert order._turn_point(chain, h - np.r_[0, 0, 0, 0, 0, 1.0], drop=0.5, short=1.5) == 2
    assert order._turn_point(chain[:3], h, drop=0.5, short=3.0) == -1  # ends at its top
