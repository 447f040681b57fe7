"""BVH (Biovision Hierarchy) reader and writer.

Reading
-------
``read_bvh(path) -> Motion``. The HIERARCHY is parsed token by token (``{``/``}`` may sit on
any line, keywords are case-insensitive, tabs, CRLF and runs of whitespace are accepted,
``End Site`` blocks are kept in ``skeleton.end_site``). Every joint may carry any subset of
the six channels in any order; the channel names are kept in ``skeleton.channels`` so a
file round-trips. The MOTION block is parsed in one vectorised pass (a compiled float
scanner over the raw bytes, exponent notation allowed) after which the value count must be
``frames × channels`` and every data line must hold exactly ``channels`` values; otherwise a
:class:`FormatError` names the first bad line.

Conversions: Euler channels (degrees) become pose quaternions. A channel order ``Z X Y``
means ``R = Rz · Rx · Ry`` (the BVH convention, see :mod:`biomorph.core.transforms`);
quaternions are made hemisphere-continuous over time. Root position channels become
``Motion.root_position`` (they replace the root OFFSET; a missing axis takes the OFFSET
value). Position channels on any other joint become ``Motion.joint_translation`` (the
joint's local translation per frame, replacing its OFFSET). Lengths stay in file units.

Writing
-------
``write_bvh(path, motion_or_skeleton, precision=6)`` writes each joint's channels in the
skeleton's channel order (defaults: root ``Xposition Yposition Zposition Zrotation
Xrotation Yrotation``, other joints ``Zrotation Xrotation Yrotation``), fixed-point with
``precision`` decimals. Euler angles are principal values in ±180° by default
(``euler="wrap"``, what Blender, Maya and MotionBuilder export and every importer reads);
``euler="continuous"`` unwraps them over time instead (curves without ±360° jumps, values
may exceed 180°: up to 543° on the Rokoko dance). The file is written atomically.
"""

from __future__ import annotations

import math
import mmap
import os
import re
import warnings
from pathlib import Path

import numpy as np
from numba import njit, prange

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import FormatError, InputError, ParameterError
from biomorph.io._fixed import emit_fixed
from biomorph.io.atomic import atomic_path

_CHANNELS = {
    c.lower(): c
    for c in ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
}
_TOKEN = re.compile(r"[{}]|[^\s{}]+")
_DEFAULT_ROOT = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
_DEFAULT_JOINT = ("Zrotation", "Xrotation", "Yrotation")


# --------------------------------------------------------------------------- compiled kernels
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


_PARALLEL_MIN_BYTES = 8 << 20  #: below this the sequential scan is as fast


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


def _scan_floats_parallel(buf: np.ndarray, start: int, out: np.ndarray, n_per_line: int):
    """:func:`_scan_floats` with the same result, MOTION sections of 8 MB and more parsed by
    all cores (2 cores: an 11 MB file 39 → 31 ms, a 47 MB one 242 → 191 ms; larger
    sections are streamed, :func:`_stream_motion`)."""
    size = buf.size
    if size - start >= _PARALLEL_MIN_BYTES:
        from numba import get_num_threads

        nc = 4 * get_num_threads()
        cuts = [start]
        for i in range(1, nc):
            pos = start + (size - start) * i // nc
            nl = int(np.argmax(buf[pos : pos + (1 << 20)] == 10)) if pos < size else 0
            if pos < size and buf[pos + nl] == 10 and pos + nl + 1 > cuts[-1]:
                cuts.append(pos + nl + 1)
        cuts.append(size)
        if len(cuts) > 2 and _scan_floats_chunks(
            buf, np.asarray(cuts, dtype=np.int64), out, n_per_line
        ):
            return out.size, 0, -1, -1, 0
    return _scan_floats(buf, start, out, n_per_line)


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
def _format_fixed(values, precision, out):  # pragma: no cover - compiled
    """Write ``values (f, c)`` as fixed-point text rows into byte buffer ``out``; return the
    number of bytes used (-1 if a value is too large)."""
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
            if not a < 1e12:
                return -1
            x = np.int64(np.floor(a * scale + 0.5))  # half-up on the scaled value
            ip = x // p10
            pos = emit_fixed(out, pos, v < 0 and x != 0, ip, x - ip * p10, precision, digits)
            out[pos] = 32 if j < c - 1 else 10
            pos += 1
    return pos


