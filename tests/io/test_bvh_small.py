"""The BVH reader's and writer's NumPy paths for small files (no numba import, issue 12)
give the same bits as the compiled kernels, and hand anything irregular to the compiled
scanner (whose diagnostics stay the only ones)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import biomorph.io.bvh as bvh
from biomorph.io.bvh import read_bvh, write_bvh
from biomorph.motion.synthetic import walk
from tests.conftest import shared_file

FILES = ["cmu_01_01.bvh", "ad_rokoko_jesse_dance.bvh", "ad_fair1_zombie_walk.bvh"]


def _read(path, compiled, monkeypatch):
    monkeypatch.setattr(bvh, "_compiled", lambda n: compiled)
    return read_bvh(path)


@pytest.mark.parametrize("name", FILES)
def test_numpy_read_and_write_equal_the_compiled_ones(name, monkeypatch, tmp_path):
    path = shared_file("motion", name)
    used = []
    real = bvh._values_numpy
    monkeypatch.setattr(bvh, "_values_numpy", lambda *a: used.append(1) or real(*a))
    a = _read(path, False, monkeypatch)
    assert used, "the small-file value path was not taken"
    b = _read(path, True, monkeypatch)
    assert np.array_equal(a.rotation, b.rotation)
    assert np.array_equal(a.root_position, b.root_position)
    assert (a.joint_translation is None) == (b.joint_translation is None)
    if a.joint_translation is not None:
        assert np.array_equal(a.joint_translation, b.joint_translation)
    assert a.meta == b.meta
    for euler in ("wrap", "continuous"):
        texts = []
        for compiled in (False, True):
            monkeypatch.setattr(bvh, "_compiled", lambda n, c=compiled: c)
            p = tmp_path / f"{compiled}{euler}.bvh"
            write_bvh(p, b, precision=6, euler=euler)
            texts.append(p.read_bytes())
        assert texts[0] == texts[1]


@pytest.mark.parametrize("precision", [0, 1, 3, 6, 9])
def test_numpy_format_equals_the_compiled_one(precision):
    from biomorph.io._bvh_kernels import _format_fixed

    rng = np.random.default_rng(precision)
    edge = [0.0, -0.0, -1e-9, 0.5e-6, -0.5e-6, 1.5e-6, 9.9999995, -0.49, 0.5, 99.5, 1e5 - 1e-7]
    vals = np.concatenate([rng.normal(0, 1, 600), rng.normal(0, 1e4, 600), edge, [7.0]])
    vals = vals.reshape(-1, 6)
    buf = np.empty(vals.size * (precision + 16), dtype=np.uint8)
    used = _format_fixed(np.ascontiguousarray(vals), precision, bvh._value_limit(precision), buf)
    assert buf[:used].tobytes() == bvh._format_numpy(vals, precision)


@pytest.mark.parametrize("compiled", [False, True])
def test_values_too_large_for_the_precision_are_refused_not_garbled(
    tmp_path, monkeypatch, compiled
):
    # 1e11 at 8 decimals is 1e19 once scaled: beyond int64, so refuse it (was garbage text)
    monkeypatch.setattr(bvh, "_compiled", lambda n: compiled)
    big = np.array([[1e11, 0.0, 0.0]])
    with pytest.raises(bvh.InputError, match="exceeds 4.61e\\+10 in magnitude"):
        bvh._format_rows(big, 8)
    ok = np.array([[4e10, -3.25, 0.0]])
    assert bvh._format_rows(ok, 8).split()[0] == b"40000000000.00000000"


@pytest.mark.parametrize(
    "body",
    [
        b"1 2 3\n4 5 6\n",  # clean
        b"1 2 3\n4 5e1 6\n",  # exponent: the scanner's rounding differs beyond 1e22
        b"1 2 3\n4 5.12345678901234567 6\n",  # 17 digits: beyond the exactly-rounded range
        b"1 2 3\n4 5 6 7\n",  # a long line
        b"1 2 3\n4 5\n",  # a short line
        b"1 2 3\n4 nan 6\n",  # a letter
        b"1 2 3\n4 1_0 6\n",  # Python's float takes underscores, the scanner does not
        b"1 2 3\n4 -- 6\n",  # malformed
    ],
)
def test_numpy_values_take_only_clean_exact_sections(body):
    got = bvh._values_numpy(body, 0, 2, 3)
    if body == b"1 2 3\n4 5 6\n":
        assert np.array_equal(got, [[1, 2, 3], [4, 5, 6]])
    else:
        assert got is None


PROBE = """
import sys
from biomorph.cli import run
try:
    run({argv!r})
except SystemExit as e:
    assert not e.code, e.code
print('NUMBA=' + str('numba' in sys.modules))
other = ('biomorph.tree', 'biomorph.creature', 'biomorph.leaf', 'scipy.spatial')
print('OTHER=' + ','.join(sorted(m for m in sys.modules if m.startswith(other))))
"""


@pytest.mark.parametrize("command", ["info", "convert"])
def test_motion_info_and_convert_of_a_small_file_load_no_numba(command, tmp_path):
    """``biomorph motion info/convert`` on a small BVH runs without numba (its import and
    cached-kernel loads were 0.9 s of the 1.4 s start-up), scipy.spatial or another pillar;
    checks the cause, not a time."""
    src = tmp_path / "walk.bvh"
    write_bvh(src, walk(240, 120, n_joints=30))
    argv = ["motion", command, str(src)]
    if command == "convert":
        argv += ["-o", str(tmp_path / "out.bvh")]
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(argv=argv)],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    marks = [ln for ln in out.stdout.splitlines() if ln.startswith("NUMBA=")]
    assert marks == ["NUMBA=False"], out.stdout + out.stderr
    # nor the other pillars' CLIs (cli builds only the group it runs) or scipy.spatial
    # (quat_to_euler is NumPy): together ~0.4 s of the call
    assert "OTHER=" in out.stdout.splitlines(), out.stdout
    if command == "convert":
        a, b = read_bvh(src), read_bvh(tmp_path / "out.bvh")
        assert np.abs(a.world_positions() - b.world_positions()).max() < 1e-5
