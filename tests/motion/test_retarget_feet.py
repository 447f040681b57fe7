"""Issue 15, retargeting onto feet proportioned otherwise (a creature's foot 2-2.5× longer
relative to its leg): the legs follow the source's foot paths, not only its angles, and the
pelvic girdle between hips and thigh takes the source's hip → thigh direction."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from biomorph.core.skeleton import JointSkeleton
from biomorph.motion import names as nm
from biomorph.motion.contact import foot_floor
from biomorph.motion.retarget import FOOT_RATIO, retarget
from biomorph.motion.synthetic import walk


def _long_feet(sk: JointSkeleton, k: float = 2.5, girdle: bool = False) -> JointSkeleton:
    """``sk`` renamed Mixamo-style, 0.8× the size, its toes ``k``× as far from the ankles;
    with ``girdle`` an unmapped joint between the hips and each thigh whose rest bone points
    *up* (as the generated creature's: every rest bone along +y)."""
    off = np.array(sk.offset, dtype=float) * 0.8
    names = ["mixamorig:" + n for n in sk.names]
    for i, n in enumerate(sk.names):
        if "toe" in n.lower():
            off[i] *= k
    parent = np.array(sk.parent)
    if not girdle:
        return JointSkeleton(names, parent, off)
    thighs = [i for i, n in enumerate(sk.names) if n in ("LeftUpLeg", "RightUpLeg")]
    names2, par2, off2 = list(names), list(parent), list(off)
    for t in thighs:  # girdle_x: child of the hips, the thigh's parent, bone straight up
        g = len(names2)
        names2.append(f"girdle_{'l' if 'Left' in sk.names[t] else 'r'}")
        par2.append(int(parent[t]))
        off2.append(np.zeros(3))
        par2[t] = g
        off2[t] = np.array([0.0, np.linalg.norm(off[t]), 0.0])
    # parents must come first: move the girdles in front of their thighs
    order = list(range(len(names2)))
    for t in sorted(thighs, reverse=True):
        g = names2.index(f"girdle_{'l' if 'Left' in sk.names[t] else 'r'}")
        order.remove(g)
        order.insert(order.index(t), g)
    where = {o: i for i, o in enumerate(order)}
    return JointSkeleton(
        [names2[o] for o in order],
        np.array([where[par2[o]] if par2[o] >= 0 else -1 for o in order]),
        np.array([off2[o] for o in order]),
    )


@pytest.fixture(scope="module")
def clip():
    return walk(480, 120, n_joints=31, noise_deg=0.0)


def _heights(m, names):
    w = m.world_positions()
    return {c: w[:, i, 1] for c, i in names.items()}


def test_long_feet_follow_the_source_foot_heights(clip):
    # at the source's angles a 2.5× foot put the toe 2.5× as far below the ankle; the toe's
    # height is now the source's (scaled), the ankle's too, up to the rig's constant offset
    tgt = _long_feet(clip.skeleton)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = retarget(clip, tgt, feet=False)
        old = _angles_only(clip, tgt)
    assert out.meta["retarget"]["legs"] == "source's foot paths"
    sc = out.meta["retarget"]["leg_scale"]
    s_map = nm.resolve(clip.names, nm.detect_preset(clip.names), clip.skeleton.parent)
    t_map = nm.resolve(out.names, nm.detect_preset(out.names), out.skeleton.parent)
    fl = foot_floor(clip)
    hs = {c: (h - fl) * sc for c, h in _heights(clip, s_map).items()}
    ht, ho = _heights(out, t_map), _heights(old, t_map)
    leg = 0.8 * sum(
        float(np.linalg.norm(clip.skeleton.offset[s_map[c]])) for c in ("l_shin", "l_foot")
    )
    for side in "lr":
        a, t = f"{side}_foot", f"{side}_toe"
        off = np.median(ht[a] - hs[a])
        assert np.abs(ht[a] - hs[a] - off).max() < 0.01 * leg  # the ankle's path
        assert np.abs(ht[t] - hs[t] - off).max() < 0.01 * leg  # the toe's height
        # the angle-only retarget's toe dipped below the ankle by 2.5× the source's drop
        drop_src = np.median(hs[a] - hs[t])
        assert np.median(ho[a] - ho[t]) > 2.0 * drop_src
        assert abs(np.median(ht[a] - ht[t]) - drop_src) < 0.01 * leg


def _angles_only(clip, tgt):
    import biomorph.motion.retarget as rt

    saved = rt.FOOT_RATIO
    rt.FOOT_RATIO = 1e9  # the angle-only path (feet "alike")
    try:
        return retarget(clip, tgt, feet=False)
    finally:
        rt.FOOT_RATIO = saved


def test_feet_alike_keep_the_source_angles_bit_for_bit(clip):
    # a Mixamo-named 0.8× copy (feet alike): the angle path, unchanged
    tgt = _long_feet(clip.skeleton, k=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = retarget(clip, tgt, feet=False)
    assert out.meta["retarget"]["legs"] == "source's angles"
    assert FOOT_RATIO == 1.5


def test_the_toe_does_not_jump_where_the_foot_points_down(clip):
    # the heading comes from the foot's lateral axis, not from the foot vector's horizontal
    # part (which flips where the foot passes the vertical): no toe speed spike above the
    # source's own (scaled) toe speed
    tgt = _long_feet(clip.skeleton)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = retarget(clip, tgt, feet=False)
    sc = out.meta["retarget"]["leg_scale"]
    s_map = nm.resolve(clip.names, nm.detect_preset(clip.names), clip.skeleton.parent)
    t_map = nm.resolve(out.names, nm.detect_preset(out.names), out.skeleton.parent)
    ws, wt = clip.world_positions(), out.world_positions()
    for side in "lr":
        vs = np.linalg.norm(np.diff(ws[:, s_map[f"{side}_toe"]][:, [0, 2]], axis=0), axis=1) * sc
        vt = np.linalg.norm(np.diff(wt[:, t_map[f"{side}_toe"]][:, [0, 2]], axis=0), axis=1)
        assert vt.max() < 3.0 * vs.max()


def test_an_unmapped_girdle_takes_the_source_hip_direction(clip):
    # the generated biped's girdle (rest bone along +y, unmapped) put both hip sockets on one
    # point above the pelvis; now each socket lies where the source's hip → thigh points
    tgt = _long_feet(clip.skeleton, girdle=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = retarget(clip, tgt, feet=False)
    w = out.world_positions()
    li, ri = out.names.index("mixamorig:LeftUpLeg"), out.names.index("mixamorig:RightUpLeg")
    hips = out.names.index("mixamorig:Hips")
    ws = clip.world_positions()
    sl, sr, sh = clip.names.index("LeftUpLeg"), clip.names.index("RightUpLeg"), 0
    gap_t = np.linalg.norm(w[:, li] - w[:, ri], axis=1)
    gap_s = np.linalg.norm(ws[:, sl] - ws[:, sr], axis=1)
    assert np.allclose(gap_t, 0.8 * gap_s, rtol=0.02)
    assert np.all(w[:, li, 1] < w[:, hips, 1]) and np.all(ws[:, sl, 1] < ws[:, sh, 1])


def test_the_target_stands_on_the_floor(clip):
    # a rig whose hip sockets sit higher relative to its hips than the source's floated by
    # the difference (the Mixamo-named Rokoko rig under cmu / Xia walks: 10-15 % of its hip
    # height); its own lowest foot is now on y = 0, as the source's floor was
    from biomorph.core.skeleton import JointSkeleton

    sk = clip.skeleton
    off = np.array(sk.offset, dtype=float) * 0.8
    hips_kids = [i for i, n in enumerate(sk.names) if n in ("LeftUpLeg", "RightUpLeg")]
    off[hips_kids, 1] += 0.3 * np.abs(off[hips_kids]).max()  # sockets higher on the hips
    tgt = JointSkeleton(["mixamorig:" + n for n in sk.names], sk.parent, off)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for feet in (False, True):
            out = retarget(clip, tgt, feet=feet)
            assert foot_floor(out) == pytest.approx(0.0, abs=1e-9)
