"""MTG (plantscan3d / OpenAlea FORM-A): the real skeleton, round trips, malformed files."""

from __future__ import annotations

import re

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.errors import FormatError, InputError
from biomorph.io import mtg
from tests.core.test_treeops import random_forest


def canonical(g: BranchGraph):
    """Order-independent description: sorted nodes with parent position, radius, depth."""
    rows = []
    for i in range(g.n_nodes):
        p = g.parent[i]
        rows.append(
            (
                tuple(g.position[i]),
                tuple(g.position[p]) if p >= 0 else None,
                None if g.radius is None else g.radius[i],
                None if g.depth is None else int(g.depth[i]),
            )
        )
    return sorted(rows, key=repr)


def test_plantscan3d_file_readme_figures():
    from tests.conftest import shared_file

    path = shared_file("trees", "plantscan3d_A3B4.mtg")
    # figures quoted in the shared data README: rows without radius are skipped there
    g = mtg.read_graph(path, missing_radius="skip")
    assert g.n_nodes == 589 and g.roots.size == 1 and g.leaves.size == 136
    assert g.total_length == pytest.approx(31.23, abs=0.005)
    assert g.radius.min() == pytest.approx(0.008) and g.radius.max() == pytest.approx(
        0.0265, abs=1e-4
    )


def test_plantscan3d_file_all_rows():
    from tests.conftest import shared_file

    path = shared_file("trees", "plantscan3d_A3B4.mtg")
    text = path.read_text()
    node_rows = len(re.findall(r"^\t*\^?[<+/]N", text, flags=re.M))
    g = mtg.read_graph(path)
    assert g.n_nodes == node_rows == 610
    assert g.roots.size == 1 and np.isfinite(g.radius).all()
    # '+' opens a new order, '<' continues it: no node has two children of its own order
    child = np.flatnonzero(g.parent >= 0)
    same = child[g.depth[child] == g.depth[g.parent[child]]]
    assert np.bincount(g.parent[same], minlength=g.n_nodes).max() <= 1
    assert g.depth.max() >= 3


def test_round_trip_real_file(tmp_path):
    from tests.conftest import shared_file

    g = mtg.read_graph(shared_file("trees", "plantscan3d_A3B4.mtg"))
    out = mtg.write_graph(tmp_path / "a.mtg", g)
    back = mtg.read_graph(out)
    assert canonical(back) == canonical(g)
    again = mtg.write_graph(tmp_path / "b.mtg", back)
    assert again.read_text() == out.read_text()


def test_round_trip_random_forest_without_orders(tmp_path):
    rng = np.random.default_rng(3)
    parent = random_forest(60, 3, 3)
    g = BranchGraph(rng.normal(size=(60, 3)), parent, radius=rng.uniform(0.01, 0.1, 60))
    back = mtg.read_graph(mtg.write_graph(tmp_path / "f.mtg", g))
    assert back.roots.size == 3
    strip = [(a, b, c) for a, b, c, _ in canonical(back)]
    assert strip == [(a, b, c) for a, b, c, _ in canonical(g)]
    no_r = mtg.read_graph(mtg.write_graph(tmp_path / "n.mtg", g.with_(radius=None)))
    assert no_r.radius is None and no_r.n_nodes == 60


HEAD = "CODE :\tFORM-A\n\nMTG :\nENTITY-CODE\t\t\tXX\tYY\tZZ\tradius\n"


def test_hand_written_multiscale_file(tmp_path):
    text = HEAD + (
        "/P1\t\t\t\t\t\t\n"
        "^/N1\t\t\t0\t0\t0\t0.1\n"
        "^<N2\t\t\t0\t0\t1\t0.09\n"
        "\t+N3\t\t1\t0\t1\t0.05\n"
        "\t^<N4\t\t2\t0\t1\t0.04\n"
        "\t\t+N5\t2\t1\t1\t0.02\n"
        "^<N6\t\t\t0\t0\t2\t0.08\n"
    )
    p = tmp_path / "h.mtg"
    p.write_text(text)
    g = mtg.read_graph(p)
    assert g.parent.tolist() == [-1, 0, 1, 2, 3, 1]
    assert g.depth.tolist() == [0, 0, 1, 1, 2, 0]
    assert g.total_length == pytest.approx(1 + 1 + 1 + 1 + 1)


@pytest.mark.parametrize(
    "body,line,match",
    [
        ("/P1\n^/N\t\t\t0\t0\tx\t0.1\n", 6, "ZZ holds 'x'"),
        ("/P1\n^/N\t\t\t0\t0\n", 6, "only some of XX YY ZZ"),
        ("/P1\n^/N\t\t\t0\t0\tnan\t0.1\n", 6, "only some"),
        ("/P1\n^/N\t\t\t0\t0\t0\tinf\n", 6, "radius is inf"),
        ("^<N\t\t\t0\t0\t0\t0.1\n", 5, "no entity is there yet"),
        ("/P1\n\t\t+N\t0\t0\t0\t0.1\n", 6, "refers to column 1"),
        ("/P1\n^/N\t\t\t0\t0\t0\t0.1\n^?N\t\t\t0\t0\t1\t0.1\n", 7, "malformed"),
        ("/P1\n", None, "no entity carries XX YY ZZ"),
    ],
)
def test_malformed_rows_name_the_line(tmp_path, body, line, match):
    p = tmp_path / "bad.mtg"
    p.write_text(HEAD + body)
    with pytest.raises(FormatError, match=match) as err:
        mtg.read_graph(p)
    assert err.value.line == line


@pytest.mark.parametrize(
    "text,match",
    [
        ("", "empty"),
        ("CODE : FORM-A\nno section here\n", "no 'MTG :' section"),
        ("MTG :\nsomething else\n", "ENTITY-CODE"),
        ("MTG :\nENTITY-CODE\t\tAA\tBB\n/P1\n", "XX, YY, ZZ missing"),
    ],
)
def test_malformed_structure(tmp_path, text, match):
    p = tmp_path / "bad.mtg"
    p.write_text(text)
    with pytest.raises(FormatError, match=match):
        mtg.read_graph(p)


def test_bad_option_and_empty_graph(tmp_path):
    p = tmp_path / "x.mtg"
    p.write_text(HEAD + "/P1\n^/N\t\t\t0\t0\t0\t0.1\n")
    with pytest.raises(InputError, match="missing_radius"):
        mtg.read_graph(p, missing_radius="drop")
    with pytest.raises(InputError, match="no nodes"):
        mtg.write_graph(tmp_path / "e.mtg", BranchGraph(np.zeros((0, 3)), []))
    assert not (tmp_path / "e.mtg").exists()
