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
    pts = np.concatenate([fin.rays.reshape(-1, 3) for fin in built])
    jnt = np.concatenate([np.tile(fin.joint_of, len(fin.rays)) for fin in built])
    d = np.linalg.norm(fv[:, None] - pts[None], axis=2)
    nearest = jnt[d.argmin(axis=1)]
    assert (nearest == fj).mean() > 0.95
    assert set(fj.tolist()) == {j for fin in built for j in fin.joints}