# --------------------------------------------------------------------------- reading
_HUGE_MIN_BYTES = 32 << 20


def _empty(shape: tuple[int, ...]) -> np.ndarray:
    """``np.empty(shape)`` (float64); arrays of 32 MB and more come from an anonymous mapping
    advised for transparent huge pages: first-touch page faults were ~1.5 s per GB here,
    most of a 1-hour take's read time. Falls back to ``np.empty`` where unsupported."""
    n = int(np.prod(shape))
    if n * 8 < _HUGE_MIN_BYTES or not hasattr(mmap, "MADV_HUGEPAGE"):
        return np.empty(shape)
    try:
        mm = mmap.mmap(-1, n * 8)
        mm.madvise(mmap.MADV_HUGEPAGE)
    except (OSError, ValueError):
        return np.empty(shape)
    return np.frombuffer(mm, dtype=np.float64, count=n).reshape(shape)  # keeps mm alive


def _line_of(buf: bytes, pos: int) -> int:
    return buf.count(b"\n", 0, pos) + 1


class _Tokens:
    def __init__(self, text: str, path: str | os.PathLike[str]) -> None:
        self.items: list[tuple[str, int]] = []
        for ln, line in enumerate(text.splitlines(), start=1):
            for m in _TOKEN.finditer(line):
                self.items.append((m.group(0), ln))
        self.i = 0
        self.path = path
        self.last_line = max(1, text.count("\n") + 1)

    def peek(self) -> tuple[str, int] | None:
        return self.items[self.i] if self.i < len(self.items) else None

    def next(self, expect: str) -> tuple[str, int]:
        if self.i >= len(self.items):
            raise FormatError(
                self.path, f"file ends inside HIERARCHY; expected {expect}", line=self.last_line
            )
        tok = self.items[self.i]
        self.i += 1
        return tok

    def number(self, what: str) -> float:
        tok, ln = self.next(what)
        try:
            v = float(tok)
        except ValueError:
            raise FormatError(self.path, f"{what}: {tok!r} is not a number", line=ln) from None
        if not math.isfinite(v):
            raise FormatError(self.path, f"{what}: {tok!r}; expected a finite number", line=ln)
        return v


def _owner(stack: list[int]) -> int:
    """Joint index of the innermost open block (an End Site block is encoded as ``-2 - j``)."""
    top = stack[-1]
    return top if top >= 0 else -2 - top


