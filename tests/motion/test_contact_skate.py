"""Issue 15 foot-skate targets: locking never leaves a clip skating more than its input, the
compiled leg-chain kinematics agree with the full forward kinematics, and the held height
of a contact is where the point rests on the floor."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import biomorph.motion as bm
from biomorph.io.bvh import read_bvh
from biomorph.motion import contact as C
from biomorph.motion.quality import foot_skate
from biomorph.motion.synthetic import walk
from tests.conftest import shared_file


def _skate(m):
    return foot_skate(m)["skate_per_body_scale"]


def _lock(m, ref=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", C.ContactWarning)
        return C.lock_feet(m, ref)


@pytest.fixture(scope="module")
def slid():
    """The built-in walk with a slide injected: the hips pushed back and forth (5 cm along
    the walk at 1.7 Hz, 3 cm sideways at 0.9 Hz), so every planted foot slides."""
    return _slide(walk(480, 60))


def _slide(m):
    t = np.arange(m.n_frames) / m.fps
    rp = np.array(m.root_position)
    rp[:, 2] += 0.05 * np.sin(2 * np.pi * 1.7 * t)
    rp[:, 0] += 0.03 * np.sin(2 * np.pi * 0.9 * t + 1.0)
    return m.with_(root_position=rp)


def _planted_speed(m, contacts):
    w = m.world_positions()
    v = []
    for j, on in contacts.items():
        idx = np.flatnonzero(on[1:] & on[:-1])
        v.append(np.linalg.norm(np.diff(w[:, j], axis=0)[idx][:, [0, 2]], axis=1).mean())
    return float(np.mean(v))


def test_locking_a_walk_with_injected_slide_lowers_its_skate(slid):
    locked = _lock(slid)
    assert _skate(locked) < _skate(slid)
    c = C.detect_contacts(slid)
    assert len(c) == 4
    # the built-in walk stands on straight knees: the held targets are often just out of
    # the leg's reach (clamped), so planted points keep ~1/6 of their slide (measured 0.17)
    assert _planted_speed(locked, c) < 0.3 * _planted_speed(slid, c)


@pytest.mark.parametrize(("fps", "speed", "stride_hz"), [(24, 1.2, 0.9), (120, 2.5, 1.4)])
def test_locking_holds_across_frame_rates_and_gaits(fps, speed, stride_hz):
    m = walk(8 * fps, fps, speed=speed, stride_hz=stride_hz, noise_deg=0.5)
    t = np.arange(m.n_frames) / m.fps
    rp = np.array(m.root_position)
    rp[:, 2] += 0.05 * np.sin(2 * np.pi * 1.7 * t)
    s = m.with_(root_position=rp)
    base = _skate(s)
    assert _skate(_lock(s)) < base
    assert _skate(_lock(bm.equalize(s, [0, 0.5, 1, 1, 1]), s)) <= base
    assert _skate(_lock(bm.blend([s, s[m.n_frames // 3 :]], transition=fps // 4))) <= base


def test_operators_with_locking_stay_at_or_below_the_slid_input(slid):
    base = _skate(slid)
    e = bm.equalize(slid, [0, 0.5, 1, 1, 1])
    assert _skate(_lock(e, slid)) <= base
    e2 = bm.equalize(slid, [1, 1.5, 1.5, 1, 1])
    assert _skate(_lock(e2, slid)) <= base
    b = bm.blend([slid, slid[160:]], transition=30)
    assert _skate(_lock(b)) <= base


def test_an_operator_cannot_lower_a_foot_near_the_floor(slid):
    # the hips 3 cm lower for the whole clip: every foot would run 3 cm lower
    low = slid.with_(root_position=slid.root_position - [0.0, 0.03, 0.0])
    out = _lock(low, slid)
    c = C.detect_contacts(slid)
    blend = round(0.2 * slid.fps)
    w_in, w_low, w_out = slid.world_positions(), low.world_positions(), out.world_positions()
    checked = 0
    for lg in C.find_legs(slid):
        on = c[lg.ankle] | c[lg.toe]  # the leg's contacts (a held heel carries the toe)
        near_contact = np.convolve(on, np.ones(2 * blend + 3), mode="same") > 0
        foot = np.linalg.norm(slid.skeleton.offset[lg.toe])
        for j in (lg.ankle, lg.toe):
            h = w_in[:, j, 1]
            free = ~near_contact & (h < np.percentile(h, 2) + 0.5 * foot)
            assert (w_low[free, j, 1] < h[free] - 0.02).all()  # the operator lowered them
            assert (w_out[free, j, 1] >= h[free] - 1e-6).all()  # locking kept the clearance
            checked += int(free.sum())
    # the built-in walk plants its feet (issue 15): a foot is low away from a contact's
    # fades only at the clip's ends now (4 frames; the skating walk had > 20)
    assert checked > 0


def test_contact_cut_by_the_clip_start_is_held_where_it_meets_the_clip():
    f = 40
    pts = np.zeros((f, 3))
    pts[:, 2] = np.linspace(0.0, 0.2, f)  # sliding from the first frame on
    on = np.zeros(f, bool)
    on[:20] = True
    tgt, _ = C._targets(on, pts, 4, 1)
    # the place comes from the contact's last 4 frames (16-19), not from frames 0-19
    assert pts[16, 2] <= tgt[0, 2] <= pts[19, 2]
    on[:] = False
    on[25:] = True  # cut by the clip's end: its first 4 frames
    tgt, _ = C._targets(on, pts, 4, 1)
    assert pts[25, 2] <= tgt[-1, 2] <= pts[28, 2]


def test_contact_plot_is_written(tmp_path, slid):
    from biomorph.motion.plots import plot_contacts

    m = slid[:120]
    out = plot_contacts(m, tmp_path / "c.png", _lock(m))
    assert out.stat().st_size > 10_000 and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_fade_out_ends_where_the_point_reaches_swing_speed():
    f = 40
    pts = np.zeros((f, 3))
    on = np.zeros(f, bool)
    on[10:20] = True
    swing = np.zeros(f, bool)
    swing[23:] = True  # full swing from the 4th frame after the contact
    _, w_full = C._targets(on, pts, 6, 1)
    _, w_cut = C._targets(on, pts, 6, 1, swing=swing)
    assert (w_full[20:26] > 0).all() and (w_cut[23:] == 0).all()
    assert (np.diff(w_cut[19:24]) < 0).all()  # still a smooth release over frames 20-22
    assert (w_cut[:20] == w_full[:20]).all()  # the fade-in is untouched


def test_held_height_is_the_lowest_of_the_contact():
    f = 40
    pts = np.zeros((f, 3))
    pts[:, 1] = 0.02 + 0.01 * np.sin(np.arange(f))  # a contact floating 1-3 cm up
    pts[:, 2] = np.linspace(0.0, 0.05, f)  # and sliding 5 cm
    on = np.zeros(f, bool)
    on[10:30] = True
    tgt, wgt = C._targets(on, pts, 4, 1)
    assert np.allclose(tgt[10:30, 1], pts[10:30, 1].min())
    assert np.ptp(tgt[10:30], axis=0).max() == 0.0  # one place for the whole contact
    assert (wgt[10:30] == 1).all() and wgt[5] == 0 and 0 < wgt[8] < 1


@pytest.mark.parametrize("translated", [False, True])
def test_leg_chain_kinematics_match_the_full_forward_kinematics(translated):
    m = walk(200, 60, noise_deg=2.0)
    if translated:  # position channels on inner joints (BVH 6-channel joints, HTR)
        jt = np.array(m.local_translations())
        jt[:, 1:] *= 1.0 + 0.1 * np.sin(np.arange(m.n_frames))[:, None, None]
        m = m.with_(joint_translation=jt)
    legs = C.find_legs(m)
    chain = C._leg_chain(m, legs)
    pos, quat = C._chain_fk(m, chain)
    full_p, full_q = m.world_positions(), m.world_rotations()
    assert np.abs(pos - full_p[:, chain]).max() < 1e-12
    assert np.abs(np.abs(np.sum(quat * full_q[:, chain], axis=-1)) - 1).max() < 1e-12
    assert set(C.detect_contacts(m)) == set(C.detect_contacts(m, world=full_p))


def _shared(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_bvh(shared_file("motion", name))


def test_dme_raw_clip_cleans_toward_its_fixed_counterpart():
    raw = _shared("dme_comp_3d_2_raw.bvh")
    fixed = _shared("dme_comp_3d_2_fixed.bvh")
    cleaned = _skate(_lock(raw))
    # measured: raw 0.874 -> 0.534 hip heights/s (0.573 before the fade-out ended at the
    # swing, 0.654 before that); the authors' fixed file is 0.571 (issue 15 target: at or below)
    assert cleaned <= _skate(fixed)
    assert cleaned < 0.7 * _skate(raw)
    # summed over the band the cleaned feet travel less than the fixed file's (1.28 vs 1.50)
    assert foot_skate(_lock(raw))["band_travel"] < foot_skate(fixed)["band_travel"]
    assert _skate(_lock(fixed)) <= _skate(fixed)
    for gains in ([0, 0.5, 1, 1, 1], [1, 1.5, 1.5, 1, 1]):
        assert _skate(_lock(bm.equalize(raw, gains), raw)) <= _skate(raw)


def test_a_foot_joint_below_the_ankle_is_part_of_that_foot():
    # the HTR character's R_ankle -> R_football -> R_toe: two legs, not four
    import biomorph as bm

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = bm.io.read_motion(shared_file("motion", "animal3d_egnaro_skel_anim.htr"))
    legs = C.find_legs(m)
    assert sorted((m.names[lg.knee], m.names[lg.ankle], m.names[lg.toe]) for lg in legs) == [
        ("L_knee", "L_ankle", "L_football"),
        ("R_knee", "R_ankle", "R_football"),
    ]


def test_short_runs_are_dropped_like_the_run_list_says():
    rng = np.random.default_rng(0)
    for _ in range(100):
        on = rng.random(int(rng.integers(1, 60))) < 0.6
        min_len = int(rng.integers(1, 6))
        ref = on.copy()
        for s, e in C._runs(ref):
            if e - s < min_len:
                ref[s:e] = False
        assert (C._drop_short(on, min_len) == ref).all()


def test_compiled_median_equals_numpy():
    rng = np.random.default_rng(1)
    for n in [*range(1, 25), 100, 101]:
        for k in range(6):
            x = rng.random(n) if k % 2 else rng.integers(0, 4, n).astype(float)  # ties
            assert C._median(x.copy()) == np.median(x)


# --------------------------------------------------------------------------- no jumps
def _worst_jump(m, out):
    """How far (body scales/s) one frame's step of a knee, ankle or toe exceeds both its
    neighbours' steps in ``out``: a one-frame pop scores its size, a fast but smooth motion
    (even a quick fade) scores about 0."""
    w = out.world_positions()
    js = sorted({j for lg in C.find_legs(m) for j in (lg.knee, lg.ankle, lg.toe) if j >= 0})
    s = np.linalg.norm(np.diff(w[:, js], axis=0), axis=2)
    return float((s[1:-1] - np.maximum(s[:-2], s[2:])).max() * m.fps / foot_skate(m)["body_scale"])


def test_locking_the_built_in_walk_never_jumps():
    # stiff knees: its held heels go out of reach before toe-off; the switch to the toe
    # on one frame was a 7.9 body scales/s pop (frame 32), now 3.9 at most (the knee
    # straightening at the reach boundary), the capture's own frame-to-frame variation 1.0
    m = walk(480, 120)
    assert _worst_jump(m, _lock(m)) < 5.0


def test_held_ankle_out_of_reach_hands_over_to_the_toe_without_a_jump():
    m = read_bvh(shared_file("motion", "xia_neutral_01_000_walk.bvh"))
    out = _lock(m)
    # the held left heel was 6.7 % beyond the leg at frame 158 and the goal switched to the
    # toe on frame 159: the toe moved 7.5 body scales/s more than in the frames around it
    assert _worst_jump(m, out) < 1.5
    lg = next(lg for lg in C.find_legs(m) if m.names[lg.ankle] == "LeftFoot")
    w = out.world_positions()
    step = np.linalg.norm(np.diff(w[150:170, lg.ankle], axis=0), axis=1)
    assert step.max() < 0.3  # units per frame (was 1.1 at frame 158 -> 159)


def test_overlapping_fades_move_the_held_place_across_the_gap():
    # two contacts 6 frames apart with 8-frame fades: the held place used to switch to the
    # nearer contact mid-gap at a weight near 1 (cmu_01_01's right toe: 4.2 units in frame 1163)
    f = 50
    pts = np.zeros((f, 3))
    pts[:, 2] = np.linspace(0.0, 10.0, f)
    on = np.zeros(f, bool)
    on[5:20] = on[26:45] = True
    tgt, wgt = C._targets(on, pts, 8, 1)
    held = tgt * wgt[:, None]
    gap = np.abs(np.diff(held[18:29, 2]))
    assert gap.max() < 0.5 * abs(tgt[26, 2] - tgt[19, 2])
    assert (wgt[19:27] > 0).all()


def test_soft_ik_is_continuous_at_full_extension():
    f = 201
    hip = np.zeros((f, 3))
    knee = np.tile([0.0, -1.0, 0.05], (f, 1))
    ankle = np.tile([0.0, -2.0, 0.0], (f, 1))
    tgt = np.column_stack([np.zeros(f), -np.linspace(1.9, 2.1, f), np.zeros(f)])  # through L
    for soft in (0.0, 0.005):
        r1, r2, _ = C.two_bone_ik(hip, knee, ankle, tgt, soft=soft)
        from biomorph.core import transforms as tf

        k = tf.quat_rotate(r1, knee - hip)
        step = np.linalg.norm(np.diff(k, axis=0), axis=1)
        if soft:  # the knee's step never grows by more than 2x from one frame to the next
            assert (step[1:] <= 2.0 * step[:-1] + 1e-12).all()
            a = k + tf.quat_rotate(r2, tf.quat_rotate(r1, ankle - knee))
            assert np.abs(np.linalg.norm(a, axis=1) - np.minimum(-tgt[:, 1], 2.0)).max() < 0.01
        else:  # hard clamp: the knee snaps (its last step before full extension is the largest)
            assert step.max() > 5 * np.median(step[step > 0])
