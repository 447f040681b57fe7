"""LAS/LAZ: real files, round trips keeping every dimension, malformed input."""

from __future__ import annotations

import laspy
import numpy as np
import pytest

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import FormatError, InputError
from biomorph.io import las
from tests.conftest import shared_file


def cloud_with_extras(n=500, seed=0):
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-5, 5, (n, 3)) + [350_000.0, 5_600_000.0, 120.0]  # UTM-like
    return PointCloud(
        xyz,
        {
            "intensity": rng.integers(0, 65535, n).astype(np.uint16),
            "classification": rng.integers(0, 31, n).astype(np.uint8),
            "red": rng.integers(0, 65535, n).astype(np.uint16),
            "green": rng.integers(0, 65535, n).astype(np.uint16),
            "blue": rng.integers(0, 65535, n).astype(np.uint16),
            "gps_time": rng.uniform(0, 1e5, n),
            "Deviation": rng.normal(size=n).astype(np.float32),
            "segment": rng.integers(-100, 100, n).astype(np.int32),
        },
    )


@pytest.mark.parametrize("ext", [".las", ".laz"])
def test_round_trip_keeps_all_dimensions(tmp_path, ext):
    c = cloud_with_extras()
    out = las.write_points(tmp_path / f"c{ext}", c)
    back = las.read_points(out)
    assert back.meta["point_format"] == 3  # gps_time + rgb chose the smallest format
    assert set(back.meta["extra_dimensions"]) == {"Deviation", "segment"}
    assert np.abs(back.xyz - c.xyz).max() <= 0.5e-4 + 1e-9  # default 0.1 mm grid
    assert back.xyz.dtype == np.float64
    for k, v in c.attributes.items():
        assert back.attributes[k].dtype == v.dtype, k
        assert np.array_equal(back.attributes[k], v), k
    # independent check with laspy itself
    raw = laspy.read(out)
    assert np.array_equal(np.asarray(raw["Deviation"]), c.attributes["Deviation"])
    assert raw.header.point_count == c.n_points
    # writing the read cloud again keeps scales/offsets, so coordinates are bit-identical
    again = las.read_points(las.write_points(tmp_path / f"d{ext}", back))
    assert np.array_equal(again.xyz, back.xyz)
    assert np.allclose(again.meta["offsets"], back.meta["offsets"])


@pytest.mark.parametrize("name,count", [("archi_tree2.las", 58219), ("treels_spruce.laz", 83392)])
def test_real_files(tmp_path, name, count):
    path = shared_file("trees", name)
    c = las.read_points(path)
    ref = laspy.read(path)
    assert c.n_points == count == ref.header.point_count
    assert np.allclose(c.xyz[:, 0], ref.x) and np.allclose(c.xyz[:, 2], ref.z)
    assert np.allclose(c.meta["scales"], ref.header.scales)
    assert "intensity" in c.attributes and "classification" in c.attributes
    out = las.write_points(tmp_path / ("o" + path.suffix), c)
    back = las.read_points(out)
    assert np.array_equal(back.xyz, c.xyz)
    assert all(np.array_equal(back.attributes[k], v) for k, v in c.attributes.items())
    assert back.meta["point_format"] == c.meta["point_format"]


def test_offset_is_added_back_when_writing(tmp_path):
    c = PointCloud(np.zeros((3, 3)) + [[0, 0, 0], [1, 0, 0], [0, 1, 0]], offset=[10, 20, 30])
    back = las.read_points(las.write_points(tmp_path / "o.las", c))
    assert np.allclose(back.xyz, c.world_xyz, atol=1e-4)


def test_scale_option_and_huge_extent(tmp_path):
    c = PointCloud(np.array([[0.0, 0, 0], [1.23456, 0, 0]]))
    back = las.read_points(las.write_points(tmp_path / "s.las", c, scale=0.01))
    assert np.allclose(back.meta["scales"], 0.01)
    assert back.xyz[1, 0] == pytest.approx(1.23, abs=1e-9)
    far = PointCloud(np.array([[0.0, 0, 0], [1e7, 0, 0]]))
    with pytest.raises(InputError, match="does not fit"):
        las.write_points(tmp_path / "far.las", far)
    assert not (tmp_path / "far.las").exists()


def test_bad_attribute_leaves_no_file(tmp_path):
    c = PointCloud(np.zeros((2, 3)), {"name": np.array(["a", "b"])})
    with pytest.raises(InputError, match="name"):
        las.write_points(tmp_path / "bad.las", c)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "content,match",
    [
        (b"", "empty"),
        (b"LASF" + b"\0" * 50, "LAS/LAZ"),
        (b"hello world, not a point cloud\n" * 10, "LAS/LAZ"),
    ],
)
def test_malformed(tmp_path, content, match):
    p = tmp_path / "bad.las"
    p.write_bytes(content)
    with pytest.raises(FormatError, match=match) as err:
        las.read_points(p)
    assert str(p) in str(err.value)


