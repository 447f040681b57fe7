"""Fins are fin-ray sheets (issue 14): rays radiating from the fin's base with a thin
membrane between them, in the skin and in the bone models — not tubes round three bones."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.creature import fins as fn
from biomorph.creature import generate, skin
from biomorph.creature.bones import world_mesh


@pytest.fixture(scope="module")
def fish():
    return generate(6, cls="fish")


def _in_plane(fin, p):
    """Points ``p`` in the fin plane's coordinates (along the first ray, across it)."""
    a = fin.rays[0, -1] - fin.rays[0, 0]
    a /= np.linalg.norm(a)
    e = np.cross(fin.normal, a)
    q = p - fin.rays[0, 0]
    return np.stack([q @ a, q @ e, q @ fin.normal], -1)


def test_rays_radiate_from_the_base_without_crossing(fish):
    built = fn.build(fish, 7, 4)
    assert len(built) == 4  # two pairs of paired fins
    for fin in built:
        c = fish
        # the first ray is the skeleton's fin chain
        tips = [c.bone_ends[j] for j in fin.joints]
        assert np.allclose(fin.rays[0, 4::4], tips)
        length = float(np.linalg.norm(np.diff(fin.rays[0], axis=0), axis=1).sum())
        roots = _in_plane(fin, fin.rays[:, 0])
        assert np.abs(roots[:, 2]).max() < 1e-9 and np.ptp(roots[:, 1]) <= fn.BASE * length + 1e-9
        # each ray turned further than the one before, so the fan opens and no two cross
        d = fin.rays[:, -1] - fin.rays[:, 0]
        ang = np.arctan2(
            np.abs(_in_plane(fin, fin.rays[0, 0] + d)[:, 1]),
            _in_plane(fin, fin.rays[0, 0] + d)[:, 0],
        )
        assert np.all(np.diff(ang) > 0) and ang[-1] - ang[0] == pytest.approx(fn.SPREAD, abs=0.1)
        # the fin is wide: its margin spans at least a third of its length across the rays
        assert np.ptp(_in_plane(fin, fin.rays[:, -1])[:, 1]) > length / 3


def test_fin_skin_is_a_thin_sheet_not_a_tube(fish):
    env, h = skin.envelope(fish, None, 1)
    fv, _ = skin.fin_skin(fish, 1)
    assert len(fv) and env.n_vertices > len(fv)
    body_v = env.vertices[: env.n_vertices - len(skin.explicit_skin(fish, None, 1)[0])]
    for fin in fn.build(fish, 7, 4):
        tip = fin.rays[0, -1]
        length = float(np.linalg.norm(np.diff(fin.rays[0], axis=0), axis=1).sum())
        # no implicit (field) surface round the fin's tip: a fat tube was there, its surface
        # 0.06-0.08 fin lengths from the tip; now the nearest is the body (0.23-0.24)
        assert np.linalg.norm(body_v - tip, axis=1).min() > 0.15 * length
        # the explicit fin skin near its margin lies within the rays' tube of the fin plane
        fin_near = fv[np.linalg.norm(fv - tip, axis=1) < 0.4 * length]
        off = np.abs(_in_plane(fin, fin_near)[:, 2])
        assert len(fin_near) and off.max() <= 0.5 * fin.width * (1 + skin.LANDMARK_TISSUE) + 1e-9
        assert off.max() < 0.05 * length


def test_fin_bone_models_fan_out_with_their_joints(fish):
    m = world_mesh(fish, "bone", 1)
    jid = m.face_ids["bone"]
    for fin in fn.build(fish, 7, 4):
        faces = m.faces[np.isin(jid, fin.joints)]
        v = m.vertices[np.unique(faces)]
        length = float(np.linalg.norm(np.diff(fin.rays[0], axis=0), axis=1).sum())
        across = _in_plane(fin, v)[:, 1]
        assert np.ptp(across) > length / 3  # rays spread, not one rod along the chain
        assert np.abs(_in_plane(fin, v)[:, 2]).max() < 0.05 * length


def test_fin_skin_rides_on_its_fin_joints(fish):
    b = skin.body(fish, 1)
    fj = skin.fin_skin_joints(fish, 1)
    fv, _ = skin.fin_skin(fish, 1)
    assert len(fj) == len(fv) and np.allclose(b.envelope.vertices[-len(fv) :], fv)
    assert np.array_equal(b.joints[-len(fj) :, 0], fj)
    assert np.all(b.weights[-len(fj) :, 0] == 1.0)
    # each vertex's joint is the one of the ray sample it lies at (segment ends: either)
    built = fn.build(fish, *fn.DETAIL[1])
    median = fn.build_median(fish, *fn.MEDIAN_DETAIL[1])  # rays on the vertebrae
    pts = np.concatenate([fin.rays.reshape(-1, 3) for fin in [*built, *median]])
    jnt = np.concatenate(
        [np.tile(fin.joint_of, len(fin.rays)) for fin in built]
        + [fin.joint_of.reshape(-1) for fin in median]
    )
    d = np.linalg.norm(fv[:, None] - pts[None], axis=2)
    nearest = jnt[d.argmin(axis=1)]
    assert (nearest == fj).mean() > 0.95
    assert set(fj.tolist()) == {j for fin in [*built, *median] for j in fin.joints}


