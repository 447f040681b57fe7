"""The tree demo's models table: one row per model, the chosen one marked, the spread."""

from __future__ import annotations

from biomorph.tree.demo import MODELS, models_table
from biomorph.tree.synthetic import generate_tree, simulate_scan


def test_the_demo_table_lists_every_model_and_marks_the_chosen():
    truth = generate_tree("birch", seed=3)
    cloud = simulate_scan(truth, n_points=12_000, scanners=3, noise=0.004, ground=True, seed=3)
    table = models_table(cloud, truth)
    assert len(table.rows) == MODELS
    assert sum("(chosen)" in str(r[0]) for r in table.rows) == 1
    assert [float(r[1]) for r in table.rows] == [1.0, 0.85, 1.15]
    for r in table.rows:
        assert 50 <= float(str(r[3]).rstrip(" %")) <= 150  # volume against the truth
    assert "CV" in table.caption and "±" in table.caption
