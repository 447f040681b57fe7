"""The compiled / memoised fast paths of the creature generator (issue 14, speed) give the
same bytes as the plain NumPy formulas they replace."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core import transforms as tf
from biomorph.creature import assembly as A
from biomorph.creature import balance as B
from biomorph.creature import limbs as lb
from biomorph.creature import mass as ms
from biomorph.creature import vertebrae as vt
from biomorph.creature.generator import Generator, Options


def _hull_plain(points):
    pts = sorted(set(map(tuple, np.asarray(points, float).round(12).tolist())))
    if len(pts) <= 2:
        return np.array(pts, float).reshape(-1, 2)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    for q in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], q) <= 0:
            lower.pop()
        lower.append(q)
    upper: list = []
    for q in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], q) <= 0:
            upper.pop()
        upper.append(q)
    return np.array(lower[:-1] + upper[:-1])


def test_hull_and_margin_match_the_plain_loops():
    rng = np.random.default_rng(0)
    for t in range(400):
        p = rng.normal(size=(int(rng.integers(1, 30)), 2))
        if t % 3 == 0:
            p = np.round(p, 1)  # duplicates and collinear runs
        if t % 5 == 0:
            p[:, 1] = 0.5
        a, b = _hull_plain(p), B.convex_hull(p)
        assert a.shape == b.shape and a.tobytes() == b.tobytes()
        if len(b) >= 3:
            q = rng.normal(size=2)
            want = float(B.edge_distances(b, q).min())
            got = float(B._min_edge_distance(b, float(q[0]), float(q[1])))
            assert np.float64(want).tobytes() == np.float64(got).tobytes()


def test_rest_quaternions_match_scipy():
    from scipy.spatial.transform import Rotation

    m = Rotation.random(500, random_state=1).as_matrix()
    m = np.concatenate([m, np.diag([1.0, -1.0, -1.0])[None], np.eye(3)[None]])
    assert A._matrix_to_quat(m).tobytes() == tf.matrix_to_quat(m).tobytes()
    skew = m[:3] * 1.001  # not orthonormal: SciPy's own path
    assert np.array_equal(A._matrix_to_quat(skew), tf.matrix_to_quat(skew))


def _boundaries_plain(region_len, counts):
    L = np.asarray(region_len, float)
    c = np.asarray(counts, np.int64).copy()
    c[1] = max(c[1], 1)
    a = np.array([0.0, L[0], L[0] + L[1], L.sum()])
    if c[0] <= 0:
        a[1] = 0.0
    if c[2] <= 0:
        a[2] = a[3]
    parts, reg = [np.array([a[0]])], []
    for r in range(3):
        if c[r] > 0:
            parts.append(np.linspace(a[r], a[r + 1], c[r] + 1)[1:])
            reg.append(np.full(c[r], r))
    return np.concatenate(parts), np.concatenate(reg)


def test_vertebra_boundaries_match_linspace():
    rng = np.random.default_rng(3)
    for t in range(500):
        L = rng.uniform(0, 600, 3)
        L[t % 3] = 0.0 if t % 4 == 0 else L[t % 3]
        c = rng.integers(0, 40, 3)
        e1, r1 = _boundaries_plain(L, c)
        e2, r2 = vt.boundaries(L, c)
        assert e1.tobytes() == e2.tobytes() and r1.tobytes() == r2.tobytes()


def _region_counts_plain(cls, neighbour_counts, weights, lengths, neighbour_lengths, max_total=160):
    nc = np.asarray(neighbour_counts, dtype=float)
    nl = np.asarray(neighbour_lengths, dtype=float)
    w = np.asarray(weights, dtype=float)
    L = np.asarray(lengths, dtype=float)
    per = np.where(nc > 0, nl / np.maximum(nc, 1), np.nan)
    seg = np.array(
        [
            np.nansum(w * per[:, r]) / max(np.sum(w[~np.isnan(per[:, r])]), 1e-12)
            if np.any(~np.isnan(per[:, r]))
            else np.nan
            for r in range(3)
        ]
    )
    base = w @ nc
    counts = np.where(np.isfinite(seg) & (seg > 0), L / np.where(seg > 0, seg, 1), base)
    counts = 0.5 * counts + 0.5 * base
    lo, hi = np.array(vt.COUNT_RANGES.get(cls, vt.COUNT_RANGES["mammal"])).T
    counts = np.clip(np.rint(counts), lo, hi)
    if cls == "mammal":
        counts[0] = 7 if counts[0] else 0
    total_len = max(L.sum(), 1e-12)
    counts = np.where(L < 0.02 * total_len, 0, counts)
    counts[1] = max(counts[1], 2)
    if counts.sum() > max_total:
        counts = np.maximum(np.floor(counts * max_total / counts.sum()), np.minimum(counts, 1))
    return counts.astype(np.int64)


def test_region_counts_match_the_nansum_formula():
    rng = np.random.default_rng(3)
    for i in range(3000):
        k = 3
        nc = rng.integers(0, 40, (k, 3)).astype(float) * (rng.random((k, 3)) > 0.25)
        nl = rng.random((k, 3)) * rng.choice([0.01, 1.0, 100.0])
        w = rng.random(k)
        w /= w.sum()
        L = rng.random(3) * rng.choice([0.01, 1.0, 100.0])
        L[rng.random(3) < 0.1] = 0.0
        cls = list(vt.COUNT_RANGES)[i % len(vt.COUNT_RANGES)]
        got = vt.region_counts(cls, nc, w, L, nl)
        assert np.array_equal(got, _region_counts_plain(cls, nc, w, L, nl)), i


def test_interp_kernel_matches_numpy():
    rng = np.random.default_rng(4)
    xp = np.cumsum(rng.uniform(0, 1, 40))
    xp[10:13] = xp[10]  # repeated knots (a degenerate spine curve)
    fp = rng.normal(size=40)
    x = np.concatenate([rng.uniform(-1, xp[-1] + 1, 300), xp])
    want = np.interp(x, xp, fp)
    got = np.array([A._interp1(v, xp, fp) for v in x])
    assert want.tobytes() == got.tobytes()


def _arm_plain(cls, trunk_lean, base, lengths, front, floor):
    DEG = lb.DEG
    r = lb.FREE_ARM_REST_DEG["mammal" if cls == "mammal" else "folded"]
    lo, hi = r["humerus_range"]
    rest = np.array([np.clip(r["humerus"] - trunk_lean / DEG, lo, hi), r["elbow"], r["wrist"]])
    L = np.asarray(lengths, float)

    def chain(a):
        c = np.cumsum(a * DEG, axis=-1)
        x = float(base[0]) + np.cumsum(L * np.sin(c), axis=-1)
        y = float(base[1]) - np.cumsum(L * np.cos(c), axis=-1)
        return x[..., -1], y.min(axis=-1)

    x, low = chain(rest)
    if x <= front and low >= floor:
        return rest * DEG
    grid = [
        np.arange(a, b + 1e-9, 5.0)
        for a, b in (r["humerus_range"], r["elbow_range"], r["wrist_range"])
    ]
    cand = np.stack(np.meshgrid(*grid, indexing="ij"), axis=-1).reshape(-1, 3)
    x, low = chain(cand)
    above = low >= floor
    if not above.any():
        return rest * DEG
    cost = np.where(above & (x <= front), np.abs(cand - rest).sum(axis=1), np.inf)
    best = np.argmin(cost) if np.isfinite(cost).any() else np.argmin(np.where(above, x, np.inf))
    return cand[best] * DEG


def test_free_arm_grid_search_matches_numpy():
    rng = np.random.default_rng(5)
    for t in range(400):
        cls = "mammal" if t % 2 else "reptile"
        base = rng.normal(size=3) * 50
        L = rng.uniform(5, 60, 3)
        front = base[0] + rng.uniform(-80, 80)
        floor = base[1] - rng.uniform(0, 120)
        lean = rng.uniform(0, np.pi / 2)
        want = _arm_plain(cls, lean, base, L, front, floor)
        got = lb.free_arm_rest(cls, lean, base, L, front, floor)
        assert want.tobytes() == got.tobytes()


def _slices_plain(xy, s, h, b, off, edges, m):
    a = np.clip(edges, 0.0, s[-1])
    P = np.stack([np.interp(a, s, xy[:, 0]), np.interp(a, s, xy[:, 1])], axis=-1)
    vol = ms.slice_volumes(s, h, b)
    smid = 0.5 * (s[1:] + s[:-1])
    t = np.diff(xy, axis=0)
    t = t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    nrm = np.stack([t[:, 1], -t[:, 0]], axis=1)
    nrm = np.where(nrm[:, 1:2] < 0, -nrm, nrm)
    cen2 = 0.5 * (xy[1:] + xy[:-1]) - nrm * 0.5 * (off[1:] + off[:-1])[:, None]
    owner = np.clip(np.searchsorted(edges, smid, side="right") - 1, 0, m - 1)
    vmass = np.bincount(owner, weights=vol, minlength=m)
    vcen = (
        np.stack(
            [np.bincount(owner, weights=vol * cen2[:, k], minlength=m) for k in range(2)], axis=1
        )
        / np.maximum(vmass, 1e-30)[:, None]
    )
    emid = 0.5 * (edges[1:] + edges[:-1])
    empty = vmass <= 0
    if empty.any():
        vcen[empty] = np.stack([np.interp(emid[empty], smid, cen2[:, k]) for k in range(2)], 1)
    return P, vmass, vcen, np.interp(emid, s, h), np.interp(emid, s, b)


@pytest.mark.parametrize("seed,kw", [(3, {}), (5, {"legs": 2}), (8, {"cls": "fish"})])
def test_body_slices_kernel_matches_numpy(seed, kw):
    from biomorph.creature import skulls as sk
    from biomorph.creature import spine as sp

    g = Generator(Options(seed=seed, **kw))
    g.run()
    spine, limbs, skull = g.state("spine"), g.state("limbs"), g.state("skull")
    xy, s, region = sp.sample(limbs.points)
    rl = sp.region_lengths(s, region)
    skull_h = sk.get(skull.shape).height * skull.length
    h, b, off = ms.profile(s, rl, spine.girth, spine.cls, skull_h, spine.legs == 0)
    counts = spine.counts.copy()
    for c in (counts, counts * 4):  # more vertebrae than slices: empty vertebrae
        edges, vreg = vt.boundaries(rl, c)
        want = _slices_plain(xy, s, h, b, off, edges, len(vreg))
        got = A._slices_kernel(xy, s, h, b, off, edges, len(vreg))
        for w_, g_ in zip(want, got, strict=True):
            assert w_.tobytes() == g_.tobytes()


def test_memoised_assembly_and_profiles_are_read_only_and_reused():
    g = Generator(Options(seed=11, legs=2))
    g.run()
    spine, limbs, skull = g.state("spine"), g.state("limbs"), g.state("skull")
    a1 = A.assemble(spine, limbs, skull)
    a2 = A.assemble(spine, limbs, skull)
    for k in ("W", "pos", "vol", "mass_c", "lim", "parent"):
        assert a1[k] is not a2[k] and a1[k].tobytes() == a2[k].tobytes()
        a1[k][...] = 0  # the caller's arrays are its own: the memoised body is untouched
    a3 = A.assemble(spine, limbs, skull)
    assert a3["pos"].tobytes() == a2["pos"].tobytes()
    A._BODY_CACHE.clear()
    assert A.assemble(spine, limbs, skull)["mass_c"].tobytes() == a2["mass_c"].tobytes()
    from biomorph.creature import spine as sp

    xy, s, region = sp.sample(limbs.points)
    h, _, _ = ms.profile(s, sp.region_lengths(s, region), spine.girth, spine.cls, 10.0, False)
    assert not h.flags.writeable


def test_step_streams_are_default_rng_of_seed_step_roll():
    from biomorph.creature.options import STEPS
    from biomorph.creature.states import step_rng

    for seed in (0, 5, 2**33 + 7):
        for i, step in enumerate(STEPS):
            for roll in (0, 100):
                for _ in range(2):  # memoised state: a second generator gives the same stream
                    got = step_rng(seed, step, roll)
                    ref = np.random.default_rng([seed & 0xFFFFFFFF, i, roll])
                    assert np.array_equal(got.random(6), ref.random(6))
                    assert got.integers(1 << 40) == ref.integers(1 << 40)


def _profile_plain(s, region_len, girth, cls, skull_h, legless):
    neck, back, tail = region_len
    total = max(neck + back + tail, 1e-9)
    h_back = max(girth * (back if back > 0.15 * total else total), 0.01 * total)
    u_neck = np.clip(s / max(neck, 1e-9), 0, 1)
    u_back = np.clip((s - neck) / max(back, 1e-9), 0, 1)
    u_tail = np.clip((s - neck - back) / max(tail, 1e-9), 0, 1)
    head_h = max(0.8 * skull_h, 0.2 * h_back)
    fishy = cls == "fish" or legless
    tail0, tail1 = (0.75, 0.25) if fishy else (0.75, 0.06)
    h = np.where(
        s < neck,
        head_h + (0.75 * h_back - head_h) * u_neck,
        np.where(
            s <= neck + back,
            h_back * (0.75 + 0.25 * np.sin(np.pi * u_back)),
            h_back * (tail0 + (tail1 - tail0) * u_tail),
        ),
    )
    return h, h * (0.5 if cls == "fish" else 0.8), h * (0.12 if fishy else 0.35)


def test_body_profile_matches_the_clip_formula():
    rng = np.random.default_rng(5)
    for i in range(500):
        rl = rng.random(3) * rng.choice([0.01, 1.0, 50.0])
        rl[rng.random(3) < 0.15] = 0.0
        total = rl.sum()
        s = np.r_[0.0, rl[0], rl[0] + rl[1], total, -0.0, rng.random(8) * total * 1.2 - 0.1]
        cls = ("mammal", "fish", "bird")[i % 3]
        args = (rl, 0.2 + rng.random(), cls, rng.random(), bool(i % 2))
        for got, ref in zip(ms._profile(s, *args), _profile_plain(s, *args), strict=True):
            assert np.array_equal(got, ref)


def _attach_all_plain(xy, s, rl, spine, skull_h, legless, places, width):
    from biomorph.creature import spine as sp
    from biomorph.creature.steps import _DROP

    at = np.array([p[3] for p in places], float)
    k = len(at)
    h = max(s[-1] * 1e-3, 1e-9)
    q = sp.point_at(xy, s, np.concatenate([at, at + h, at - h]))
    g = q[:k]
    d = q[k : 2 * k] - q[2 * k :]
    nd = np.linalg.norm(d, axis=-1, keepdims=True)
    t = d / np.where(nd > 0, nd, 1.0)
    n = np.stack([t[:, 1], -t[:, 0]], axis=1)
    n = np.where(n[:, 1:2] < 0, -n, n)
    h, b, _ = ms.profile(at, rl, spine.girth, spine.cls, skull_h, legless)
    drop = np.array([_DROP[p[2].kind] for p in places]) * h
    drop = np.where([p[0] == "hip" for p in places], drop * 0.75, drop)
    half = 0.45 * b * (1.35 if spine.posture == "sprawling" else 1.0)
    half = half * np.array([width if p[2].kind == "leg" else 1.0 for p in places])
    a2 = g - drop[:, None] * n
    return [
        (np.array([g[i, 0], g[i, 1], 0.0]), np.array([a2[i, 0], a2[i, 1], half[i]]))
        for i in range(len(places))
    ]


@pytest.mark.parametrize("kw", [{}, {"cls": "bird"}, {"legs": 6}, {"cls": "reptile", "legs": 4}])
def test_attachments_match_the_array_formula(kw):
    from biomorph.creature import spine as sp
    from biomorph.creature import steps as st

    for seed in range(12):
        g = Generator(Options(seed=seed, **kw))
        for _ in range(2):
            g.step()
        spine, gird = g.state("spine"), g.state("girdles")
        xy, s, region = sp.sample(st.to_creature_px(spine.points))
        rl = sp.region_lengths(s, region)
        for shifts, width in (({}, 1.0), ({"hip": 3.0, "shoulder": -2.0}, 1.35)):
            places = st.placements(gird, shifts, rl, s)
            args = (xy, s, rl, spine, 0.7 + seed, spine.legs == 0, places, width)
            got, ref = st._attach_all(*args), _attach_all_plain(*args)
            assert len(got) == len(ref)
            for (a, b), (c, d) in zip(got, ref, strict=True):
                assert np.array_equal(a, c) and np.array_equal(b, d)