def _parse_hierarchy(text: str, path: str | os.PathLike[str]):
    toks = _Tokens(text, path)
    first = toks.next("HIERARCHY")
    if first[0].upper() != "HIERARCHY":
        raise FormatError(
            path,
            f"file starts with {first[0]!r}; expected HIERARCHY (not a BVH file?)",
            line=first[1],
        )
    names: list[str] = []
    parent: list[int] = []
    offset: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    end_site: dict[int, list[float]] = {}
    stack: list[int] = []  # open joints (-2 marks an End Site block)
    while True:
        tok = toks.peek()
        if tok is None:
            if stack:
                raise FormatError(
                    path,
                    f"file ends inside joint {names[_owner(stack)]!r}; "
                    "expected '}' and a MOTION section",
                    line=toks.last_line,
                )
            raise FormatError(
                path,
                "no MOTION section; expected 'MOTION' after the hierarchy",
                line=toks.last_line,
            )
        word, ln = toks.next("a keyword")
        key = word.upper()
        if key in ("ROOT", "JOINT"):
            if key == "JOINT" and not stack:
                raise FormatError(path, "JOINT outside any ROOT; expected ROOT first", line=ln)
            parts = []
            while (nxt := toks.peek()) is not None and nxt[1] == ln and nxt[0] != "{":
                parts.append(toks.next("a name")[0])
            name = " ".join(parts)
            if not name:
                raise FormatError(path, f"{key} without a name; expected '{key} <name>'", line=ln)
            if name in names:
                raise FormatError(
                    path, f"joint name {name!r} occurs twice; expected unique names", line=ln
                )
            brace, bl = toks.next("'{'")
            if brace != "{":
                raise FormatError(
                    path, f"found {brace!r} after {key} {name}; expected '{{'", line=bl
                )
            names.append(name)
            parent.append(stack[-1] if stack else -1)
            offset.append([np.nan] * 3)
            channels.append(())
            stack.append(len(names) - 1)
        elif key == "END":
            site, sl = toks.next("'Site'")
            brace, bl = toks.next("'{'")
            if site.upper() != "SITE" or brace != "{":
                raise FormatError(
                    path, f"malformed End Site ({site} {brace}); expected 'End Site {{'", line=ln
                )
            if not stack or stack[-1] < 0:
                raise FormatError(path, "End Site outside a joint", line=ln)
            stack.append(-2 - stack[-1])  # encode owner joint
        elif key == "OFFSET":
            vals = [toks.number("OFFSET value") for _ in range(3)]
            if not stack:
                raise FormatError(path, "OFFSET outside a joint", line=ln)
            top = stack[-1]
            if top <= -2:
                end_site[-2 - top] = vals
            else:
                offset[top] = vals
        elif key == "CHANNELS":
            if not stack or stack[-1] <= -2:
                raise FormatError(path, "CHANNELS outside a joint", line=ln)
            cnt_tok, cl = toks.next("channel count")
            try:
                cnt = int(cnt_tok)
            except ValueError:
                raise FormatError(
                    path, f"channel count {cnt_tok!r} is not an integer", line=cl
                ) from None
            if not 0 <= cnt <= 6:
                raise FormatError(path, f"CHANNELS {cnt}; expected 0 to 6 channels", line=cl)
            chans = []
            for _ in range(cnt):
                c, cl2 = toks.next("a channel name")
                canon = _CHANNELS.get(c.lower())
                if canon is None:
                    raise FormatError(
                        path,
                        f"channel {c!r} unknown (or fewer channels than "
                        f"CHANNELS {cnt} announces); expected "
                        "Xposition..Zrotation",
                        line=cl2,
                    )
                if canon in chans:
                    raise FormatError(path, f"channel {canon} listed twice", line=cl2)
                chans.append(canon)
            channels[stack[-1]] = tuple(chans)
        elif word == "}":
            if not stack:
                raise FormatError(path, "unbalanced '}'", line=ln)
            top = stack.pop()
            if top >= 0 and np.isnan(offset[top][0]):
                raise FormatError(path, f"joint {names[top]!r} has no OFFSET", line=ln)
        elif key == "MOTION":
            if stack:
                raise FormatError(
                    path,
                    f"MOTION inside joint {names[_owner(stack)]!r}; a '}}' is missing",
                    line=ln,
                )
            break
        else:
            raise FormatError(
                path,
                f"unexpected {word!r} in HIERARCHY; expected ROOT, JOINT, "
                "End Site, OFFSET, CHANNELS, '}' or MOTION",
                line=ln,
            )
    if not names:
        raise FormatError(path, "no ROOT joint in HIERARCHY", line=1)
    end = np.full((len(names), 3), np.nan)
    for j, v in end_site.items():
        end[j] = v
    return names, parent, np.asarray(offset, float), channels, end


_NUM = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"


