"""Fast paths give the same bits as the paths they replace: the Motion type's NumPy FK and
slerp (small work, numba not loaded) against the compiled kernels, and each operator's fused
kernel against the reference it replaced (tests/motion/oracles.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from biomorph.core import motion as cm
from biomorph.core._motion_kernels import fk_positions, sample_slerp
from biomorph.io.bvh import read_bvh
from biomorph.motion.synthetic import walk
from tests.conftest import shared_file


def _clips():
    out = [walk(300, 120, n_joints=40, noise_deg=2.0, seed=3)]
    for name in ("ad_rokoko_jesse_dance.bvh", "ad_fair1_zombie_walk.bvh"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out.append(read_bvh(shared_file("motion", name)))
    return out


@pytest.fixture(scope="module")
def clips():
    return _clips()


def test_numpy_fk_equals_the_compiled_fk(clips):
    for m in clips:
        rot = np.ascontiguousarray(m.rotation)
        tr = np.ascontiguousarray(m.local_translations())
        sk = m.skeleton
        p1, q1 = np.empty(tr.shape), np.empty(rot.shape)
        p2, q2 = np.empty(tr.shape), np.empty(rot.shape)
        fk_positions(cm.ro(sk.rest_rotation), cm.ro(rot), cm.ro(tr), cm.ro_int(sk.parent), p1, q1)
        cm.fk_numpy(sk.rest_rotation, rot, tr, sk.parent, p2, q2)
        assert np.array_equal(p1, p2) and np.array_equal(q1, q2)


def test_numpy_slerp_equals_the_compiled_slerp(clips):
    rng = np.random.default_rng(0)
    for m in clips:
        t = np.sort(rng.uniform(0, m.n_frames - 1, 2 * m.n_frames))
        t[::5] = np.floor(t[::5])  # exact frames
        t[-1] = m.n_frames - 1
        i0, frac, _, _ = cm.sample_linear(m, t)
        a = np.empty((t.size,) + m.rotation.shape[1:])
        b = np.empty_like(a)
        sample_slerp(cm.ro(m.rotation), cm.ro_int(i0), cm.ro(frac), a)
        cm.slerp_numpy(m.rotation, i0, frac, b)
        assert np.array_equal(a, b)


def test_store_flips_match_the_sequential_rule():
    """The compiled continuity step compares with the *stored* previous sample: a dot of
    exactly 0 resets the sign (``-0 < 0`` is false), which a plain parity count misses."""
    dots = np.array([[0.5], [-0.2], [0.0], [-0.3], [0.7], [-0.1], [np.nan], [0.4]])
    sign, want = 1.0, []
    for d in dots[:, 0]:
        sign = -1.0 if sign * d < 0 else 1.0
        want.append(sign < 0)
    assert cm._store_flips(dots)[:, 0].tolist() == want


def test_use_compiled_thresholds(monkeypatch):
    monkeypatch.delitem(__import__("sys").modules, "biomorph.core._motion_kernels")
    assert not cm.use_compiled(cm.COMPILED_MIN_WORK - 1)
    assert cm.use_compiled(cm.COMPILED_MIN_WORK)
