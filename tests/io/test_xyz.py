"""Text point clouds: delimiters, headers, real files, exact round trips, errors with lines."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import FormatError, InputError
from biomorph.io import xyz
from tests.conftest import shared_file


def write(tmp_path, text, name="c.xyz"):
    p = tmp_path / name
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


@pytest.mark.parametrize(
    "text",
    [
        "1 2 3\n4 5 6\n",
        "1\t2\t3\n4\t5\t6\n",
        "1,2,3\n4,5,6\n",
        "1, 2, 3\r\n4 ,5,6\r\n",
        "1;2;3\n4;5;6\n",
        "1  2 \t 3\n\n\n4 5 6",
        "# comment\n1 2 3\n# more\n4 5 6\n",
        "1.0e0 2E0 +3\n4.0 .5e1 6.\n",
    ],
)
def test_delimiters_and_layouts(tmp_path, text):
    c = xyz.read_points(write(tmp_path, text))
    assert np.allclose(c.xyz, [[1, 2, 3], [4, 5, 6]])
    assert c.attributes == {}


def test_decimal_comma_with_semicolons(tmp_path):
    c = xyz.read_points(write(tmp_path, "1,5;2;3,25\n4;5,5;6\n", "c.txt"))
    assert np.allclose(c.xyz, [[1.5, 2, 3.25], [4, 5.5, 6]])


def test_header_names_columns_and_picks_xyz(tmp_path):
    c = xyz.read_points(
        write(tmp_path, "intensity,X,Y,Z,Deviation\n7,1,2,3,0.5\n8,4,5,6,0.25\n", "c.csv")
    )
    assert np.allclose(c.xyz, [[1, 2, 3], [4, 5, 6]])
    assert c.attributes["intensity"].tolist() == [7, 8]
    assert c.attributes["intensity"].dtype == np.int64
    assert np.allclose(c.attributes["Deviation"], [0.5, 0.25])
    cc = xyz.read_points(write(tmp_path, "//X,Y,Z,R\n1,2,3,9\n", "cc.txt"))
    assert cc.attributes["R"].tolist() == [9]
    commented = xyz.read_points(write(tmp_path, "# x y z scalar\n1 2 3 0.5\n", "h.xyz"))
    assert list(commented.attributes) == ["scalar"]


def test_extra_columns_without_header(tmp_path):
    c = xyz.read_points(write(tmp_path, "1 2 3 10 0.5\n4 5 6 20 0.25\n"))
    assert c.attributes["column_3"].tolist() == [10, 20]
    assert np.allclose(c.attributes["column_4"], [0.5, 0.25])


def test_pts_count_line(tmp_path):
    c = xyz.read_points(write(tmp_path, "2\n1 2 3 -5\n4 5 6 7\n", "c.pts"))
    assert c.n_points == 2 and c.attributes["column_3"].tolist() == [-5, 7]


@pytest.mark.parametrize(
    "name,count",
    [
        ("adtree_tree1.xyz", 11855),
        ("rtwig_cloud.txt", 14667),
        ("plantscan3d_A3B4.asc", 20903),
        ("adtree_tiny_for_debug.xyz", 245),
    ],
)
def test_real_files(name, count):
    path = shared_file("trees", name)
    c = xyz.read_points(path)
    assert c.n_points == count
    ref = np.array(
        [[float(t) for t in ln.split()[:3]] for ln in path.read_text().splitlines() if ln.strip()]
    )
    assert np.array_equal(c.xyz, ref)


def test_real_csv_with_spaced_header():
    c = xyz.read_points(shared_file("trees", "rtwig_QSM_simpleforest.csv"))
    assert c.n_points == 1149
    assert "radius" in c.attributes and "branchOrder" in c.attributes
    assert c.attributes["branchOrder"].max() == 4


@pytest.mark.parametrize("ext", [".xyz", ".txt", ".csv", ".asc", ".pts"])
def test_round_trip_exact(tmp_path, ext):
    rng = np.random.default_rng(1)
    c = PointCloud(
        rng.normal(size=(300, 3)) * 1000,
        {
            "intensity": rng.integers(0, 5000, 300),
            "Deviation": rng.normal(size=300),
            "f32": rng.normal(size=300).astype(np.float32),
        },
    )
    back = xyz.read_points(xyz.write_points(tmp_path / f"c{ext}", c))
    assert np.array_equal(back.xyz, c.xyz)
    assert np.array_equal(back.attributes["intensity"], c.attributes["intensity"])
    assert np.array_equal(back.attributes["Deviation"], c.attributes["Deviation"])
    assert np.array_equal(back.attributes["f32"].astype(np.float32), c.attributes["f32"])


def test_precision_option(tmp_path):
    c = PointCloud(np.array([[1.23456789, 0, 0]]))
    p = xyz.write_points(tmp_path / "p.xyz", c, precision=3)
    assert p.read_text().strip() == "1.235 0.000 0.000"


@settings(max_examples=25, deadline=None)
@given(
    arrays(
        np.float64,
        st.tuples(st.integers(1, 20), st.just(3)),
        elements=st.floats(-1e12, 1e12, allow_nan=False, allow_subnormal=False),
    )
)
def test_round_trip_property(tmp_path_factory, pts):
    p = tmp_path_factory.mktemp("x") / "r.xyz"
    back = xyz.read_points(xyz.write_points(p, PointCloud(pts)))
    assert np.array_equal(back.xyz, pts)


@pytest.mark.parametrize(
    "text,line,match",
    [
        ("", None, "empty"),
        ("   \n\n", None, "empty"),
        ("1 2 3\n4 5 6\n7 8\n", 3, "2 columns; expected 3"),
        ("1 2 3\n4 5 6 7\n", 2, "4 columns"),
        ("1 2 3\n4 five 6\n", 2, "column 2 holds 'five'"),
        ("1 2 3\n4 5 nan\n", 2, "NaN or inf"),
        ("x y z\n1 2 3\n1 inf 3\n", 3, "NaN or inf"),
        ("1 2\n3 4\n", 1, "at least 3"),
        ("a b c\n", 1, "no numeric data"),
        ("1,2,3\n4,,6\n", 2, "column 2"),
        ("x y z w\n1 2 3\n", 1, "header names 4 columns"),
    ],
)
def test_malformed_names_line(tmp_path, text, line, match):
    p = write(tmp_path, text)
    with pytest.raises(FormatError, match=match) as err:
        xyz.read_points(p)
    assert err.value.line == line
    assert str(p) in str(err.value)


def test_binary_garbage_names_line(tmp_path):
    p = write(tmp_path, b"1 2 3\n4 5 6\n\xff\xfe\x00garbage\n")
    with pytest.raises(FormatError, match="not text") as err:
        xyz.read_points(p)
    assert err.value.line == 3
    q = write(tmp_path, b"1 2 3\n4 \xff 6\n", "q.xyz")
    with pytest.raises(FormatError, match="column 2") as err:
        xyz.read_points(q)
    assert err.value.line == 2
    latin = write(tmp_path, "x;y;z;Intensit\xe4t\n1;2;3;4\n".encode("latin-1"), "l.csv")
    assert xyz.read_points(latin).attributes["Intensit\xe4t"].tolist() == [4]


def test_writer_refuses_nan_and_leaves_no_file(tmp_path):
    from biomorph.errors import InputError

    with pytest.raises(InputError):
        xyz.write_points(tmp_path / "n.xyz", PointCloud(np.array([[0, 0, np.nan]])))
    assert not (tmp_path / "n.xyz").exists()


@settings(max_examples=40, deadline=None)
@given(
    arrays(
        np.float64,
        st.tuples(st.integers(1, 30), st.just(4)),
        elements=st.floats(-1e30, 1e30, allow_nan=False, allow_subnormal=False),
    ),
    st.sampled_from(["%.3f", "%.6e", "%r", "%g", "%.15g", "%.0f", "%+.2E"]),
    st.sampled_from([" ", "\t", ",", ";"]),
)
def test_compiled_scanner_is_bit_exact(tmp_path_factory, values, fmt, sep):
    """Every token must parse to exactly float(token), whatever the format."""
    lines = [sep.join(fmt % v for v in row.tolist()) for row in values]
    text = "\n".join(lines) + "\n"
    p = tmp_path_factory.mktemp("s") / "s.txt"
    p.write_text(text)
    vals, _, meta = xyz.read_table(p)
    ref = np.array([[float(t) for t in ln.split(sep)] for ln in lines])
    assert np.array_equal(vals, ref)
    if sep != ";" or "," not in text:
        assert meta["parser"] == "compiled"


def test_compiled_scanner_special_tokens(tmp_path):
    p = write(tmp_path, "1 2 3 NaN\n4 5 6 -Infinity\n7 8 9 inf\n0 0 0 1e-400\n")
    vals, _, meta = xyz.read_table(p)
    assert meta["parser"] == "compiled"
    assert np.isnan(vals[0, 3]) and vals[1, 3] == -np.inf and vals[2, 3] == np.inf
    assert vals[3, 3] == 0.0
    mid = write(tmp_path, "1 2 3 # trailing comment\n4 5 6\n", "m.xyz")
    assert np.allclose(xyz.read_points(mid).xyz, [[1, 2, 3], [4, 5, 6]])


@settings(max_examples=30, deadline=None)
@given(
    arrays(
        np.float64,
        st.tuples(st.integers(1, 40), st.just(3)),
        elements=st.floats(-1e9, 1e9, allow_nan=False, allow_subnormal=False),
    ),
    st.integers(0, 6),
    arrays(np.int64, 40, elements=st.integers(-(2**40), 2**40)),
)
def test_fixed_precision_writer_matches_printf(tmp_path_factory, pts, precision, ints):
    c = PointCloud(pts, {"i": ints[: len(pts)]})
    p = xyz.write_points(tmp_path_factory.mktemp("w") / "w.csv", c, precision=precision)
    lines = p.read_text().splitlines()[1:]
    for row, line in zip(pts.tolist(), lines, strict=True):
        got = line.split(",")
        for v, tok in zip(row, got[:3], strict=True):
            ref = f"{v:.{precision}f}"
            # rounding of the scaled value may differ from printf by one unit in the last place
            # (compared as integers of the printed digits: exact at any magnitude)
            assert abs(int(tok.replace(".", "")) - int(ref.replace(".", ""))) <= 1
            assert abs(float(tok) - v) <= 0.5 * 10.0**-precision * (1 + 1e-6) + abs(v) * 1e-15
    assert [int(line.split(",")[3]) for line in lines] == ints[: len(pts)].tolist()
    back = xyz.read_points(p)
    assert np.allclose(back.xyz, pts, atol=0.51 * 10.0**-precision, rtol=1e-15)


def test_fixed_precision_falls_back_for_huge_or_nan_attributes(tmp_path):
    c = PointCloud(np.array([[1e30, 0, 0], [0, 0, 0]]), {"a": np.array([np.nan, 1.5])})
    p = xyz.write_points(tmp_path / "h.xyz", c, precision=2)
    lines = p.read_text().splitlines()
    assert lines[1].split()[0] == f"{1e30:.2f}" and lines[1].split()[3] == "nan"
    with pytest.raises(InputError, match="precision"):
        xyz.write_points(tmp_path / "bad.xyz", c, precision=40)
