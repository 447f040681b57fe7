"""TreeQSM-style tables (tree.qsm): column order, ids, units, round trip (issue 13)."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.tree.export import write_qsm_tables
from biomorph.tree.metrics import volume
from biomorph.tree.order import segments, with_order
from biomorph.tree.qsm import (
    BRANCH_COLUMNS,
    CYLINDER_COLUMNS,
    TREEDATA_COLUMNS,
    branch_table,
    cylinder_table,
    treedata_table,
)
from biomorph.tree.reference import read_qsm_csv


def _tree():
    """4 m stem (r 0.1 → 0.06) with a horizontal 1 m branch (r 0.01) leaving at 2 m."""
    z = np.linspace(0, 4, 9)
    pos = np.vstack(
        [
            np.column_stack([np.zeros(9), np.zeros(9), z]),
            np.column_stack([np.linspace(0.25, 1.0, 4), np.zeros(4), np.full(4, 2.0)]),
        ]
    )
    parent = np.concatenate([[-1], np.arange(8), [4, 9, 10, 11]])
    radius = np.concatenate([np.linspace(0.1, 0.06, 9), np.full(4, 0.01)])
    return with_order(BranchGraph(pos, parent, radius=radius))


def test_treeqsm_column_order():
    # TreeQSM's cylinder text export: radius, length, start, axis, parent, extension,
    # branch, BranchOrder, PositionInBranch, added, then mad, SurfCov, UnmodRadius
    assert CYLINDER_COLUMNS[:14] == (
        "radius",
        "length",
        "start_x",
        "start_y",
        "start_z",
        "axis_x",
        "axis_y",
        "axis_z",
        "parent",
        "extension",
        "branch",
        "BranchOrder",
        "PositionInBranch",
        "added",
    )
    assert BRANCH_COLUMNS[:10] == (
        "order",
        "parent",
        "diameter",
        "volume",
        "area",
        "length",
        "angle",
        "height",
        "azimuth",
        "zenith",
    )
    assert TREEDATA_COLUMNS[:3] == ("TotalVolume", "TrunkVolume", "BranchVolume")


def test_tables_describe_the_tree():
    g = _tree()
    seg = segments(g)
    quality = {
        "reliable": np.r_[np.ones(9, bool), np.zeros(4, bool)],
        "mad": np.full(13, 0.002),
        "coverage": np.full(13, 0.75),
        "fitted_radius": np.full(13, 0.05),
    }
    cyl = cylinder_table(g, seg, quality)
    assert cyl["ID"].tolist() == list(range(1, 13))
    assert cyl["parent"][0] == 0 and cyl["BranchOrder"].max() == 1
    # the branch's cylinders are "added" (radius from the model), the stem's measured
    stem = cyl["BranchOrder"] == 0
    assert cyl["added"][~stem].all() and not cyl["added"][stem].any()
    assert np.allclose(cyl["SurfCov"], 0.75) and np.allclose(cyl["UnmodRadius"], 0.05)
    br = branch_table(g, cyl)
    assert br["order"].tolist() == [0, 1] and br["parent"].tolist() == [0, 1]
    assert br["length"] == pytest.approx([4.0, 1.0])
    assert br["angle"][1] == pytest.approx(90.0) and br["zenith"][1] == pytest.approx(90.0)
    assert br["height"][1] == pytest.approx(2.0)
    assert br["volume"].sum() == pytest.approx(1000 * volume(g))  # litres
    assert br["volume"][1] == pytest.approx(1000 * np.pi * 0.01**2 * 1.0)
    td = treedata_table(g, cyl)
    assert td["TotalVolume"][0] == pytest.approx(1000 * volume(g))
    assert td["TrunkLength"][0] == pytest.approx(4.0)
    assert td["NumberBranches"][0] == 1 and td["MaxBranchOrder"][0] == 1
    assert td["DBHqsm"][0] == pytest.approx(2 * (0.1 - 0.04 * 1.3 / 4))
    # TreeQSM's DBHcyl, right after DBHqsm: the stem circles' DBH, empty without one
    assert TREEDATA_COLUMNS.index("DBHcyl") == TREEDATA_COLUMNS.index("DBHqsm") + 1
    assert np.isnan(td["DBHcyl"][0])
    assert treedata_table(g, cyl, dbh_fit={0: 0.19})["DBHcyl"][0] == 0.19
    # a 4 m tree: a measured stem with its fits, a fragment without (no fit quality: height)
    assert td["MeasuredStem"][0] == 1
    none = {"reliable": np.zeros(g.n_nodes, dtype=bool)}
    assert treedata_table(g, cyl, none)["MeasuredStem"][0] == 0
    every = {"reliable": np.ones(g.n_nodes, dtype=bool)}
    assert treedata_table(g, cyl, every)["MeasuredStem"][0] == 1
    # the tree's location: the base of its trunk, in the graph's frame
    moved = g.with_(position=g.position + [500.0, 800.0, 20.0])
    td2 = treedata_table(moved, cylinder_table(moved))
    assert [td2[f"location_{c}"][0] for c in "xyz"] == pytest.approx([500.0, 800.0, 20.0])


def test_written_tables_read_back(tmp_path):
    g = _tree()
    files = write_qsm_tables(tmp_path, g, segments(g), None)
    header = files["csv"].read_text().splitlines()[0].split(",")
    assert tuple(header) == CYLINDER_COLUMNS
    back = read_qsm_csv(files["csv"])
    assert back.total_length == pytest.approx(g.total_length, rel=1e-5)
    rows = files["branches"].read_text().splitlines()
    assert rows[0].split(",") == list(BRANCH_COLUMNS) and len(rows) == 3
    assert files["treedata"].read_text().splitlines()[0].split(",") == list(TREEDATA_COLUMNS)
