"""Compiled kernels of the BVH reader and writer (numba, cached).

Kept apart from :mod:`biomorph.io.bvh`, which imports this module only for MOTION sections
large enough that the compiled loops pay for loading numba (``bvh._COMPILED_MIN_VALUES``) or
when it is loaded already; smaller files take NumPy paths that give the same bits (issue 12:
``biomorph motion info`` and ``convert`` on a small file load no numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from biomorph.io._fixed import emit_fixed


@njit(cache=True)
def _scan_floats(buf, start, out, n_per_line):  # pragma: no cover - compiled
    """Parse whitespace-separated decimal numbers from ``buf[start:]`` into ``out``.

    Not shared with :mod:`biomorph.io.xyz`'s ``_scan_table`` (issue 12 asked for one scanner
    if it costs neither reader speed): the contracts differ — XYZ takes a delimiter,
    ``#`` comments and converts tokens beyond 2^53 / 1e±22 exactly through a slow path,
    while this scanner counts values per line for BVH's frame diagnostics, refuses
    overflow and never leaves the compiled loop. A common kernel would need both sets of
    branches in the innermost per-byte loop of each reader, so both are kept.

    Returns ``(count, status, err_pos, bad_line_pos, bad_line_count)``: status 0 ok,
    1 more values than ``out`` holds, 2 a malformed token starting at ``err_pos``.
    3 a value overflowing to infinity starting at ``err_pos``.
    ``bad_line_pos`` is the byte offset of the first line whose value count differs from
    ``n_per_line`` (-1 if none)."""
    n = out.size
    pow10 = np.empty(23)
    p = 1.0
    for e in range(23):
        pow10[e] = p  # 1e0 .. 1e22, each exact (products of exact values below 2**53 * 2**e)
        p *= 10.0
    k = 0
    i = start
    size = buf.size
    line_start = start
    line_count = 0
    bad_line = -1
    bad_count = 0
    while i < size:
        c = buf[i]
        if c == 10:  # newline closes a line
            if line_count != 0 and line_count != n_per_line and bad_line < 0:
                bad_line = line_start
                bad_count = line_count
            line_count = 0
            i += 1
            line_start = i
            continue
        if c == 32 or c == 9 or c == 13 or c == 11 or c == 12:
            i += 1
            continue
        tok = i
        if k >= n:
            return k, 1, tok, bad_line, bad_count
        neg = False
        if c == 45:
            neg = True
            i += 1
        elif c == 43:
            i += 1
        mant = 0
        nd = 0
        exp10 = 0
        digits = 0
        while i < size and 48 <= buf[i] <= 57:
            if nd < 18:
                mant = mant * 10 + (buf[i] - 48)
                if mant > 0:
                    nd += 1
            else:
                exp10 += 1
            digits += 1
            i += 1
        if i < size and buf[i] == 46:
            i += 1
            while i < size and 48 <= buf[i] <= 57:
                if nd < 18:
                    mant = mant * 10 + (buf[i] - 48)
                    exp10 -= 1
                    if mant > 0:
                        nd += 1
                digits += 1
                i += 1
        if digits == 0:
            return k, 2, tok, bad_line, bad_count
        if i < size and (buf[i] == 101 or buf[i] == 69):
            i += 1
            eneg = False
            if i < size and (buf[i] == 45 or buf[i] == 43):
                eneg = buf[i] == 45
                i += 1
            ed = 0
            ev = 0
            while i < size and 48 <= buf[i] <= 57:
                if ev < 10000:
                    ev = ev * 10 + (buf[i] - 48)
                ed += 1
                i += 1
            if ed == 0:
                return k, 2, tok, bad_line, bad_count
            exp10 += -ev if eneg else ev
        if i < size:
            c2 = buf[i]
            if not (c2 == 32 or c2 == 9 or c2 == 10 or c2 == 13 or c2 == 11 or c2 == 12):
                return k, 2, tok, bad_line, bad_count
        v = float(mant)
        # powers of ten up to 1e22 are exact doubles: a table lookup gives the same value as
        # 10.0 ** k without a pow() call per number (most of the scan's time before)
        if exp10 > 0:
            v = v * (pow10[exp10] if exp10 <= 22 else 10.0**exp10)
        elif exp10 < 0:
            if exp10 >= -22:
                v = v / pow10[-exp10]
            else:
                v = v / 1e22 / 10.0 ** (-exp10 - 22)
        if v > 1.7976931348623157e308:  # overflow (e.g. 1e999): not a finite number
            return k, 3, tok, bad_line, bad_count
        out[k] = -v if neg else v
        k += 1
        line_count += 1
    if line_count != 0 and line_count != n_per_line and bad_line < 0:
        bad_line = line_start
        bad_count = line_count
    return k, 0, -1, bad_line, bad_count


@njit(cache=True)
def _count_tokens(buf, lo, hi):  # pragma: no cover - compiled
    """Whitespace-separated words in ``buf[lo:hi]`` (the values a well-formed chunk holds)."""
    n = 0
    prev_space = True
    for i in range(lo, hi):
        c = buf[i]
        space = c == 32 or c == 10 or c == 9 or c == 13 or c == 11 or c == 12
        if prev_space and not space:
            n += 1
        prev_space = space
    return n


@njit(cache=True, parallel=True)
def _scan_floats_chunks(buf, bounds, out, n_per_line):  # pragma: no cover - compiled
    """:func:`_scan_floats` over chunks ``bounds[i]..bounds[i+1]`` (each starting at a line
    start) in parallel: count the words of every chunk, prefix-sum them into output offsets,
    parse every chunk into its slice. Returns ``ok``: False when any chunk is not clean
    (a malformed value, a short line, or a total other than ``out.size``) — the caller then
    runs the sequential scan for its exact diagnostics."""
    nc = bounds.size - 1
    counts = np.zeros(nc, dtype=np.int64)
    for i in prange(nc):
        counts[i] = _count_tokens(buf, bounds[i], bounds[i + 1])
    if counts.sum() != out.size:
        return False
    offs = np.zeros(nc + 1, dtype=np.int64)
    for i in range(nc):
        offs[i + 1] = offs[i] + counts[i]
    good = np.ones(nc, dtype=np.bool_)
    for i in prange(nc):
        k, status, _e, bad_line, _b = _scan_floats(
            buf[: bounds[i + 1]], bounds[i], out[offs[i] : offs[i + 1]], n_per_line
        )
        good[i] = status == 0 and bad_line < 0 and k == counts[i]
    return good.all()


@njit(cache=True, inline="always")
def _euler_quat(data, t, j, rot_cols, rot_axes, d2r):  # pragma: no cover - compiled
    """Quaternion of joint j's Euler channels (degrees) at frame t: product in listed order."""
    x = 0.0
    y = 0.0
    z = 0.0
    w = 1.0
    for m in range(3):
        col = rot_cols[j, m]
        if col < 0:
            continue
        h = 0.5 * data[t, col] * d2r
        s = np.sin(h)
        c = np.cos(h)
        ax = rot_axes[j, m]
        # (x,y,z,w) * (axis*s, c)
        if ax == 0:
            bx, by, bz = s, 0.0, 0.0
        elif ax == 1:
            bx, by, bz = 0.0, s, 0.0
        else:
            bx, by, bz = 0.0, 0.0, s
        nx = w * bx + x * c + y * bz - z * by
        ny = w * by - x * bz + y * c + z * bx
        nz = w * bz + x * by - y * bx + z * c
        nw = w * c - x * bx - y * by - z * bz
        x, y, z, w = nx, ny, nz, nw
    return x, y, z, w


