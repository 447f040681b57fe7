"""Reference readers (QSM CSV) and agreement measures, on small built models."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.errors import FormatError
from biomorph.tree.reference import (
    compare_to_reference,
    radius_profile,
    read_qsm_csv,
    read_reference,
)

QSM = """ ID, parentID, startX, startY, startZ, endX, endY, endZ, radius, length, branchOrder
0,-1,0,0,0,0,0,1,0.10,1,0
1,0,0,0,1,0,0,2,0.08,1,0
2,1,0,0,2,0,0,3,0.06,1,0
3,1,0,0,2,1,0,2,0.03,1,1
"""


def test_read_simpleforest_style_csv(tmp_path):
    p = tmp_path / "qsm.csv"
    p.write_text(QSM)
    g = read_qsm_csv(p)
    assert g.n_nodes == 5 and g.roots.size == 1
    assert g.total_length == pytest.approx(4.0)
    assert g.leaves.size == 2
    assert g.radius[g.roots[0]] == pytest.approx(0.10)
    assert sorted(g.depth.tolist()) == [0, 0, 0, 0, 1]
    shifted = read_reference(p, shift=np.array([1.0, 2, 3]))
    assert np.allclose(shifted.position - g.position, [1, 2, 3])


@pytest.mark.parametrize(
    "text, msg",
    [
        ("", "empty"),
        (" ID, parentID, startX\n0,-1\n", "expected 3"),
        (" ID, parentID, startX, startY, startZ, radius\n0,-1,a,0,0,1\n", "non-numeric"),
        (" ID, foo\n0,1\n", "missing columns"),
    ],
)
def test_malformed_csv_raises_format_error(tmp_path, text, msg):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(FormatError, match=msg):
        read_qsm_csv(p)


def test_agreement_of_a_model_with_itself_and_a_shortened_copy(tmp_path):
    p = tmp_path / "qsm.csv"
    p.write_text(QSM)
    g = read_qsm_csv(p)
    same = compare_to_reference(g, g, tolerance=0.05)
    assert same["f1"] == pytest.approx(1.0)
    assert same["tips_ratio"] == 1.0 and same["length_ratio"] == pytest.approx(1.0)
    assert same["radius_profile_error"] == pytest.approx(0.0)
    # the wood: volume in all and per class, the trunk (the csv carries branch orders)
    assert same["volume"] == pytest.approx(same["volume_reference"]) and same["volume"] > 0
    assert same["volume_ratio"] == pytest.approx(1.0)
    assert sum(a for a, _ in same["classes"].values()) == pytest.approx(same["volume"])
    assert same["trunk_length_ratio"] == pytest.approx(1.0) and same["trunk_length"] > 0
    thin = compare_to_reference(g.with_(radius=g.radius * 0.5), g, tolerance=0.05)
    assert thin["volume_ratio"] == pytest.approx(0.25)
    # drop the lateral branch: recall falls to 3/4 of the length, precision stays 1
    keep = np.ones(g.n_nodes, bool)
    keep[3] = False
    part = g.subgraph(keep)
    c = compare_to_reference(part, g, tolerance=0.05)
    assert c["precision"] == pytest.approx(1.0)
    assert c["recall"] == pytest.approx(0.75, abs=0.03)
    assert c["length_ratio"] == pytest.approx(0.75)


def test_radius_profile_is_length_weighted():
    g = BranchGraph(
        np.array([[0, 0, 0], [0, 0, 1.0], [0, 0, 2]]),
        np.array([-1, 0, 1]),
        radius=np.array([0.2, 0.1, 0.05]),
    )
    prof = radius_profile(g, np.array([0.5, 1.5, 2.5]))
    assert np.allclose(prof, [0.1, 0.05])