@pytest.mark.parametrize("ext", [".las", ".laz"])
def test_truncated(tmp_path, ext):
    good = las.write_points(tmp_path / f"g{ext}", cloud_with_extras(2000))
    data = good.read_bytes()
    for cut in (100, len(data) // 2, len(data) - 7):
        p = tmp_path / f"t{cut}{ext}"
        p.write_bytes(data[:cut])
        with pytest.raises(FormatError):
            las.read_points(p)


def test_empty_point_record_rejected(tmp_path):
    header = laspy.LasHeader(point_format=0, version="1.2")
    empty = laspy.LasData(header)
    p = tmp_path / "empty.las"
    empty.write(str(p))
    with pytest.raises(FormatError, match="no points"):
        las.read_points(p)


LAZ_DAMAGE = {
    # name: (patch(data) -> data, words the one-line FormatError must contain)
    "point-count": (lambda d: _patched(d, 107, "<I", 0x7FFFFFFF), "chunk"),
    "chunk-table-cut": (lambda d: d[:-7], "chunk table"),
    "chunk-count": (lambda d: _patched(d, _table_at(d) + 4, "<I", 0x7FFFFFFF), "chunks"),
    "chunk-table-version": (lambda d: _patched(d, _table_at(d), "<I", 7), "version"),
    "chunk-table-offset": (lambda d: _patched(d, _points_at(d), "<q", 2**40), "offset"),
    "vlr-length": (lambda d: _patched(d, 227 + 20, "<H", 0xFFFF), "VLR 0"),
    "laszip-items": (lambda d: _patched(d, _laszip_at(d) + 32, "<H", 0), "items"),
    "x-scale-0": (lambda d: _patched(d, 131, "<d", 0.0), "x scale"),
    "y-scale-nan": (lambda d: _patched(d, 139, "<d", float("nan")), "y scale"),
}


def _patched(data: bytes, at: int, fmt: str, value) -> bytes:
    import struct

    b = bytearray(data)
    struct.pack_into(fmt, b, at, value)
    return bytes(b)


def _points_at(data: bytes) -> int:
    import struct

    return struct.unpack_from("<I", data, 96)[0]


def _table_at(data: bytes) -> int:
    import struct

    return struct.unpack_from("<q", data, _points_at(data))[0]


def _laszip_at(data: bytes) -> int:
    import struct

    pos = struct.unpack_from("<H", data, 94)[0]
    while data[pos + 2 : pos + 16] != b"laszip encoded":
        pos += 54 + struct.unpack_from("<H", data, pos + 20)[0]
    return pos + 54


READ_IN_CHILD = """
import sys
from biomorph.errors import BiomorphError
from biomorph.io.las import read_points
try:
    read_points(sys.argv[1])
except BiomorphError as exc:
    print(exc)
    sys.exit(2)
"""


@pytest.mark.parametrize("damage", sorted(LAZ_DAMAGE))
def test_corrupt_laz_is_one_format_error_never_an_abort(tmp_path, damage):
    """Each damage made the native decompressor abort, segfault, allocate tens of GB, or was
    silently accepted; now one FormatError names the field. Read in a child process so an
    abort counts as a failure."""
    import subprocess
    import sys

    patch, words = LAZ_DAMAGE[damage]
    good = las.write_points(tmp_path / "g.laz", cloud_with_extras(2000))
    bad = tmp_path / f"{damage}.laz"
    bad.write_bytes(patch(good.read_bytes()))
    res = subprocess.run(
        [sys.executable, "-c", READ_IN_CHILD, str(bad)], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 2, (res.returncode, res.stderr[-2000:])
    msg = res.stdout.strip()
    assert str(bad) in msg and words in msg and len(msg.splitlines()) == 1, msg


def test_corrupt_laz_chunk_is_named(tmp_path):
    """Damage inside the last chunk's compressed bytes: the error names that chunk and its
    point records (the file has three chunks of 50,000 points)."""
    good = las.write_points(tmp_path / "g.laz", cloud_with_extras(120_000))
    data = bytearray(good.read_bytes())
    at = len(data) - 2000
    data[at : at + 16] = bytes(16)
    bad = tmp_path / "bad.laz"
    bad.write_bytes(bytes(data))
    with pytest.raises(FormatError, match=r"chunk 2 \(points 100000 to 119999\) is corrupt"):
        las.read_points(bad)
