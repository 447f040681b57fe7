"""Hooks at forks (tree.cleanup.fork_hooks): an arm the skeleton entered from a node up
the other arm, the path climbing the wrong arm and coming back down."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.io import read_points
from biomorph.tree.cleanup import HOOK_SAVING, fork_hooks
from biomorph.tree.pipeline import skeletonize
from tests.conftest import shared_file
from tests.tree.limb_helpers import STEP, line

SPACING = 0.01  # point spacing of the toy scans (m)


def _fork(hooked: bool) -> tuple[BranchGraph, np.ndarray]:
    """A stem to a fork at 1 m, arm A up to the right and arm B up to the left; with
    ``hooked`` arm B hangs from A's third node, its first two nodes the way back down
    (as the skeleton entered it), else from the fork. Points every centimetre along
    all three axes."""
    stem = np.vstack([[0.0, 0.0, 0.0], line([0, 0, 0], [0, 0, 1.0])])
    fork = stem[-1]
    arm_a = line(fork, [0.4, 0, 1.8])
    arm_b = line(fork, [-0.4, 0, 1.8])
    pos = [stem, arm_a]
    n_stem = stem.shape[0]
    parent = [-1, *range(n_stem - 1)]
    parent += [n_stem - 1] + list(range(n_stem, n_stem + arm_a.shape[0] - 1))
    a3 = n_stem + 2  # A's third node, 0.15 m up arm A
    if hooked:
        down = line(arm_a[2], arm_b[0], STEP)[:-1]  # the way back down to arm B
        pos.append(down)
        first = n_stem + arm_a.shape[0]
        parent += [a3] + list(range(first, first + down.shape[0] - 1))
        attach = first + down.shape[0] - 1
    else:
        attach = n_stem - 1
    pos.append(arm_b)
    start = sum(p.shape[0] for p in pos[:-1])
    parent += [attach] + list(range(start, start + arm_b.shape[0] - 1))
    xyz = np.vstack(
        [line(a, b, SPACING) for a, b in (([0, 0, 0], fork), (fork, arm_a[-1]), (fork, arm_b[-1]))]
    )
    g = BranchGraph(np.vstack(pos), np.asarray(parent), radius=np.full(sum(map(len, pos)), 0.02))
    return g, xyz


def test_an_arm_entered_from_up_the_other_hangs_from_the_fork():
    g, xyz = _fork(hooked=True)
    parent, keep, hooks = fork_hooks(g, xyz, SPACING, STEP)
    assert len(hooks) == 1
    h = hooks[0]
    fork = int(np.flatnonzero(np.isclose(g.position, [0, 0, 1.0]).all(axis=1))[0])
    # hung from the fork, or from the node next to it: within a node spacing the straight
    # ways are alike (the crotch between the arms is wood)
    assert parent[h["node"]] == h["anchor"]
    assert np.linalg.norm(g.position[h["anchor"]] - g.position[fork]) <= STEP + 1e-9
    assert h["saving"] >= HOOK_SAVING * STEP
    # the node hung from the fork is where arm B starts (the way down's last node, or B's
    # first): its points then run straight on from the fork
    assert np.linalg.norm(g.position[h["node"]] - [-0.4 / 18, 0, 1.0 + 0.8 / 18]) < STEP
    # the way back down is dropped, arm A (which carries its own wood) stays whole
    way_back = np.flatnonzero(~keep)
    assert way_back.size == h["dropped"] >= 1
    assert (g.position[way_back, 0] > 0).all() and (g.position[way_back, 2] > 1.0).all()
    sub = g.with_(parent=parent).subgraph(keep)
    assert sub.leaves.size == 2  # the two arms' tips: no stub left behind
    # the way from the root to arm B's tip is shorter by the hook's saving

    def way(par, v):
        out = 0.0
        while par[v] >= 0:
            out += float(np.linalg.norm(g.position[v] - g.position[par[v]]))
            v = par[v]
        return out

    tip_b = int(np.argmin(g.position[:, 0]))
    assert way(parent, tip_b) == pytest.approx(way(g.parent, tip_b) - h["saving"])


def test_a_fork_without_a_hook_and_a_hook_over_empty_space_are_left_alone():
    g, xyz = _fork(hooked=False)
    _, keep, hooks = fork_hooks(g, xyz, SPACING, STEP)
    assert hooks == [] and keep.all()
    # the hooked skeleton, but no point between the arms near the fork: the straight way
    # would be drawn through empty space
    g, xyz = _fork(hooked=True)
    low = xyz[:, 2] < 1.2
    bare = xyz[~low | (np.abs(xyz[:, 0]) < 1e-9)]  # the stem's points and the arms above
    parent, keep, hooks = fork_hooks(g, bare, SPACING, STEP)
    assert hooks == [] and keep.all() and (parent == g.parent).all()


def test_a_zigzag_chain_is_no_hook():
    rng = np.random.default_rng(0)
    z = np.arange(0, 2.0, STEP)
    pos = np.column_stack([rng.normal(0, 0.3 * STEP, z.size), np.zeros(z.size), z])
    g = BranchGraph(pos, np.arange(-1, z.size - 1), radius=np.full(z.size, 0.02))
    xyz = line([0, 0, 0], [0, 0, 2.0], SPACING)
    _, keep, hooks = fork_hooks(g, xyz, SPACING, STEP)
    assert hooks == [] and keep.all()


def test_a_bend_of_a_thick_branch_is_no_hook():
    """A limb bending through 180° on a 0.1 m arc: its chord saves more than two node
    spacings and lies inside its 8 cm wood, but the way never turns back."""
    ang = np.linspace(0.0, np.pi, 8)
    pos = np.column_stack([0.1 * (1 - np.cos(ang)), np.zeros(ang.size), 0.1 * np.sin(ang)])
    g = BranchGraph(pos, np.arange(-1, ang.size - 1), radius=np.full(ang.size, 0.08))
    # the limb's wood: points filling its tube around the arc
    rng = np.random.default_rng(1)
    t = rng.uniform(0, ang[-1], 20_000)
    centre = np.column_stack([0.1 * (1 - np.cos(t)), np.zeros(t.size), 0.1 * np.sin(t)])
    xyz = centre + rng.normal(0, 0.03, centre.shape)
    path = np.cumsum(np.r_[0, np.linalg.norm(np.diff(pos, axis=0), axis=1)])
    chord = np.linalg.norm(pos[-1] - pos[0])
    assert path[-1] - chord > HOOK_SAVING * STEP  # the old rule's saving alone would cut it
    _, keep, hooks = fork_hooks(g, xyz, SPACING, STEP)
    assert hooks == [] and keep.all()


def test_two_twigs_touching_at_their_tips_are_no_hook():
    """Two parallel twigs 4 cm apart whose tips touch: the skeleton runs up one, across
    and down the other. The straight way between them is within reach of their points
    (a sparse scan's spacing), but neither twig goes on beyond the turn: that is no fork,
    and straightening it would hang one twig from the other's side."""
    up = np.vstack([[0.0, 0.0, 0.0], line([0, 0, 0], [0, 0, 0.6])])
    down = line([0.04, 0, 0.6], [0.04, 0, 0.0])
    pos = np.vstack([up, down])
    g = BranchGraph(pos, np.arange(-1, pos.shape[0] - 1), radius=np.full(pos.shape[0], 0.005))
    xyz = np.vstack([line([0, 0, 0], [0, 0, 0.6], 0.02), line([0.04, 0, 0.6], [0.04, 0, 0], 0.02)])
    _, keep, hooks = fork_hooks(g, xyz, 0.02, STEP)
    assert hooks == [] and keep.all()
    # the same way with the first twig going on beyond the turn is a fork's hook
    on = np.vstack([pos, line([0, 0, 0.6], [0, 0, 1.0])])
    par = np.r_[g.parent, up.shape[0] - 1, np.arange(pos.shape[0], on.shape[0] - 1)]
    g2 = BranchGraph(on, par, radius=np.full(on.shape[0], 0.005))
    xyz2 = np.vstack([xyz, line([0, 0, 0.6], [0, 0, 1.0], 0.02)])
    _, _, hooks = fork_hooks(g2, xyz2, 0.02, STEP)
    assert len(hooks) >= 1


def test_the_pipeline_straightens_adtree_tree7s_trunk_at_its_fork():
    """AdTree tree7: the trunk ran 0.1 m up one leader above the fork and back down into
    the other (6.17 m of trunk for a 5.23 m tree, 9 cm of it downwards); straightened, 5.84 m
    and 2 cm (since the points are put in canonical order, session 33: 10 cm down without
    the hooks' rule, 4 cm with it; since the tips are followed to their ends, session 34:
    9 cm and 5 cm down, 6.10 and 5.94 m long)."""
    cloud = read_points(shared_file("trees", "adtree_tree7.xyz"))
    runs = {on: skeletonize(cloud, method="graph", fork_hooks=on) for on in (True, False)}

    def trunk(run):
        """The trunk's length and how far it steps down along its way up (m)."""
        g = run.graph
        way = np.zeros(g.n_nodes)
        for v in g.order:
            if g.parent[v] >= 0:
                way[v] = way[g.parent[v]] + g.edge_length[v]
        nodes = np.flatnonzero(g.depth == 0)
        nodes = nodes[np.argsort(way[nodes])]
        z = g.position[nodes, 2]
        return float(way[nodes[-1]]), float(-np.minimum(np.diff(z), 0).sum())

    (on_len, on_down), (off_len, off_down) = trunk(runs[True]), trunk(runs[False])
    assert off_down > 0.08 and on_down < 0.6 * off_down
    assert on_len < off_len - 0.1  # up and down the hook's 5-10 cm
    assert runs[True].info["fork_hooks"] >= 1 and "fork_hooks" not in runs[False].info
    assert runs[True].params["fork_hooks"] is True


def test_fork_hooks_reach_the_summary_from_the_cli(tmp_path, capsys):
    import json

    from biomorph.cli import run
    from tests.tree.test_cli import _write_xyz
    from tests.tree.test_livny import make_cloud

    xyz = _write_xyz(tmp_path / "tree.xyz", make_cloud(n=4000, seed=21))
    args = ["tree", "skeletonize", str(xyz), "--no-ground", "--json"]
    assert run([*args, "--fork-hooks", "--out", str(tmp_path / "on")]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["params"]["fork_hooks"] is True and "fork_hooks" in summary["info"]
    assert run([*args, "--out", str(tmp_path / "off")]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["params"]["fork_hooks"] is False and "fork_hooks" not in summary["info"]
