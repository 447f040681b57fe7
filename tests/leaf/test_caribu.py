"""CARIBU .can writer/reader against the golden file."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import BiomorphError, FormatError
from biomorph.io.caribu import decode_label, read_can, write_can
from biomorph.leaf.shape import LeafShape
from tests.conftest import shared_file


def test_golden_file_reads_and_round_trips(tmp_path) -> None:
    path = shared_file("leaves", "caribu", "filterT.can")
    m = read_can(path)
    assert m.n_faces == 192
    assert decode_label("100000101000") == (1, 0, 101, 0)
    assert set(m.face_ids["leaf"]) == {101} and set(m.face_ids["optical"]) == {1}
    out = write_can(tmp_path / "copy.can", m)
    again = read_can(out)
    assert np.allclose(again.vertices, m.vertices)
    assert np.array_equal(again.face_ids["leaf"], m.face_ids["leaf"])
    # same line layout as the golden file (token count and label)
    gold = [ln.split() for ln in path.read_text().splitlines() if ln.strip()]
    ours = [ln.split() for ln in out.read_text().splitlines()]
    assert [len(t) for t in ours] == [len(t) for t in gold]
    assert [t[2] for t in ours] == [t[2] for t in gold]


def test_leaf_ids_survive(tmp_path) -> None:
    m = LeafShape.from_preset("wheat").mesh(triangles=15)
    m = m.with_(face_ids={"plant": np.full(15, 7), "leaf": np.full(15, 3)})
    back = read_can(write_can(tmp_path / "l.can", m, scale=100.0), scale=100.0)
    assert back.n_faces == 15 and set(back.face_ids["plant"]) == {7}
    assert back.area() == pytest.approx(m.area(), rel=1e-4)
    with pytest.raises(BiomorphError, match="plant ids"):
        write_can(tmp_path / "bad.can", m.with_(face_ids={"plant": np.full(15, 10**6)}))
    assert not (tmp_path / "bad.can").exists()


def test_malformed_file(tmp_path) -> None:
    p = tmp_path / "x.can"
    p.write_text("p 1 100000101000 3 0 0 0 1 0 0\n")
    with pytest.raises(FormatError, match=":1:"):
        read_can(p)