def _complete_rows(buf: np.ndarray, data_start: int, n_ch: int) -> tuple[int, int, bool]:
    """``(rows, end, partial)``: complete frame rows in ``buf[data_start:end]`` when only the
    last line may be short (``partial``: it was cut off); ``rows = -1`` when the values do not
    split into whole rows for another reason (the strict diagnostics then apply)."""
    total = int(_count_tokens(buf, data_start, buf.size))
    if n_ch <= 0:
        return -1, buf.size, False
    if total % n_ch == 0:
        return total // n_ch, buf.size, False
    text_end = buf.size
    while text_end > data_start and buf[text_end - 1] in (9, 10, 11, 12, 13, 32):
        text_end -= 1
    nl = np.flatnonzero(buf[data_start:text_end] == 10)
    end = data_start + (int(nl[-1]) + 1 if nl.size else 0)
    head = int(_count_tokens(buf, data_start, end))
    if head % n_ch:
        return -1, buf.size, False
    return head // n_ch, end, True


def _parse_motion(
    path,
    raw,
    buf,
    data_start,
    n_frames,
    n_ch,
    rot_cols,
    rot_axes,
    pos_cols,
    offset,
    strict=True,
    meta=None,
):
    """The MOTION section in one piece (exact diagnostics): values, then rotations, root
    positions, joint translations and the Euler wrap count.

    ``strict=False``: when ``Frames:`` disagrees with the data (more rows, fewer rows, a last
    row cut off) every complete row is read and the discrepancy is recorded in
    ``meta["tolerated"]`` with a :class:`~biomorph.core.motion.MotionInputWarning` — what
    Blender's importer, ``bvh`` and ``bvhtoolbox`` do (they read all rows; bvhio reads the
    declared count). Malformed values and rows of the wrong length stay errors."""
    if not strict and n_ch > 0:
        rows, end, partial = _complete_rows(buf, data_start, n_ch)
        if rows >= 1 and (rows != n_frames or partial):
            from biomorph.core.motion import tolerate

            got = _parse_motion(
                path,
                raw[:end],
                buf[:end],
                data_start,
                rows,
                n_ch,
                rot_cols,
                rot_axes,
                pos_cols,
                offset,
            )
            what = f"'Frames: {n_frames}' but {rows} complete data rows"
            if partial:
                what += f"; the cut-off last line (line {_line_of(raw, end)}) was dropped"
            tolerate(
                meta if meta is not None else {},
                f"{os.fspath(path)}: {what}; read {rows} frames (--strict refuses)",
            )
            return got
    out = _empty((n_frames * n_ch,))
    count, status, err, bad_line, bad_count = _scan_floats_parallel(
        buf, data_start, out, max(n_ch, 1)
    )
    first_data_line = _line_of(raw, data_start)
    if status == 3:
        tok = raw[err : err + 40].split()[0].decode(errors="replace")
        raise FormatError(
            path,
            f"MOTION value {tok!r} overflows (frame {count // max(n_ch, 1)}, "
            f"channel {count % max(n_ch, 1)}); expected a finite number",
            line=_line_of(raw, err),
        )
    if status == 2:
        tok = raw[err : err + 40].split()[0].decode(errors="replace")
        raise FormatError(
            path,
            f"MOTION value {tok!r} is not a number (frame "
            f"{count // max(n_ch, 1)}, channel {count % max(n_ch, 1)})",
            line=_line_of(raw, err),
        )
    if (
        status == 0
        and count < n_frames * n_ch
        and bad_line >= 0
        and _line_of(raw, bad_line) == (last_line := _line_of(raw, len(raw.rstrip())))
    ):
        raise FormatError(
            path,
            f"file ends inside frame {count // n_ch} (its line holds "
            f"{bad_count} of {n_ch} values); 'Frames: {n_frames}' announces "
            f"{n_frames} frames (truncated file?)",
            line=last_line,
        )
    if bad_line >= 0 and n_ch > 0:
        ln = _line_of(raw, bad_line)
        raise FormatError(
            path,
            f"frame line holds {bad_count} values; expected {n_ch} (the CHANNELS of the hierarchy)",
            line=ln,
        )
    if status == 1:
        ln = _line_of(raw, err)
        raise FormatError(
            path,
            f"more data than 'Frames: {n_frames}' announces (frame line "
            f"{ln - first_data_line + 1}); expected {n_frames} frames",
            line=ln,
        )
    if count < n_frames * n_ch:
        raise FormatError(
            path,
            f"file ends after {count // n_ch} complete frames; 'Frames: "
            f"{n_frames}' announces {n_frames} (truncated file?)",
            line=_line_of(raw, len(raw)),
        )
    conv = _MotionRows(n_frames, rot_cols, rot_axes, pos_cols, offset)
    conv.add(out.reshape(n_frames, n_ch))
    return conv.result()


