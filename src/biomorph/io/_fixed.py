"""Compiled fixed-point number text, shared by the BVH and XYZ writers."""

from __future__ import annotations

import numba


@numba.njit(cache=True, inline="always")
def emit_fixed(out, pos, neg, ip, fp, frac_digits, digits):  # pragma: no cover - compiled
    """Write ``[-]ip[.fp]`` into byte buffer ``out`` at ``pos``; return the new position.

    ``ip`` and ``fp`` are the non-negative integer and fraction parts of an already rounded
    value (``fp`` has ``frac_digits`` decimal digits, leading zeros implied); ``digits`` is a
    scratch ``uint8[24]``. Rounding stays with the caller (formats differ in tie-breaking).
    """
    if neg:
        out[pos] = 45  # '-'
        pos += 1
    nd = 0
    if ip == 0:
        digits[0] = 48
        nd = 1
    while ip > 0:
        digits[nd] = 48 + ip % 10
        ip //= 10
        nd += 1
    for k in range(nd - 1, -1, -1):
        out[pos] = digits[k]
        pos += 1
    if frac_digits > 0:
        out[pos] = 46  # '.'
        pos += 1
        for k in range(frac_digits - 1, -1, -1):
            digits[k] = 48 + fp % 10
            fp //= 10
        for k in range(frac_digits):
            out[pos] = digits[k]
            pos += 1
    return pos
