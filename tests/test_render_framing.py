"""Previews are framed to the data: each view to its own extent, stray points ignored."""

from __future__ import annotations

import numpy as np

from biomorph.render import _VIEWS, _frame


def test_each_view_frames_its_own_extent_and_ignores_strays():
    rng = np.random.default_rng(0)
    # a 20 m tall, 2 m wide "pine" of 20,000 points and five stray points 200 m away
    pine = np.c_[rng.uniform(-1, 1, 20000), rng.uniform(-1, 1, 20000), rng.uniform(0, 20, 20000)]
    xyz = np.r_[pine, np.full((5, 3), 200.0)]
    for name, rot in _VIEWS.items():
        centre, half = _frame(xyz @ rot.T)
        vertical = name != "top"
        want = 0.55 * (20.0 if vertical else 2.0)
        assert abs(half - want) < 0.05 * want, (name, half)
        assert np.all(np.abs(centre) < 11.0)


def test_small_inputs_use_the_exact_bounds():
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 3.0]])
    rot = next(iter(_VIEWS.values()))
    _, half = _frame(pts @ rot.T)
    assert half > 0


def test_graph_preview_has_a_legend_for_its_colours():
    """Branch order (one tree) or tree id (a plot) in the legend; the views carry units."""
    from biomorph.core.graph import BranchGraph
    from biomorph.render import _add_graph, _Scene

    pos = np.array([[0, 0, 0], [0, 0, 1], [0, 0, 2], [0.5, 0, 1.5]], float)
    g = BranchGraph(pos, np.array([-1, 0, 1, 1]), radius=np.full(4, 0.05), depth=[0, 0, 0, 1])
    scene = _Scene()
    _add_graph(scene, g, "z")
    assert [lab for lab, _ in scene.legend] == ["order 0", "order 1"]
    plot = BranchGraph(
        np.vstack([pos, pos + [3, 0, 0]]),
        np.array([-1, 0, 1, 1, -1, 4, 5, 5]),
        radius=np.full(8, 0.05),
    )
    scene = _Scene()
    _add_graph(scene, plot, "z")
    assert [lab for lab, _ in scene.legend] == ["tree 0", "tree 1"]
    # a plot's fragments (no tree: understorey, stumps) are one dark-grey legend entry
    scene = _Scene()
    _add_graph(scene, plot, "z", muted={1})
    assert [lab for lab, _ in scene.legend] == ["tree 0", "1 fragment"]
    _, colors, _ = scene.segments[0]
    child = np.flatnonzero(plot.parent >= 0)
    assert np.allclose(colors[plot.trees[child] == 1, :3], 0.25)
    assert not np.allclose(colors[plot.trees[child] == 0, :3], 0.25)