class _MotionRows:
    """Turns rows of MOTION values (frames × channels, degrees and file units) into the
    Motion arrays, in one piece or block after block: rotations (hemisphere-continuous
    across blocks), root positions, joint translations and the Euler wrap count."""

    def __init__(self, n_frames, rot_cols, rot_axes, pos_cols, offset):
        n = rot_cols.shape[0]
        self.rot_cols, self.rot_axes, self.pos_cols, self.offset = (
            rot_cols,
            rot_axes,
            pos_cols,
            offset,
        )
        self.rotation = _empty((n_frames, n, 4))
        self.root_pos = np.empty((n_frames, 3))
        self.inner = [j for j in range(1, n) if (pos_cols[j] >= 0).any()]
        self.translation = np.broadcast_to(offset, (n_frames, n, 3)).copy() if self.inner else None
        self.rc = rot_cols[rot_cols >= 0]
        self.t = 0
        self.wraps = 0
        self.last = None

    def add(self, vals):
        t0, t1 = self.t, self.t + vals.shape[0]
        _euler_kernel(vals, self.rot_cols, self.rot_axes, self.rotation[t0:t1])
        if t0 > 0:
            _chain_block(self.rotation, t0)
        pc = self.pos_cols
        for a in range(3):
            self.root_pos[t0:t1, a] = vals[:, pc[0, a]] if pc[0, a] >= 0 else self.offset[0, a]
        for j in self.inner:
            for a in range(3):
                if pc[j, a] >= 0:
                    self.translation[t0:t1, j, a] = vals[:, pc[j, a]]
        if self.rc.size:
            self.wraps += int(_count_wraps(vals, self.rc))
            if self.last is not None:
                self.wraps += int(
                    np.count_nonzero(np.abs(vals[0, self.rc] - self.last[self.rc]) > 180.0)
                )
            self.last = vals[-1].copy()
        self.t = t1

    def result(self):
        if self.translation is not None:
            self.translation[:, 0] = self.root_pos
        return self.rotation, self.root_pos, self.translation, self.wraps


_STREAM_MIN_BYTES = 64 << 20  #: MOTION sections with more values than this are streamed
_STREAM_FRAMES = 16384  #: frames per streamed block


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


def _stream_motion(buf, data_start, n_frames, n_ch, rot_cols, rot_axes, pos_cols, offset):
    """The MOTION section of a big file in blocks of ``_STREAM_FRAMES`` frames through one
    reused value buffer, so the ``frames × channels`` table of values is never held whole
    (on a 1-hour 60-joint take that table is 630 MB, and first-touching fresh memory is a
    large part of the read time). Equal to :func:`_parse_motion` bit for bit; returns
    ``None`` at the first irregularity (a malformed value, a short line, too many or too
    few values), and the caller re-reads with :func:`_parse_motion` for its diagnostics."""
    conv = _MotionRows(n_frames, rot_cols, rot_axes, pos_cols, offset)
    block = np.empty((min(_STREAM_FRAMES, n_frames), n_ch))
    pos = data_start
    while conv.t < n_frames:
        t1 = min(conv.t + _STREAM_FRAMES, n_frames)
        vals = block[: t1 - conv.t]
        flat = vals.reshape(-1)
        k, status, nxt, bad_line, _ = _scan_floats(buf, pos, flat, n_ch)
        if k != flat.size or bad_line >= 0 or status != (0 if t1 == n_frames else 1):
            return None
        conv.add(vals)
        pos = nxt
    return conv.result()


