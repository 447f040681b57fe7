"""Palágyi–Kuba 8-subiteration thinning: templates, topology, thinness, idempotence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from biomorph.errors import ParameterError
from biomorph.tree.thinning import DIRECTIONS, templates, thin_palagyi_kuba


def _topology(v):
    """(26-connected object components, 6-connected background components incl. outside)."""
    _, nobj = ndimage.label(v, structure=np.ones((3, 3, 3)))
    _, nbg = ndimage.label(
        np.pad(~v, 1, constant_values=True), structure=ndimage.generate_binary_structure(3, 1)
    )
    return nobj, nbg


def _grid(shape):
    return np.mgrid[tuple(slice(0, s) for s in shape)]


def test_template_sets():
    ts = templates()
    assert len(ts) == 8 and [len(t) for t in ts] == [20] * 8  # the seed: 20 per subiteration
    assert [len(t) for t in templates(full_symmetry=True)] == [22] * 8
    for (_, (sx, sy, sz)), tset in zip(DIRECTIONS, ts, strict=True):
        for t in tset:
            assert t[1, 1, 1] == 1  # centre black
            # a face neighbour on a peeled side is white in every template
            assert 0 in (t[1 + sx, 1, 1], t[1, 1 + sy, 1], t[1, 1, 1 + sz])
    # opposite directions are point reflections of each other
    for a, b in ((0, 1), (2, 3), (4, 5), (6, 7)):
        ra = {t[::-1, ::-1, ::-1].tobytes() for t in ts[a]}
        assert ra == {t.tobytes() for t in ts[b]}


@pytest.mark.parametrize("full", [False, True])
def test_topology_preserved_on_random_shapes(full):
    rng = np.random.default_rng(1)
    for _ in range(60):
        v = ndimage.binary_dilation(
            rng.random((11, 11, 11)) < 0.05, iterations=int(rng.integers(1, 3))
        )
        v &= rng.random(v.shape) < 0.93  # pepper: small cavities and tunnels
        t = thin_palagyi_kuba(v, full_symmetry=full)
        assert _topology(t) == _topology(v)
        assert (t <= v).all()


def test_cylinder_becomes_centred_line():
    x, y, z = _grid((21, 21, 60))
    cyl = ((x - 10) ** 2 + (y - 10) ** 2 <= 49) & (z >= 5) & (z < 55)
    t = thin_palagyi_kuba(cyl)
    pts = np.argwhere(t)
    # one voxel per slice over most of the length, near the axis
    per_slice = np.bincount(pts[:, 2], minlength=60)[10:50]
    assert (per_slice == 1).mean() > 0.9
    mid = pts[(pts[:, 2] >= 10) & (pts[:, 2] < 50)]
    assert np.abs(mid[:, :2] - 10).max() <= 2 and (np.abs(mid[:, :2] - 10) <= 1).mean() > 0.85
    assert 35 <= t.sum() <= 60


def test_idempotent_and_thin_lines_kept():
    x, y, z = _grid((15, 15, 15))
    line = (x == 7) & (y == 7) & (z >= 2) & (z <= 12)
    assert np.array_equal(thin_palagyi_kuba(line), line)  # already thin: unchanged
    box = (x >= 3) & (x <= 11) & (y >= 4) & (y <= 9) & (z >= 2) & (z <= 13)
    once = thin_palagyi_kuba(box)
    assert np.array_equal(thin_palagyi_kuba(once), once)


def test_ball_shrinks_to_point_and_hollow_sphere_keeps_cavity():
    x, y, z = _grid((21, 21, 21))
    r2 = (x - 10) ** 2 + (y - 10) ** 2 + (z - 10) ** 2
    assert thin_palagyi_kuba(r2 <= 64).sum() == 1
    shell = (r2 <= 64) & (r2 > 25)
    assert _topology(thin_palagyi_kuba(shell)) == _topology(shell) == (1, 2)


def test_symmetric_shape_gives_near_symmetric_result():
    # a plus-shaped prism: four arms; the skeleton has four arms of similar length
    x, y, z = _grid((31, 31, 9))
    plus = (
        ((np.abs(x - 15) <= 2) & (np.abs(y - 15) <= 12))
        | ((np.abs(y - 15) <= 2) & (np.abs(x - 15) <= 12))
    ) & (np.abs(z - 4) <= 2)
    t = np.argwhere(thin_palagyi_kuba(plus))
    reach = [t[:, 0].max() - 15, 15 - t[:, 0].min(), t[:, 1].max() - 15, 15 - t[:, 1].min()]
    assert max(reach) - min(reach) <= 2 and min(reach) >= 8


def test_agrees_with_skimage_on_simple_shapes():
    skm = pytest.importorskip("skimage.morphology")
    x, y, z = _grid((25, 25, 40))
    # an inclined tube (diagonal in x-z)
    d = np.abs((x - 5) - 0.4 * (z - 3))
    tube = (d <= 3) & (np.abs(y - 12) <= 3) & (z >= 3) & (z <= 36)
    ours = np.argwhere(thin_palagyi_kuba(tube))
    lee = np.argwhere(skm.skeletonize(tube))
    # same component count and every voxel of ours within 2 voxels of theirs
    from scipy.spatial import cKDTree

    assert cKDTree(lee).query(ours)[0].max() <= 3.0
    assert abs(len(ours) - len(lee)) <= 0.3 * len(lee)


def test_bad_input():
    with pytest.raises(ParameterError, match="3-D"):
        thin_palagyi_kuba(np.ones((4, 4), bool))
    assert not thin_palagyi_kuba(np.zeros((3, 4, 5), bool)).any()