_EULER_CHUNK = 4096


@njit(cache=True, parallel=True)
def _euler_kernel(data, rot_cols, rot_axes, out):  # pragma: no cover - compiled
    """Pose quaternions from Euler columns (degrees) with hemisphere continuity.

    ``rot_cols[j, m]`` is the data column of joint j's m-th rotation channel (-1 none),
    ``rot_axes[j, m]`` its axis 0/1/2; the rotation is the product in listed order.

    Parallel over blocks of frames (each thread streams its rows of ``data`` and ``out``
    once, all joints per row), continuity first within each block; then one sign per block
    and joint chains the blocks. Negation is exact, so the result equals the sequential
    frame-by-frame continuity bit for bit."""
    f, n = out.shape[0], out.shape[1]
    d2r = np.pi / 180.0
    ch = _EULER_CHUNK
    nb = (f + ch - 1) // ch
    for b in prange(nb):
        t0 = b * ch
        t1 = min(t0 + ch, f)
        for t in range(t0, t1):
            for j in range(n):
                x, y, z, w = _euler_quat(data, t, j, rot_cols, rot_axes, d2r)
                if t > t0:
                    dot = (
                        x * out[t - 1, j, 0]
                        + y * out[t - 1, j, 1]
                        + z * out[t - 1, j, 2]
                        + w * out[t - 1, j, 3]
                    )
                    if dot < 0:
                        x, y, z, w = -x, -y, -z, -w
                out[t, j, 0] = x
                out[t, j, 1] = y
                out[t, j, 2] = z
                out[t, j, 3] = w
    if nb == 1:
        return
    sign = np.ones((nb, n))
    for b in range(1, nb):
        t0 = b * ch
        for j in range(n):
            dot = sign[b - 1, j] * (
                out[t0 - 1, j, 0] * out[t0, j, 0]
                + out[t0 - 1, j, 1] * out[t0, j, 1]
                + out[t0 - 1, j, 2] * out[t0, j, 2]
                + out[t0 - 1, j, 3] * out[t0, j, 3]
            )
            sign[b, j] = -1.0 if dot < 0 else 1.0
    for b in prange(1, nb):
        t0 = b * ch
        t1 = min(t0 + ch, f)
        for j in range(n):
            if sign[b, j] < 0:
                for t in range(t0, t1):
                    for c in range(4):
                        out[t, j, c] = -out[t, j, c]