def read_bvh(path: str | os.PathLike[str], up: str | None = None, strict: bool = False):
    """Read a BVH file into a :class:`biomorph.motion.Motion` (see the module docstring).

    ``up="z"`` converts a Z-up file to Y-up (rotating the root about X by -90°); by default
    the file is kept as is and ``motion.meta["up_guess"]`` says which axis looks vertical.
    A ``Frames:`` count that disagrees with the data rows is tolerated (all complete rows
    are read, one :class:`~biomorph.core.motion.MotionInputWarning`, the message kept in
    ``meta["tolerated"]``) unless ``strict=True``, which raises :class:`FormatError`.
    """
    from biomorph.core.motion import Motion, guess_up_axis

    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise FormatError(path, "file does not exist") from None
    except IsADirectoryError:
        raise FormatError(path, "is a directory; expected a BVH file") from None
    m = re.search(rb"(?im)^[ \t]*MOTION[ \t]*\r?$", raw)
    if m is None:
        if not raw.strip():
            raise FormatError(path, "file is empty; expected a BVH file", line=1)
        raw_text = raw.decode("utf-8", errors="replace")
        _parse_hierarchy(raw_text, path)  # raises the precise hierarchy error
        raise FormatError(path, "no MOTION section", line=_line_of(raw, len(raw)))
    header = raw[: m.end()].decode("utf-8", errors="replace")
    names, parent, offset, channels, end = _parse_hierarchy(header, path)
    # Frames: / Frame Time:
    pos = m.end()
    motion_line = _line_of(raw, m.start())
    fr = re.compile(rb"[ \t\r\n]*Frames[ \t]*:?[ \t]*(\S+)[ \t]*\r?\n")
    ft = re.compile(rb"[ \t\r\n]*Frame[ \t]*Time[ \t]*:?[ \t]*(\S+)[ \t]*\r?(?:\n|$)")
    m1 = fr.match(raw, pos)
    if m1 is None:
        raise FormatError(path, "missing 'Frames: <count>' after MOTION", line=motion_line + 1)
    try:
        n_frames = int(m1.group(1))
    except ValueError:
        raise FormatError(
            path,
            f"Frames: {m1.group(1).decode(errors='replace')!r} is not an integer",
            line=_line_of(raw, m1.start(1)),
        ) from None
    m2 = ft.match(raw, m1.end())
    if m2 is None:
        raise FormatError(
            path, "missing 'Frame Time: <seconds>' after Frames:", line=_line_of(raw, m1.end())
        )
    try:
        frame_time = float(m2.group(1))
    except ValueError:
        frame_time = float("nan")
    if not np.isfinite(frame_time) or frame_time <= 0:
        raise FormatError(
            path,
            f"Frame Time {m2.group(1).decode(errors='replace')!r}; expected seconds per frame > 0",
            line=_line_of(raw, m2.start(1)),
        )
    if n_frames < 1:
        raise FormatError(
            path,
            f"Frames: {n_frames}; expected at least one frame",
            line=_line_of(raw, m1.start(1)),
        )
    n = len(names)
    n_ch = sum(len(c) for c in channels)
    rot_cols = np.full((n, 3), -1, dtype=np.int64)
    rot_axes = np.zeros((n, 3), dtype=np.int64)
    pos_cols = np.full((n, 3), -1, dtype=np.int64)
    col = 0
    for j, chans in enumerate(channels):
        k = 0
        for c in chans:
            axis = "XYZ".index(c[0])
            if c.endswith("rotation"):
                rot_cols[j, k] = col
                rot_axes[j, k] = axis
                k += 1
            else:
                pos_cols[j, axis] = col
            col += 1
    data_start = m2.end()
    buf = np.frombuffer(raw, dtype=np.uint8)
    streamed = None
    # Each value takes at least one character and one separator: a 'Frames:' count beyond
    # what the bytes can hold is refused (strict) or read as the rows that are there, never
    # allocated (a corrupt 'Frames: 99999999999' must not ask for terabytes).
    capacity = (len(raw) - data_start) // (2 * max(n_ch, 1)) + 1
    can_stream = True
    if n_ch > 0 and n_frames > capacity:
        if strict or _complete_rows(buf, data_start, n_ch)[0] < 1:
            raise FormatError(
                path,
                f"Frames: {n_frames} but the {len(raw) - data_start:,} "
                f"bytes of MOTION data hold at most {capacity:,} frames of "
                f"{n_ch} channels (corrupt header?)",
                line=_line_of(raw, m1.start(1)),
            )
        can_stream = False
    if can_stream and n_frames * n_ch * 8 >= _STREAM_MIN_BYTES:
        streamed = _stream_motion(
            buf, data_start, n_frames, n_ch, rot_cols, rot_axes, pos_cols, offset
        )
    tolerated: dict = {}
    if streamed is not None:
        rotation, root_pos, translation, wraps = streamed
    else:
        rotation, root_pos, translation, wraps = _parse_motion(
            path,
            raw,
            buf,
            data_start,
            n_frames,
            n_ch,
            rot_cols,
            rot_axes,
            pos_cols,
            offset,
            strict,
            tolerated,
        )
    try:
        skel = JointSkeleton(names, parent, offset, channels=channels, end_site=end)
    except InputError as exc:
        raise FormatError(path, str(exc)) from None
    meta = {
        "source": os.fspath(path),
        "format": "bvh",
        "units": "file units",
        "euler_wraps_in_file": wraps,
        **tolerated,
    }
    for arr in (rotation, root_pos, translation):  # fresh arrays: hand them over, no copy
        if arr is not None:
            arr.setflags(write=False)
    mo = Motion(skel, rotation, root_pos, frame_time, translation, meta)
    mo.meta["up_guess"] = guess_up_axis(mo)
    if up is not None:
        from biomorph.core.motion import to_y_up

        mo = to_y_up(mo, up)
    return mo