# ------------------------------------------------------------------ median fins (sixth round)
def _closed(f):
    """Every edge of the triangle mesh ``f`` is shared by exactly two faces."""
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def test_fish_has_dorsal_anal_and_caudal_fins_round_its_body(fish):
    median = fn.build_median(fish, *fn.MEDIAN_DETAIL[1])
    assert [m.name for m in median] == list(fn.MEDIAN)
    env, _ = skin.envelope(fish, None, 1)
    body_v = env.vertices[: env.n_vertices - len(skin.explicit_skin(fish, None, 1)[0])]
    spine = {j for j in range(len(fish)) if fish.kind[j] == "spine"}
    depth = np.ptp(body_v[:, 1])
    for m in median:
        r, k = fn.MEDIAN_DETAIL[1]
        assert m.rays.shape == (r, k, 3) and np.isfinite(m.rays).all()
        assert set(m.joints) <= spine  # the rays ride on vertebrae, no joints of their own
        assert np.allclose(m.rays[..., 2], 0.0)  # in the sagittal plane
        tips = m.rays[:, -1]
        # the rays leave the skin: no two samples of a ray coincide, and each is long
        seg = np.linalg.norm(np.diff(m.rays, axis=1), axis=2)
        assert seg.min() > 0 and (np.linalg.norm(tips - m.surface, axis=1) > 0.1 * depth).all()
        for tip in tips:
            near = body_v[np.abs(body_v[:, 0] - tip[0]) < 0.02 * fish.length]
            if m.name == "dorsal":  # above the body's back where it stands
                assert len(near) and tip[1] > near[:, 1].max()
            elif m.name == "anal":  # below its belly
                assert len(near) and tip[1] < near[:, 1].min()
        if m.name == "caudal":  # behind the tail's end (the creature faces +x)
            assert tips[:, 0].max() < body_v[:, 0].min()
            # a forked tail: the lobes' tips further out than the middle ray's
            reach = np.linalg.norm(tips - m.surface, axis=1)
            assert reach[0] > reach[len(reach) // 2] < reach[-1]
    dorsal, anal = median[0], median[1]
    # the dorsal fin stands on the trunk, the anal fin behind the vent (on the tail)
    assert {fish.region[j] for j in dorsal.joints} == {"back"}
    assert {fish.region[j] for j in anal.joints} == {"tail"}


def test_median_fins_sized_from_the_body(fish):
    """The fins scale with the creature: the same shape at twice the weight is 2^(1/3)
    larger, and the caudal fin is as tall as the deepest trunk section."""
    from biomorph.creature.bones.cage import trunk_sections

    caudal = fn.build_median(fish, 9, 5)[2]
    depth = 2 * trunk_sections(fish)[2].max()
    lobes = caudal.rays[[0, -1], -1]
    assert np.linalg.norm(lobes[0] - lobes[1]) == pytest.approx(fn.CAUDAL_SPAN * depth, rel=0.35)
    heavy = generate(6, cls="fish", weight=2 * fish.total_mass)
    a = fn.build_median(fish, 9, 5)
    b = fn.build_median(heavy, 9, 5)
    for fa, fb in zip(a, b, strict=True):
        ra = np.linalg.norm(fa.rays[:, -1] - fa.surface, axis=1)
        rb = np.linalg.norm(fb.rays[:, -1] - fb.surface, axis=1)
        assert rb / ra == pytest.approx(np.full(len(ra), 2 ** (1 / 3)), rel=0.02)


def test_median_fins_in_the_bone_models_skin_and_glb(fish, tmp_path):
    from biomorph.creature import export

    for lod in (0, 1, 2):
        median = fn.build_median(fish, *fn.MEDIAN_DETAIL[lod])
        m = world_mesh(fish, "bone", lod)
        jid = m.face_ids["bone"]
        for fin in median:
            # the rays' tips are in the bone models, on their vertebrae
            v = m.vertices[np.unique(m.faces[np.isin(jid, fin.joints)])]
            d = np.linalg.norm(v[:, None] - fin.rays[None, :, -1], axis=2).min(axis=0)
            assert d.max() < fin.width
    fv, ff = skin.fin_skin(fish, 1)
    assert _closed(ff) and np.isfinite(fv).all()
    tri = fv[ff]
    assert (
        np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) > 0
    ).all()
    # the fin skin rides on the vertebra of its ray
    b = skin.body(fish, 1)
    fj = skin.fin_skin_joints(fish, 1)
    n_med = sum(
        2 * f.rays.shape[0] * f.rays.shape[1]
        + f.rays.shape[0] * (f.rays.shape[1] * skin._FIN_SIDES[1] + 2)
        for f in fn.build_median(fish, *fn.MEDIAN_DETAIL[1])
    )
    assert set(fj[-n_med:].tolist()) <= {j for j in range(len(fish)) if fish.kind[j] == "spine"}
    assert np.array_equal(b.joints[-n_med:, 0], fj[-n_med:])
    p = export(fish, tmp_path / "fish.glb", skin=True)
    assert p.stat().st_size > 0
    try:
        from tests.gltf_validator import assert_valid_glb
    except ImportError:  # pragma: no cover
        return
    assert_valid_glb(p)


def test_tetrapods_have_no_median_fins():
    for seed, kw in ((7, {"legs": 4}), (3, {"cls": "bird"}), (1, {"cls": "reptile"})):
        c = generate(seed, **kw)
        assert fn.build_median(c) == []
        assert len(skin.fin_skin(c, 1)[0]) == 0
