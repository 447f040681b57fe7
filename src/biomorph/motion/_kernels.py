"""Compiled inner loops of the motion operators (numba, cached).

Quaternions are scalar-last ``(x, y, z, w)`` as everywhere in biomorph. These kernels do
per-element work that NumPy would spread over many temporary arrays (slerp, log/exp maps,
the equalizer's per-joint pipeline); each loops over frames × joints once.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

# Kernels the Motion type itself needs live in core (re-exported here for the operators).
from biomorph.core._motion_kernels import (  # noqa: F401
    _qmul,
    _qrot,
    _slerp,
    _store_continuous,
    fk_positions,
    sample_slerp,
)
from biomorph.core.motion import ro, ro_int  # noqa: F401


@njit(cache=True, inline="always")
def _idx(j, f, mode):  # pragma: no cover - compiled
    if f == 1:
        return 0
    if mode == 0:
        return 0 if j < 0 else (f - 1 if j > f - 1 else j)
    period = 2 * (f - 1)
    j = abs(j) % period
    return period - j if j > f - 1 else j


@njit("void(float64[::1], float64[::1], int64, int64)", cache=True)
def lowpass_into(cur, nxt, step, mode):  # pragma: no cover - compiled
    """One à-trous low-pass level. Explicit signature: one compiled version for every caller
    (a literal ``step = 1`` inside a kernel would otherwise compile a second one)."""
    f = cur.size
    lo = min(2 * step, f)
    hi = max(f - 2 * step, lo)
    if hi > lo:
        # interior: the five taps as shifted views indexed from 0, so the loop index is
        # provably non-negative (no negative-index wraparound test per access) and the loop
        # vectorises; same expression, same rounding as the per-index form (11x faster)
        c0 = cur[lo:hi]
        cm1 = cur[lo - step : hi - step]
        cp1 = cur[lo + step : hi + step]
        cm2 = cur[lo - 2 * step : hi - 2 * step]
        cp2 = cur[lo + 2 * step : hi + 2 * step]
        dst = nxt[lo:hi]
        for i in range(hi - lo):
            dst[i] = 0.375 * c0[i] + 0.25 * (cm1[i] + cp1[i]) + 0.0625 * (cm2[i] + cp2[i])
    for i in range(0, lo):
        nxt[i] = (
            0.375 * cur[i]
            + 0.25 * (cur[_idx(i - step, f, mode)] + cur[_idx(i + step, f, mode)])
            + 0.0625 * (cur[_idx(i - 2 * step, f, mode)] + cur[_idx(i + 2 * step, f, mode)])
        )
    for i in range(hi, f):
        nxt[i] = (
            0.375 * cur[i]
            + 0.25 * (cur[_idx(i - step, f, mode)] + cur[_idx(i + step, f, mode)])
            + 0.0625 * (cur[_idx(i - 2 * step, f, mode)] + cur[_idx(i + 2 * step, f, mode)])
        )


@njit(cache=True, inline="always")
def _filter_rows(xs, out, gains, mode, cur, nxt):  # pragma: no cover - compiled
    """The telescoped filter bank on every row of ``xs (c, f)`` into ``out``:
    ``g0·G0 + Σ (g_k − g_{k−1}) G_k``; ``cur``/``nxt`` are ``(f,)`` work buffers."""
    f = xs.shape[1]
    levels = gains.size - 1
    for ch in range(xs.shape[0]):
        for i in range(f):
            cur[i] = xs[ch, i]
            out[ch, i] = gains[0] * cur[i]
        step = 1
        for k in range(levels):
            lowpass_into(cur, nxt, step, mode)
            dg = gains[k + 1] - gains[k]
            if dg != 0.0:
                for i in range(f):
                    out[ch, i] += dg * nxt[i]
            cur, nxt = nxt, cur
            step *= 2


@njit(cache=True)
def equalize_rows(xt, gains, mode, out):  # pragma: no cover - compiled
    """Equalize every row of ``xt (c, f)`` into ``out``: g0·G0 + Σ (g_k − g_{k−1}) G_k."""
    f = xt.shape[1]
    _filter_rows(xt, out, gains, mode, np.empty(f), np.empty(f))


@njit(cache=True, inline="always")
def _qlog(x, y, z, w):  # pragma: no cover - compiled
    """Rotation vector (angle in [0, pi]) of a unit quaternion.

    Small rotations (|v| < 0.1 w, i.e. below ~11°, the usual case relative to a smooth
    reference) use the series 2·atan(t)/t = 2(1 − t²/3 + t⁴/5 − …), t = |v|/w, to 17th order
    (error < 1e-18) instead of atan2; larger ones call atan2."""
    if w < 0:
        x, y, z, w = -x, -y, -z, -w
    s2 = x * x + y * y + z * z
    if s2 < 0.01 * w * w:
        u = s2 / (w * w)
        p = 1.0 / 17.0
        p = 1.0 / 15.0 - u * p
        p = 1.0 / 13.0 - u * p
        p = 1.0 / 11.0 - u * p
        p = 1.0 / 9.0 - u * p
        p = 1.0 / 7.0 - u * p
        p = 1.0 / 5.0 - u * p
        p = 1.0 / 3.0 - u * p
        p = 1.0 - u * p
        k = 2.0 * p / w
        return k * x, k * y, k * z
    s = np.sqrt(s2)
    k = 2.0 * np.arctan2(s, w) / s
    return k * x, k * y, k * z


@njit(cache=True, inline="always")
def _qexp(rx, ry, rz):  # pragma: no cover - compiled
    """Unit quaternion of a rotation vector; half angles below 0.5 rad (rotations below 57°)
    use the Taylor series of cos(h) and sin(h)/h to h^14 (truncation < h^16/16! < 1e-18,
    below double rounding), larger ones sin/cos."""
    a2 = rx * rx + ry * ry + rz * rz
    u = 0.25 * a2  # (a/2)^2
    if u < 0.25:
        c = 1.0 - u / 182.0
        c = 1.0 - u / 132.0 * c
        c = 1.0 - u / 90.0 * c
        c = 1.0 - u / 56.0 * c
        c = 1.0 - u / 30.0 * c
        c = 1.0 - u / 12.0 * c
        c = 1.0 - u / 2.0 * c  # cos(h) to h^14
        sh = 1.0 - u / 210.0
        sh = 1.0 - u / 156.0 * sh
        sh = 1.0 - u / 110.0 * sh
        sh = 1.0 - u / 72.0 * sh
        sh = 1.0 - u / 42.0 * sh
        sh = 1.0 - u / 20.0 * sh
        sh = 1.0 - u / 6.0 * sh  # sin(h)/h to h^14
        k = 0.5 * sh
        return k * rx, k * ry, k * rz, c
    a = np.sqrt(a2)
    k = np.sin(0.5 * a) / a
    return k * rx, k * ry, k * rz, np.cos(0.5 * a)


@njit(cache=True)
def blend_slerp(qa, qb, wb, out):  # pragma: no cover - compiled
    """``out[k, j] = slerp(qa[k, j], qb[k, j], wb[k])``, hemisphere-continuous along k."""
    for k in range(qa.shape[0]):
        t = wb[k]
        for j in range(qa.shape[1]):
            x, y, z, w = _slerp(
                qa[k, j, 0],
                qa[k, j, 1],
                qa[k, j, 2],
                qa[k, j, 3],
                qb[k, j, 0],
                qb[k, j, 1],
                qb[k, j, 2],
                qb[k, j, 3],
                t,
            )
            _store_continuous(out, k, j, x, y, z, w)


@njit(cache=True)
def _box_edge4(src, dst, r):  # pragma: no cover - compiled
    """Centred moving average of width 2r+1 with edge hold over the four columns of
    ``src (f, 4)`` at once (one running sum per column)."""
    f = src.shape[0]
    if r == 0:
        for i in range(f):
            for c in range(4):
                dst[i, c] = src[i, c]
        return
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    for m in range(-r, r + 1):
        k = min(max(m, 0), f - 1)
        a0 += src[k, 0]
        a1 += src[k, 1]
        a2 += src[k, 2]
        a3 += src[k, 3]
    inv = 1.0 / (2 * r + 1)
    for i in range(f):
        dst[i, 0] = a0 * inv
        dst[i, 1] = a1 * inv
        dst[i, 2] = a2 * inv
        dst[i, 3] = a3 * inv
        hi = min(i + r + 1, f - 1)
        lo = max(i - r, 0)
        a0 += src[hi, 0] - src[lo, 0]
        a1 += src[hi, 1] - src[lo, 1]
        a2 += src[hi, 2] - src[lo, 2]
        a3 += src[hi, 3] - src[lo, 3]


MEAN_LOG_COS = 0.7071067811865476  #: cos(45°): the mean-log path needs angles ≤ 90° about M


@njit(cache=True, error_model="numpy")  # no zero-division checks: vectorises
def _log_about(mx, my, mz, mw, qs, xs, big):  # pragma: no cover - compiled
    """``xs[:, i] = log(M⁻¹ q_i)`` for the quaternions ``qs (4, f)`` (rows x, y, z, w).

    The series branch of :func:`_qlog` is evaluated for every frame without branches (the
    hemisphere sign as a product by ±1, exact), so the loop vectorises; frames outside the
    series' range (``big``) are redone with :func:`_qlog` itself. Same bits as calling
    :func:`_qlog` on every frame."""
    f = qs.shape[1]
    q0, q1, q2, q3 = qs[0], qs[1], qs[2], qs[3]
    x0, x1, x2 = xs[0], xs[1], xs[2]
    nbig = 0
    for i in range(f):
        a, b, cc, d = _qmul(-mx, -my, -mz, mw, q0[i], q1[i], q2[i], q3[i])
        sg = 1.0 - 2.0 * (d < 0)  # -1 or 1 without a branch (vectorises)
        a = a * sg
        b = b * sg
        cc = cc * sg
        d = d * sg
        s2 = a * a + b * b + cc * cc
        u = s2 / (d * d)
        p = 1.0 / 17.0
        p = 1.0 / 15.0 - u * p
        p = 1.0 / 13.0 - u * p
        p = 1.0 / 11.0 - u * p
        p = 1.0 / 9.0 - u * p
        p = 1.0 / 7.0 - u * p
        p = 1.0 / 5.0 - u * p
        p = 1.0 / 3.0 - u * p
        p = 1.0 - u * p
        k = 2.0 * p / d
        x0[i] = k * a
        x1[i] = k * b
        x2[i] = k * cc
        far = not (s2 < 0.01 * d * d)
        big[i] = far
        nbig += far
    if nbig:
        for i in range(f):
            if big[i]:
                a, b, cc, d = _qmul(-mx, -my, -mz, mw, q0[i], q1[i], q2[i], q3[i])
                x0[i], x1[i], x2[i] = _qlog(a, b, cc, d)


@njit(cache=True, error_model="numpy")  # no zero-division checks: vectorises
def _exp_about(mx, my, mz, mw, xs, qs, big):  # pragma: no cover - compiled
    """``qs[:, i] = M · exp(xs[:, i])`` (not yet hemisphere-continuous): the series branch
    of :func:`_qexp` for every frame without branches (vectorises), frames outside its range
    redone with :func:`_qexp`. Same bits as calling :func:`_qexp` on every frame."""
    f = xs.shape[1]
    x0, x1, x2 = xs[0], xs[1], xs[2]
    q0, q1, q2, q3 = qs[0], qs[1], qs[2], qs[3]
    nbig = 0
    for i in range(f):
        rx, ry, rz = x0[i], x1[i], x2[i]
        a2 = rx * rx + ry * ry + rz * rz
        u = 0.25 * a2
        c = 1.0 - u / 182.0
        c = 1.0 - u / 132.0 * c
        c = 1.0 - u / 90.0 * c
        c = 1.0 - u / 56.0 * c
        c = 1.0 - u / 30.0 * c
        c = 1.0 - u / 12.0 * c
        c = 1.0 - u / 2.0 * c
        sh = 1.0 - u / 210.0
        sh = 1.0 - u / 156.0 * sh
        sh = 1.0 - u / 110.0 * sh
        sh = 1.0 - u / 72.0 * sh
        sh = 1.0 - u / 42.0 * sh
        sh = 1.0 - u / 20.0 * sh
        sh = 1.0 - u / 6.0 * sh
        k = 0.5 * sh
        x, y, z, w = _qmul(mx, my, mz, mw, k * rx, k * ry, k * rz, c)
        q0[i] = x
        q1[i] = y
        q2[i] = z
        q3[i] = w
        far = not (u < 0.25)
        big[i] = far
        nbig += far
    if nbig:
        for i in range(f):
            if big[i]:
                ex, ey, ez, ew = _qexp(x0[i], x1[i], x2[i])
                q0[i], q1[i], q2[i], q3[i] = _qmul(mx, my, mz, mw, ex, ey, ez, ew)


@njit(cache=True, inline="always")
def _store_joint_continuous(qs, out, j):  # pragma: no cover - compiled
    """``out[:, j] = ±qs.T`` with the sign of each frame chosen like
    :func:`_store_continuous` (the dot with the stored previous frame, ``s·d`` exactly)."""
    s = 1.0
    px, py, pz, pw = 0.0, 0.0, 0.0, 0.0
    for i in range(qs.shape[1]):
        x, y, z, w = qs[0, i], qs[1, i], qs[2, i], qs[3, i]
        if i > 0:
            s = -1.0 if s * (x * px + y * py + z * pz + w * pw) < 0 else 1.0
        px, py, pz, pw = x, y, z, w
        out[i, j, 0] = s * x
        out[i, j, 1] = s * y
        out[i, j, 2] = s * z
        out[i, j, 3] = s * w


@njit(cache=True, parallel=True)
def equalize_rotations(q, gains, mode, radius, out):  # pragma: no cover - compiled
    """The equalizer's rotation path for every joint of ``q (f, J, 4)`` (each joint's column
    is copied into a contiguous buffer first). Per joint, one of two parametrisations:

    * **mean-log** — when every frame is within 90° of the joint's mean orientation ``M``
      (normalised mean of the continuous quaternions): ``x = log(M⁻¹ q)``, all bands of x
      (the last gain on the remaining low-pass) filtered, ``out = M exp(x')``.
    * **reference** — otherwise (a joint turning far, e.g. the root's heading): reference
      ``R`` = normalised double box filter (radius ``radius``) of the continuous
      quaternions; ``x = log(R⁻¹ q)`` filtered; if the last gain is not 1,
      ``R' = M exp(g_K log(M⁻¹ R))`` (log unwrapped over time); ``out = R' exp(x')``.

    Output hemisphere-continuous."""
    f, nj = q.shape[0], q.shape[1]
    levels = gains.size - 1
    glast = gains[levels]
    for j in prange(nj):  # joints are independent: one per thread
        xs = np.empty((3, f))
        xo = np.empty((3, f))
        cur = np.empty(f)
        nxt = np.empty(f)
        qs = np.empty((4, f))  # the joint's column, one row per component (vectorisable)
        mx = 0.0
        my = 0.0
        mz = 0.0
        mw = 0.0
        for i in range(f):
            for c in range(4):
                qs[c, i] = q[i, j, c]
            mx += qs[0, i]
            my += qs[1, i]
            mz += qs[2, i]
            mw += qs[3, i]
        mn = np.sqrt(mx * mx + my * my + mz * mz + mw * mw)
        mean_log = mn > 0.5 * f
        if mean_log:
            mx /= mn
            my /= mn
            mz /= mn
            mw /= mn
            for i in range(f):
                d = abs(mx * qs[0, i] + my * qs[1, i] + mz * qs[2, i] + mw * qs[3, i])
                if d < MEAN_LOG_COS:
                    mean_log = False
                    break
        if mean_log:
            big = np.empty(f, dtype=np.bool_)
            _log_about(mx, my, mz, mw, qs, xs, big)
            _filter_rows(xs, xo, gains, mode, cur, nxt)
            _exp_about(mx, my, mz, mw, xo, qs, big)
            _store_joint_continuous(qs, out, j)
            continue
        qj = np.empty((f, 4))
        for i in range(f):
            for c in range(4):
                qj[i, c] = qs[c, i]
        tmp4 = np.empty((f, 4))
        ref = np.empty((f, 4))
        _box_edge4(qj, tmp4, radius)
        _box_edge4(tmp4, ref, radius)
        mx = 0.0
        my = 0.0
        mz = 0.0
        mw = 0.0
        for i in range(f):
            n = np.sqrt(ref[i, 0] ** 2 + ref[i, 1] ** 2 + ref[i, 2] ** 2 + ref[i, 3] ** 2)
            if n < 0.3:  # degenerate average (full turn inside the window): use the signal
                for c in range(4):
                    ref[i, c] = qj[i, c]
            else:
                for c in range(4):
                    ref[i, c] /= n
            mx += ref[i, 0]
            my += ref[i, 1]
            mz += ref[i, 2]
            mw += ref[i, 3]
            # x = log(conj(R) q)
            a, b, cc, d = _qmul(
                -ref[i, 0],
                -ref[i, 1],
                -ref[i, 2],
                ref[i, 3],
                qj[i, 0],
                qj[i, 1],
                qj[i, 2],
                qj[i, 3],
            )
            rx, ry, rz = _qlog(a, b, cc, d)
            xs[0, i] = rx
            xs[1, i] = ry
            xs[2, i] = rz
        _filter_rows(xs, xo, gains, mode, cur, nxt)
        scale_ref = glast != 1.0
        if scale_ref:
            mn = np.sqrt(mx * mx + my * my + mz * mz + mw * mw)
            if mn > 1e-12:
                mx /= mn
                my /= mn
                mz /= mn
                mw /= mn
            else:
                mx, my, mz, mw = 0.0, 0.0, 0.0, 1.0
        px, py, pz = 0.0, 0.0, 0.0  # previous unwrapped log(M⁻¹R)
        ox, oy, oz, ow = 0.0, 0.0, 0.0, 0.0  # previous output (continuity, in registers)
        for i in range(f):
            rx_, ry_, rz_, rw_ = ref[i, 0], ref[i, 1], ref[i, 2], ref[i, 3]
            if scale_ref:
                # R' = M exp(g_K u), u = log(M⁻¹R) unwrapped over time
                a, b, cc, d = _qmul(-mx, -my, -mz, mw, rx_, ry_, rz_, rw_)
                ux, uy, uz = _qlog(a, b, cc, d)
                # u + 2πk·û is the same rotation; keep the representative nearest the
                # previous frame (a joint may turn past 180°). When |u − p| ≤ π, u itself is
                # the nearest (every other candidate is 2π from u), so the search is skipped
                dd0 = (ux - px) ** 2 + (uy - py) ** 2 + (uz - pz) ** 2
                if i > 0 and dd0 > np.pi * np.pi:
                    ang = np.sqrt(ux * ux + uy * uy + uz * uz)
                    if ang > 1e-9:
                        nx, ny, nz = ux / ang, uy / ang, uz / ang
                        best = dd0
                        bx, by, bz = ux, uy, uz
                        for kk in (-2, -1, 1, 2):
                            cx = ux + 2 * np.pi * kk * nx
                            cy = uy + 2 * np.pi * kk * ny
                            cz = uz + 2 * np.pi * kk * nz
                            dd = (cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2
                            if dd < best:
                                best = dd
                                bx, by, bz = cx, cy, cz
                        ux, uy, uz = bx, by, bz
                px, py, pz = ux, uy, uz
                ex, ey, ez, ew = _qexp(glast * ux, glast * uy, glast * uz)
                rx_, ry_, rz_, rw_ = _qmul(mx, my, mz, mw, ex, ey, ez, ew)
            ex, ey, ez, ew = _qexp(xo[0, i], xo[1, i], xo[2, i])
            x, y, z, w = _qmul(rx_, ry_, rz_, rw_, ex, ey, ez, ew)
            if i > 0 and (x * ox + y * oy + z * oz + w * ow) < 0:
                x, y, z, w = -x, -y, -z, -w
            ox, oy, oz, ow = x, y, z, w
            out[i, j, 0] = x
            out[i, j, 1] = y
            out[i, j, 2] = z
            out[i, j, 3] = w


@njit(cache=True)
def blend_average(q, w, out):  # pragma: no cover - compiled
    """Normalised weighted quaternion average of N clips: ``q (N, f, n, 4)``, weights
    ``w (f, N)``; signs aligned to the heaviest clip; exact copy where a weight is 1;
    hemisphere-continuous along f."""
    nc, f, nj = q.shape[0], q.shape[1], q.shape[2]
    for k in range(f):
        h = 0
        for i in range(1, nc):
            if w[k, i] > w[k, h]:
                h = i
        for j in range(nj):
            rx, ry, rz, rw = q[h, k, j, 0], q[h, k, j, 1], q[h, k, j, 2], q[h, k, j, 3]
            if w[k, h] == 1.0:
                x, y, z, ww = rx, ry, rz, rw
            else:
                x = 0.0
                y = 0.0
                z = 0.0
                ww = 0.0
                for i in range(nc):
                    wi = w[k, i]
                    if wi == 0.0:
                        continue
                    d = (
                        q[i, k, j, 0] * rx
                        + q[i, k, j, 1] * ry
                        + q[i, k, j, 2] * rz
                        + q[i, k, j, 3] * rw
                    )
                    s = wi if d >= 0 else -wi
                    x += s * q[i, k, j, 0]
                    y += s * q[i, k, j, 1]
                    z += s * q[i, k, j, 2]
                    ww += s * q[i, k, j, 3]
                nrm = np.sqrt(x * x + y * y + z * z + ww * ww)
                x, y, z, ww = x / nrm, y / nrm, z / nrm, ww / nrm
            _store_continuous(out, k, j, x, y, z, ww)


@njit(cache=True)
def blend_average_sampled(rot, start, length, i0, frac, w, out):  # pragma: no cover - compiled
    """:func:`blend_average` fused with the slerp sampling of each clip.

    ``rot (F, n, 4)`` holds the clips' rotations one after another (clip ``i`` at rows
    ``start[i] .. start[i] + length[i] - 1``); clip ``i`` is sampled at output frame ``k`` by
    slerp between its frames ``i0[i, k]`` and ``i0[i, k] + 1`` with ``frac[i, k]``, and only
    where it has weight (``w (f, N)``), so no ``(N, f, n, 4)`` stack of sampled clips is built.
    Equals ``blend_average(stack(sample_slerp(clip_i)))``: the samples here are not made
    hemisphere-continuous, which flips signs only, and the average is invariant to the sign
    of every non-heaviest clip and flips with the heaviest one, which the output's continuity
    step undoes (frame 0 is unflipped in both)."""
    nc, f, nj = w.shape[1], w.shape[0], rot.shape[1]
    for k in range(f):
        h = 0
        for i in range(1, nc):
            if w[k, i] > w[k, h]:
                h = i
        ah = start[h] + i0[h, k]
        bh = start[h] + min(i0[h, k] + 1, length[h] - 1)
        th = frac[h, k]
        for j in range(nj):
            rx, ry, rz, rw = _slerp(
                rot[ah, j, 0],
                rot[ah, j, 1],
                rot[ah, j, 2],
                rot[ah, j, 3],
                rot[bh, j, 0],
                rot[bh, j, 1],
                rot[bh, j, 2],
                rot[bh, j, 3],
                th,
            )
            if w[k, h] == 1.0:
                x, y, z, ww = rx, ry, rz, rw
            else:
                x = 0.0
                y = 0.0
                z = 0.0
                ww = 0.0
                for i in range(nc):
                    wi = w[k, i]
                    if wi == 0.0:
                        continue
                    if i == h:
                        qx, qy, qz, qw = rx, ry, rz, rw
                    else:
                        a = start[i] + i0[i, k]
                        b = start[i] + min(i0[i, k] + 1, length[i] - 1)
                        qx, qy, qz, qw = _slerp(
                            rot[a, j, 0],
                            rot[a, j, 1],
                            rot[a, j, 2],
                            rot[a, j, 3],
                            rot[b, j, 0],
                            rot[b, j, 1],
                            rot[b, j, 2],
                            rot[b, j, 3],
                            frac[i, k],
                        )
                    d = qx * rx + qy * ry + qz * rz + qw * rw
                    s = wi if d >= 0 else -wi
                    x += s * qx
                    y += s * qy
                    z += s * qz
                    ww += s * qw
                nrm = np.sqrt(x * x + y * y + z * z + ww * ww)
                x, y, z, ww = x / nrm, y / nrm, z / nrm, ww / nrm
            _store_continuous(out, k, j, x, y, z, ww)


@njit(cache=True)
def dtw(cost):  # pragma: no cover - compiled
    """Accumulated-cost DTW over ``cost (n, m)`` and its backtracked path (see
    :func:`biomorph.motion.align.dtw_path`)."""
    n, m = cost.shape
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            best = acc[i - 1, j - 1]
            if acc[i - 1, j] < best:
                best = acc[i - 1, j]
            if acc[i, j - 1] < best:
                best = acc[i, j - 1]
            acc[i, j] = cost[i - 1, j - 1] + best
    # backtrack
    path = np.empty((n + m, 2), dtype=np.int64)
    i, j, k = n, m, 0
    while i > 0 and j > 0:
        path[k, 0] = i - 1
        path[k, 1] = j - 1
        k += 1
        d = acc[i - 1, j - 1]
        u = acc[i - 1, j]
        l = acc[i, j - 1]
        if d <= u and d <= l:
            i -= 1
            j -= 1
        elif u <= l:
            i -= 1
        else:
            j -= 1
    return path[:k][::-1].copy(), acc[n, m]


@njit(cache=True)
def mirror_rotations(rest, rot, parent, other, sign, corr, use_corr, out):  # pragma: no cover
    """Local pose rotations of the mirrored motion, one frame at a time: the world rotation
    of every joint (FK, as ``fk_positions``), reflected (``sign`` ±1 per component) and
    taken from the mirror joint ``other[j]``, times the joint's constant correction
    ``corr[j]`` on the right when ``use_corr`` (rigs whose left and right local frames are not
    mirror images), then ``out[t, j] = rest[j]⁻¹ · M[parent]⁻¹ · M[j]``, hemisphere-continuous
    along t. Fuses FK, the ``[:, other] * sign`` gather and
    ``retarget._local_from_world`` without any ``(f, n, 4)`` temporaries (same bits)."""
    f, n = rot.shape[0], rot.shape[1]
    world = np.empty((n, 4))
    mw = np.empty((n, 4))
    for t in range(f):
        for j in range(n):
            lx, ly, lz, lw = _qmul(
                rest[j, 0],
                rest[j, 1],
                rest[j, 2],
                rest[j, 3],
                rot[t, j, 0],
                rot[t, j, 1],
                rot[t, j, 2],
                rot[t, j, 3],
            )
            p = parent[j]
            if p >= 0:
                lx, ly, lz, lw = _qmul(
                    world[p, 0], world[p, 1], world[p, 2], world[p, 3], lx, ly, lz, lw
                )
            world[j, 0], world[j, 1], world[j, 2], world[j, 3] = lx, ly, lz, lw
        for j in range(n):
            o = other[j]
            for c in range(4):
                mw[j, c] = world[o, c] * sign[c]
            if use_corr:
                mw[j, 0], mw[j, 1], mw[j, 2], mw[j, 3] = _qmul(
                    mw[j, 0],
                    mw[j, 1],
                    mw[j, 2],
                    mw[j, 3],
                    corr[j, 0],
                    corr[j, 1],
                    corr[j, 2],
                    corr[j, 3],
                )
        for j in range(n):
            p = parent[j]
            x, y, z, w = mw[j, 0], mw[j, 1], mw[j, 2], mw[j, 3]
            if p >= 0:
                x, y, z, w = _qmul(-mw[p, 0], -mw[p, 1], -mw[p, 2], mw[p, 3], x, y, z, w)
            x, y, z, w = _qmul(-rest[j, 0], -rest[j, 1], -rest[j, 2], rest[j, 3], x, y, z, w)
            _store_continuous(out, t, j, x, y, z, w)


@njit(cache=True)
def continuous_inplace(q):  # pragma: no cover - compiled
    """``transforms.quat_continuous(q, axis=0)`` in place for ``q (f, n, 4)``: joint j's
    sample t is negated when an odd number of the dots of consecutive *input* samples up to
    t are negative (the same dots, summed in the same order, as the NumPy version)."""
    f, n = q.shape[0], q.shape[1]
    prev = np.empty((n, 4))
    neg = np.zeros(n, dtype=np.bool_)
    for j in range(n):
        for c in range(4):
            prev[j, c] = q[0, j, c]
    for t in range(1, f):
        for j in range(n):
            x, y, z, w = q[t, j, 0], q[t, j, 1], q[t, j, 2], q[t, j, 3]
            d = x * prev[j, 0] + y * prev[j, 1] + z * prev[j, 2] + w * prev[j, 3]
            prev[j, 0], prev[j, 1], prev[j, 2], prev[j, 3] = x, y, z, w
            if d < 0:
                neg[j] = not neg[j]
            if neg[j]:
                q[t, j, 0], q[t, j, 1], q[t, j, 2], q[t, j, 3] = -x, -y, -z, -w