read_motion = read_bvh


# --------------------------------------------------------------------------- writing
def _children_lists(parent: np.ndarray) -> list[list[int]]:
    kids: list[list[int]] = [[] for _ in range(len(parent))]
    for j, p in enumerate(parent):
        if p >= 0:
            kids[int(p)].append(j)
    return kids


def _fmt(v: float, precision: int) -> str:
    s = f"{v:.{precision}f}"
    return s[1:] if s.startswith("-") and float(s) == 0 else s


def write_bvh(
    path: str | os.PathLike[str], motion_or_skeleton, precision: int = 6, euler: str = "wrap"
) -> Path:
    """Write a Motion (or a JointSkeleton as a one-frame rest pose) as BVH; atomic.

    Rotations are written as Euler angles (degrees) in each joint's channel order, composed
    with the joint's rest rotation (BVH has none); ``euler="wrap"`` (default) writes them in
    ±180°, ``"continuous"`` unwraps them over time. Joints without
    channels in ``skeleton.channels`` get the defaults (root 6, others 3 rotations)."""
    from biomorph.core.motion import Motion

    if not isinstance(precision, (int, np.integer)) or not 0 <= precision <= 12:
        raise ParameterError(f"precision {precision!r}; expected an integer 0..12")
    if euler not in ("wrap", "continuous"):
        raise ParameterError(f"euler {euler!r}; expected 'wrap' (±180°) or 'continuous'")
    euler_mode = euler
    if isinstance(motion_or_skeleton, JointSkeleton):
        sk = motion_or_skeleton
        mo = Motion(sk, tf.quat_identity((1, sk.n_joints)), sk.offset[:1].copy(), 1.0 / 30)
    elif isinstance(motion_or_skeleton, Motion):
        mo = motion_or_skeleton
    else:
        raise ParameterError(
            f"cannot write {type(motion_or_skeleton).__name__} as BVH; "
            "expected a Motion or a JointSkeleton"
        )
    sk = mo.skeleton
    n = sk.n_joints
    if sk.channels is not None:
        chans = [tuple(c) for c in sk.channels]
    else:
        chans = [_DEFAULT_ROOT if sk.parent[j] < 0 else _DEFAULT_JOINT for j in range(n)]
    trans = mo.local_translations()
    f = mo.n_frames
    # per joint, then concatenated in the depth-first order the HIERARCHY is written in
    # (index order differs from it for skeletons not stored depth-first)
    joint_cols: list[list[np.ndarray]] = [[] for _ in range(n)]
    orders = mo.rotation_orders
    has_rest = not np.allclose(sk.rest_rotation, tf.quat_identity((n,)), atol=0.0)
    for j in range(n):
        rot_names = [c for c in chans[j] if c.endswith("rotation")]
        euler_deg = None
        if rot_names:
            q = mo.rotation[:, j]
            if has_rest:
                q = tf.quat_multiply(sk.rest_rotation[j], q)
            order = orders[j]
            with warnings.catch_warnings():  # gimbal lock: scipy picks a valid solution
                warnings.simplefilter("ignore", UserWarning)
                e = tf.quat_to_euler(q, order)
            euler_deg = np.degrees(tf.unwrap_euler(e, axis=0) if euler_mode == "continuous" else e)
        for c in chans[j]:
            a = "XYZ".index(c[0])
            if c.endswith("rotation"):
                assert euler_deg is not None  # a rotation channel implies rot_names
                joint_cols[j].append(euler_deg[:, orders[j].index(c[0])])
            else:
                joint_cols[j].append(trans[:, j, a])
    from biomorph.core.motion import dfs_preorder

    cols = [c for j in dfs_preorder(sk.parent) for c in joint_cols[j]]
    data = np.column_stack(cols) if cols else np.zeros((f, 0))
    if data.size and not np.isfinite(data).all():
        bad = int(np.argwhere(~np.isfinite(data))[0][0])
        raise InputError(f"cannot write BVH: frame {bad} holds NaN or inf")
    kids = _children_lists(sk.parent)
    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        ind = "\t" * depth
        kw = "ROOT" if sk.parent[j] < 0 else "JOINT"
        lines.append(f"{ind}{kw} {sk.names[j]}")
        lines.append(f"{ind}{{")
        off = sk.offset[j]
        lines.append(f"{ind}\tOFFSET " + " ".join(_fmt(v, precision) for v in off))
        lines.append(
            f"{ind}\tCHANNELS {len(chans[j])}" + ("" if not chans[j] else " " + " ".join(chans[j]))
        )
        for k in kids[j]:
            emit(k, depth + 1)
        if not kids[j] and np.all(np.isfinite(sk.end_site[j])):
            lines.append(f"{ind}\tEnd Site")
            lines.append(f"{ind}\t{{")
            lines.append(f"{ind}\t\tOFFSET " + " ".join(_fmt(v, precision) for v in sk.end_site[j]))
            lines.append(f"{ind}\t}}")
        lines.append(f"{ind}}}")

    import sys

    limit = sys.getrecursionlimit()
    if int(sk.depth.max()) + 50 > limit:
        sys.setrecursionlimit(int(sk.depth.max()) + 100)
    for r in np.flatnonzero(sk.parent < 0):
        emit(int(r), 0)
    lines.append("MOTION")
    lines.append(f"Frames: {f}")
    lines.append(f"Frame Time: {float(mo.frame_time)!r}")
    head = ("\n".join(lines) + "\n").encode("utf-8")
    if data.shape[1]:
        c = data.shape[1]
        buf = np.empty(f * c * (precision + 16), dtype=np.uint8)
        used = _format_fixed(np.ascontiguousarray(data), int(precision), buf)
        if used < 0:
            raise InputError("cannot write BVH: a channel value exceeds 1e12 in magnitude")
        body = buf[:used].tobytes()
    else:
        body = b"\n" * f
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(head)
            fh.write(body)
    return Path(path)


__all__ = ["read_bvh", "read_motion", "write_bvh"]