@njit(cache=True)
def _count_wraps(data, cols):  # pragma: no cover - compiled
    """Number of jumps larger than 180 between consecutive rows in the given columns."""
    n = 0
    for t in range(1, data.shape[0]):
        for c in cols:
            if abs(data[t, c] - data[t - 1, c]) > 180.0:
                n += 1
    return n


@njit(cache=True)
def _format_fixed(values, precision, limit, out):  # pragma: no cover - compiled
    """Write ``values (f, c)`` as fixed-point text rows into byte buffer ``out``; return the
    number of bytes used (-1 if a value is not below ``limit`` in magnitude)."""
    f, c = values.shape
    scale = 10.0**precision
    p10 = np.int64(1)
    for _ in range(precision):
        p10 *= 10
    pos = 0
    digits = np.empty(24, dtype=np.uint8)
    for t in range(f):
        for j in range(c):
            v = values[t, j]
            a = abs(v)
            if not a < limit:
                return -1
            x = np.int64(np.floor(a * scale + 0.5))  # half-up on the scaled value
            ip = x // p10
            pos = emit_fixed(out, pos, v < 0 and x != 0, ip, x - ip * p10, precision, digits)
            out[pos] = 32 if j < c - 1 else 10
            pos += 1
    return pos


@njit(cache=True)
def _chain_block(rotation, t0):  # pragma: no cover - compiled
    """Negate joints of the block starting at frame ``t0`` whose first quaternion is in the
    other hemisphere than frame ``t0 - 1`` (continuity across blocks; negation is exact)."""
    f, n = rotation.shape[0], rotation.shape[1]
    for j in range(n):
        dot = 0.0
        for c in range(4):
            dot += rotation[t0 - 1, j, c] * rotation[t0, j, c]
        if dot < 0:
            for t in range(t0, f):
                for c in range(4):
                    rotation[t, j, c] = -rotation[t, j, c]
