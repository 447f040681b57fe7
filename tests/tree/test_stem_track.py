"""The stem followed through the points slab by slab (tree.stem): needle envelopes round
it and whorl branches across it do not take it off the stem, an occluded stretch shorter
than the gap is crossed, a lean is followed, and the taper model anchors on it."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.graph import BranchGraph
from biomorph.errors import ParameterError
from biomorph.tree import radius as rd
from biomorph.tree import stem as st
from biomorph.tree.neighbours import PointIndex
from tests.tree.test_livny import cylinder_points


def _needled_stem(seed=0, lean=0.0, gap=None, n=24_000):
    """A 6 m stem tapering 12 -> 6 cm (leaning ``lean`` rad towards +x), a clump of
    needles every 0.5 m (0.2-0.5 m round it, as a whorl's) and, with ``gap`` (lo, hi), no
    stem points between those heights."""
    rng = np.random.default_rng(seed)
    h = rng.uniform(0, 6, n)
    r = 0.12 - 0.01 * h
    th = rng.uniform(0, 2 * np.pi, n)
    axis = np.c_[np.sin(lean) * h, np.zeros(n), np.cos(lean) * h]
    ring = np.c_[np.cos(th) * np.cos(lean), np.sin(th), -np.cos(th) * np.sin(lean)]
    pts = axis + r[:, None] * ring
    pts += rng.normal(0, 0.002, pts.shape)
    if gap is not None:
        pts = pts[(h < gap[0]) | (h > gap[1])]
    clumps = []
    for zc in np.arange(0.75, 6, 0.5):
        m = 600
        rr = rng.uniform(0.2, 0.5, m)
        a = rng.uniform(0, 2 * np.pi, m)
        c = np.array([np.sin(lean) * zc, 0, np.cos(lean) * zc])
        clumps.append(c + np.c_[rr * np.cos(a), rr * np.sin(a), rng.uniform(-0.1, 0.1, m)])
    return np.vstack([pts, *clumps])


def _track(pts, centre, r, spacing=0.01):
    return st.track_stem(pts, spacing, np.asarray(centre, float), r, kdtree=PointIndex(pts))


def test_the_stem_is_followed_through_needle_clumps_to_its_top():
    pts = _needled_stem()
    tr = _track(pts, (0, 0, 1.3), 0.107)
    assert tr.n >= 40 and tr.centre[:, 2].min() < 0.4 and tr.centre[:, 2].max() > 5.5
    # on the stem's axis, with its radius: no envelope taken
    assert np.abs(tr.centre[:, :2]).max() < 0.03
    truth = 0.12 - 0.01 * tr.centre[:, 2]
    assert np.abs(tr.radius / truth - 1).max() < 0.15
    assert np.all(np.diff(tr.centre[:, 2]) > 0)  # bottom to top
    # the seed's own section is part of it
    assert np.isclose(tr.centre[:, 2], 1.3).any()


def test_a_short_occlusion_is_crossed_and_a_long_one_ends_the_stem():
    short = _track(_needled_stem(gap=(3.0, 3.6)), (0, 0, 1.3), 0.107)
    assert short.centre[:, 2].max() > 5.5  # 0.6 m hidden: 6 radii, under the gap
    long = _track(_needled_stem(gap=(3.0, 5.0)), (0, 0, 1.3), 0.107)
    assert 2.8 < long.centre[:, 2].max() < 3.1  # 2 m hidden: over 10 radii


def test_a_leaning_stem_is_followed_along_its_axis():
    lean = np.radians(25)
    pts = _needled_stem(lean=lean)
    s = 1.3
    tr = _track(pts, (np.sin(lean) * s, 0, np.cos(lean) * s), 0.12 - 0.01 * s)
    top = tr.centre[np.argmax(tr.centre[:, 2])]
    assert top[2] > 5.0 and top[0] == pytest.approx(np.tan(lean) * top[2], abs=0.05)
    along = tr.centre[:, 0] / np.sin(lean)
    assert np.abs(tr.radius / (0.12 - 0.01 * along) - 1).max() < 0.2


def test_bad_seeds_are_refused():
    pts = _needled_stem()
    with pytest.raises(ParameterError, match="must be > 0"):
        st.track_stem(pts, 0.0, np.zeros(3), 0.1, kdtree=PointIndex(pts))


def _sleeve(rng, x=0.35, lo=1.0, hi=6.0):
    """Needle envelopes along a path ``x`` m off the stem: rings 10 cm high, each of its own
    radius (0.2-0.6 m), their tips a tight envelope (3 mm)."""
    rings = []
    for z0 in np.arange(lo, hi, 0.1):
        r = rng.uniform(0.2, 0.6)
        rings.append(cylinder_points((x, 0, z0), (x, 0, z0 + 0.1), r, int(4000 * r), rng, 0.003))
    return np.vstack(rings)


def test_the_taper_model_anchors_on_the_tracked_stem_where_its_fits_hold_envelopes():
    # the skeleton's stem path runs out into the needles from 1 m (a sparse crown's
    # shortest paths): two in three of its lower half's circles are envelopes, and their
    # trimmed median anchored the taper model on them (a quarter of the TreeLS spruce:
    # 2,706 L for 491)
    rng = np.random.default_rng(3)
    pts = np.vstack([_needled_stem(seed=3), _sleeve(rng)])
    z = np.linspace(0, 6, 61)
    pos = np.c_[np.where(z > 1.0, 0.35, 0.0), np.zeros(61), z]
    g = BranchGraph(pos, np.arange(-1, 60))
    fit = rd.fit_circles(g, pts, np.full(61, 0.45), spacing=0.01)
    kd = PointIndex(pts)
    calls = []

    def stems(graph, f, stem, reliable):
        calls.append(1)
        return st.stem_tracks(graph, f, stem, reliable, pts, 0.01, kdtree=kd)

    plain, fp = rd.taper_radii(g, fit)
    tracked, ft = rd.taper_radii(g, fit, stems=stems)
    # the track anchors the model, or vets the stem path's fits (those above its band
    # dropped as envelopes) and the rest do
    assert ft.model[0]["anchor"] in ("stem (tracked)", "stem (fits on the track)")
    assert fp.model[0]["anchor"] == "stem"
    truth = 0.12 - 0.01 * 1.3
    at = int(np.argmin(np.abs(z - 1.3)))
    assert tracked[at] == pytest.approx(truth, rel=0.1)
    assert plain[at] > 1.5 * truth
    assert len(calls) == 1  # once per taper model, for all trees
    # a stem path on the stem: its own fits agree with the track and anchor the model
    on = g.with_(position=np.c_[np.zeros(61), np.zeros(61), z])
    clean = rd.fit_circles(on, pts, np.full(61, 0.15), spacing=0.01)
    same, fc = rd.taper_radii(on, clean, stems=stems)
    assert fc.model[0]["anchor"] == "stem" and len(calls) == 2
    assert np.array_equal(same, rd.taper_radii(on, clean)[0])


def test_a_needle_envelope_round_the_stem_is_left_for_the_stem_inside_it():
    # a spruce's crown is a cone of needle tips round its stem, a continuous surface a
    # track follows as well as the stem (the stem's few points inside its circles pass
    # the envelope test); the stem is the innermost
    rng = np.random.default_rng(4)
    stem = cylinder_points((0, 0, 0), (0, 0, 6), 0.1, 5000, rng, noise=0.002)
    shell = cylinder_points((0, 0, 0.5), (0, 0, 6), 0.3, 30_000, rng, noise=0.003)
    pts = np.vstack([stem, shell])
    kd = PointIndex(pts)
    outer = st.track_stem(pts, 0.02, np.array([0, 0, 2.0]), 0.3, kdtree=kd)
    assert outer.n >= st.TRACK_MIN_CIRCLES
    assert np.median(outer.radius) == pytest.approx(0.3, rel=0.05)
    inner = st._inner(outer, pts, 0.02, kd, seed=0)
    assert inner is not None and inner.height > 4.0
    assert np.median(inner.radius) == pytest.approx(0.1, rel=0.05)
    assert st._inner(inner, pts, 0.02, kd, seed=0) is None  # nothing inside the stem


@pytest.mark.parametrize("seed", [1, 2])
def test_the_track_vets_the_stem_paths_fits_when_their_levels_agree(seed):
    """Half the stem path's fits are needle envelopes 1.5-3.3x the stem, the other half on
    the tracked stem: their trimmed level lies inside the track's band (0.21-0.26 above it
    for a band of 0.26-0.33), so the path's fits anchored the model with their own scatter
    (0.39-0.43), a band that keeps envelopes up to twice the model (a quarter of the TreeLS
    spruce: 0.94 m³ for 0.44). Left out where the track measured the stem, the rest give
    the stem's level and scatter."""
    rng = np.random.default_rng(seed)
    n = 40
    cum = np.linspace(0, 1, n)
    yt = np.log(0.1) + cum + rng.normal(0, 0.12, n)  # the track's radii (model ordinates)
    y = yt + rng.normal(0, 0.02, n)
    env = np.arange(n) % 2 == 1
    y[env] += rng.uniform(0.4, 1.2, env.sum())
    stem = np.ones(n, dtype=bool)
    a_path, _, sc_path = rd._robust_line(cum, y, 1.0)
    a_track, _, st = rd._robust_line(cum, yt, 1.0)
    assert a_path - a_track < 3 * st and 0.35 < sc_path < np.log(rd.KEEP_MAX_RATIO)
    a, sc, src = rd._tree_anchor(cum, y, stem, stem, None, 0.0, lambda: (np.arange(n), yt, 0.8))
    assert src == "stem (fits on the track)"
    assert abs(a - a_track) < 0.05 and sc < 0.2
