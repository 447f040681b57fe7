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

import itertools
import math
import mmap
import os
import re
import sys
import warnings
from pathlib import Path

import numpy as np

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import FormatError, InputError, ParameterError
from biomorph.io.atomic import atomic_path

_CHANNELS = {
    c.lower(): c
    for c in ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
}
_TOKEN = re.compile(r"[{}]|[^\s{}]+")
_DEFAULT_ROOT = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
_DEFAULT_JOINT = ("Zrotation", "Xrotation", "Yrotation")


_PARALLEL_MIN_BYTES = 8 << 20  #: below this the sequential scan is as fast


def _scan_floats_parallel(buf: np.ndarray, start: int, out: np.ndarray, n_per_line: int):
    """:func:`_scan_floats` with the same result, MOTION sections of 8 MB and more parsed by
    all cores (2 cores: an 11 MB file 39 → 31 ms, a 47 MB one 242 → 191 ms; larger
    sections are streamed, :func:`_stream_motion`)."""
    from biomorph.io._bvh_kernels import _scan_floats, _scan_floats_chunks

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


# --------------------------------------------------------------------------- small files
#: MOTION values from which the compiled kernels (:mod:`biomorph.io._bvh_kernels`) are used
#: even when numba is not loaded yet. Importing numba and loading the cached kernels costs
#: 0.6 s of CPU once per process; the NumPy read costs 0.33 µs and the NumPy write 0.10 µs
#: more per value than the compiled ones (``bench/cli.py --crossover``, load 7.7), so they
#: break even near 1.9 M and 6.6 M values; 1 M values (a 2.3-minute 60-joint take at
#: 120 fps, ~8 MB of text) keeps the NumPy read under ~0.35 s.
_COMPILED_MIN_VALUES = 1_000_000
_KERNELS = "biomorph.io._bvh_kernels"
_SCAN_CHARS = b"0123456789.+- \t\n\r\x0b\x0c"  #: bytes the NumPy value path accepts


_numpy_values = [0]  #: MOTION values handled by the NumPy paths in this process so far


def _compiled(n_values: int) -> bool:
    """Use the compiled kernels for ``n_values`` MOTION values: whenever they are loaded in
    this process already, else from :data:`_COMPILED_MIN_VALUES` on, for one call or summed
    over the calls so far (reading many small files switches once the NumPy overhead has
    cost about the kernels' load time)."""
    return (
        n_values >= _COMPILED_MIN_VALUES
        or _numpy_values[0] >= _COMPILED_MIN_VALUES
        or _KERNELS in sys.modules
    )


def _count_words(buf: np.ndarray, lo: int, hi: int) -> int:
    """Whitespace-separated words in ``buf[lo:hi]``."""
    if _compiled((hi - lo) // 4):
        from biomorph.io._bvh_kernels import _count_tokens

        return int(_count_tokens(buf, lo, hi))
    return len(buf[lo:hi].tobytes().split())


def _values_numpy(raw: bytes, data_start: int, n_frames: int, n_ch: int) -> np.ndarray | None:
    """The MOTION values ``(n_frames, n_ch)`` of a clean section with Python's float parser,
    or ``None`` (then the compiled scanner reads it, with its exact diagnostics).

    Same bits as the scanner: only tokens of at most 15 characters without an exponent are
    taken (mantissa below 10^15 < 2^53 and at most 15 decimals: the scanner's one division
    by an exact power of ten is then correctly rounded, like ``float``); anything else — a
    letter, an exponent, a longer token, a line with another number of values, a count other
    than ``Frames × channels`` or a malformed number — returns ``None``."""
    data = raw[data_start:]
    if n_ch <= 0 or data.translate(None, _SCAN_CHARS):
        return None
    rows = [w for w in map(bytes.split, data.split(b"\n")) if w]
    if len(rows) != n_frames or any(len(w) != n_ch for w in rows):
        return None
    words = itertools.chain.from_iterable
    if max(map(len, words(rows))) > 15:
        return None
    try:
        vals = np.fromiter(map(float, words(rows)), dtype=np.float64, count=n_frames * n_ch)
    except ValueError:
        return None
    return vals.reshape(n_frames, n_ch)


def _euler_numpy(data: np.ndarray, rot_cols: np.ndarray, rot_axes: np.ndarray, out) -> None:
    """NumPy ``_bvh_kernels._euler_kernel``: per joint, the product of its Euler channels'
    quaternions in listed order, hemisphere-continuous over frames; the same arithmetic in
    the same order (same bits)."""
    from biomorph.core.motion import _store_flips

    d2r = np.pi / 180.0
    f = data.shape[0]
    for j in range(rot_cols.shape[0]):
        x: np.ndarray | float = 0.0
        y: np.ndarray | float = 0.0
        z: np.ndarray | float = 0.0
        w: np.ndarray | float = 1.0
        for m in range(3):
            col = rot_cols[j, m]
            if col < 0:
                continue
            h = 0.5 * data[:, col] * d2r
            s_ = np.sin(h)
            c = np.cos(h)
            ax = rot_axes[j, m]
            bx = s_ if ax == 0 else 0.0
            by = s_ if ax == 1 else 0.0
            bz = s_ if ax == 2 else 0.0
            x, y, z, w = (
                w * bx + x * c + y * bz - z * by,
                w * by - x * bz + y * c + z * bx,
                w * bz + x * by - y * bx + z * c,
                w * c - x * bx - y * by - z * bz,
            )
        out[:, j, 0] = x
        out[:, j, 1] = y
        out[:, j, 2] = z
        out[:, j, 3] = w
    if f > 1:
        q = out
        dots = (
            q[1:, :, 0] * q[:-1, :, 0]
            + q[1:, :, 1] * q[:-1, :, 1]
            + q[1:, :, 2] * q[:-1, :, 2]
            + q[1:, :, 3] * q[:-1, :, 3]
        )
        q[1:][_store_flips(dots)] *= -1.0


def _value_limit(precision: int) -> float:
    """Largest magnitude the fixed-point writer takes: 1e12, and below 2**62 once scaled by
    ``10**precision`` (the digits are formed in int64; 1e11 at 8 decimals would overflow)."""
    return min(1e12, 2.0**62 / 10.0**precision)


def _format_numpy(values: np.ndarray, precision: int) -> bytes | None:
    """NumPy ``_bvh_kernels._format_fixed``: ``values (f, c)`` as fixed-point text rows
    (half-up on the scaled magnitude, ``-`` unless it rounds to 0), the same bytes; ``None``
    if a value is too large."""
    a = np.abs(values)
    if not (a < _value_limit(precision)).all():
        return None
    p10 = 10**precision
    x = np.floor(a * 10.0**precision + 0.5).astype(np.int64)
    ip = x // p10
    fp = x - ip * p10
    neg = (values < 0) & (x != 0)
    nd = len(str(int(ip.max()))) if ip.size else 1  # integer digits of the largest value
    n_digits = 1 + sum((ip >= 10**k).astype(np.int64) for k in range(1, nd))
    f, c = values.shape
    width = 1 + nd + (precision + 1 if precision > 0 else 0) + 1
    cells = np.zeros((f, c, width), dtype=np.uint8)
    keep = np.zeros((f, c, width), dtype=bool)
    cells[..., 0] = 45  # '-'
    keep[..., 0] = neg
    rest = ip.copy()
    for k in range(nd - 1, -1, -1):
        cells[..., 1 + k] = 48 + rest % 10
        rest //= 10
        keep[..., 1 + k] = (nd - k) <= n_digits  # no leading zeros
    col = 1 + nd
    if precision > 0:
        cells[..., col] = 46
        keep[..., col] = True
        rest = fp.copy()
        for k in range(precision - 1, -1, -1):
            cells[..., col + 1 + k] = 48 + rest % 10
            rest //= 10
        keep[..., col + 1 : col + 1 + precision] = True
        col += 1 + precision
    cells[..., col] = 32
    cells[:, -1, col] = 10
    keep[..., col] = True
    return cells[keep].tobytes()


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
    total = _count_words(buf, data_start, buf.size)
    if n_ch <= 0:
        return -1, buf.size, False
    if total % n_ch == 0:
        return total // n_ch, buf.size, False
    text_end = buf.size
    while text_end > data_start and buf[text_end - 1] in (9, 10, 11, 12, 13, 32):
        text_end -= 1
    nl = np.flatnonzero(buf[data_start:text_end] == 10)
    end = data_start + (int(nl[-1]) + 1 if nl.size else 0)
    head = _count_words(buf, data_start, end)
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
    if not _compiled(n_frames * n_ch):
        vals = _values_numpy(raw, data_start, n_frames, n_ch)
        if vals is not None:
            _numpy_values[0] += vals.size  # counts towards loading the kernels
            conv = _MotionRows(n_frames, rot_cols, rot_axes, pos_cols, offset)
            conv.add(vals)
            return conv.result()
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
        compiled = _compiled(vals.size) or t0 > 0
        if compiled:
            from biomorph.io._bvh_kernels import _chain_block, _count_wraps, _euler_kernel

            _euler_kernel(vals, self.rot_cols, self.rot_axes, self.rotation[t0:t1])
            if t0 > 0:
                _chain_block(self.rotation, t0)
        else:
            _euler_numpy(vals, self.rot_cols, self.rot_axes, self.rotation[t0:t1])
        pc = self.pos_cols
        for a in range(3):
            self.root_pos[t0:t1, a] = vals[:, pc[0, a]] if pc[0, a] >= 0 else self.offset[0, a]
        for j in self.inner:
            for a in range(3):
                if pc[j, a] >= 0:
                    self.translation[t0:t1, j, a] = vals[:, pc[j, a]]
        if self.rc.size:
            self.wraps += (
                int(_count_wraps(vals, self.rc))
                if compiled
                else int(np.count_nonzero(np.abs(np.diff(vals[:, self.rc], axis=0)) > 180.0))
            )
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


def _stream_motion(buf, data_start, n_frames, n_ch, rot_cols, rot_axes, pos_cols, offset):
    """The MOTION section of a big file in blocks of ``_STREAM_FRAMES`` frames through one
    reused value buffer, so the ``frames × channels`` table of values is never held whole
    (on a 1-hour 60-joint take that table is 630 MB, and first-touching fresh memory is a
    large part of the read time). Equal to :func:`_parse_motion` bit for bit; returns
    ``None`` at the first irregularity (a malformed value, a short line, too many or too
    few values), and the caller re-reads with :func:`_parse_motion` for its diagnostics."""
    from biomorph.io._bvh_kernels import _scan_floats

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
def _format_rows(data: np.ndarray, precision: int) -> bytes:
    """The MOTION rows as fixed-point text (compiled for big tables, else NumPy: same bytes)."""
    f, c = data.shape
    if _compiled(data.size):
        from biomorph.io._bvh_kernels import _format_fixed

        buf = np.empty(f * c * (precision + 16), dtype=np.uint8)
        used = _format_fixed(np.ascontiguousarray(data), precision, _value_limit(precision), buf)
        body = None if used < 0 else buf[:used].tobytes()
    else:
        body = _format_numpy(data, precision)
        _numpy_values[0] += data.size
    if body is None:
        raise InputError(
            f"cannot write BVH: a channel value exceeds {_value_limit(precision):.3g} in "
            f"magnitude (the most {precision} decimals can hold)"
        )
    return body


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

    limit = sys.getrecursionlimit()
    depth = [0] * n  # parents precede children
    for j in range(n):
        depth[j] = depth[sk.parent[j]] + 1 if sk.parent[j] >= 0 else 0
    if max(depth) + 50 > limit:
        sys.setrecursionlimit(max(depth) + 100)
    for r in np.flatnonzero(sk.parent < 0):
        emit(int(r), 0)
    lines.append("MOTION")
    lines.append(f"Frames: {f}")
    lines.append(f"Frame Time: {float(mo.frame_time)!r}")
    head = ("\n".join(lines) + "\n").encode("utf-8")
    if data.shape[1]:
        body = _format_rows(data, int(precision))
    else:
        body = b"\n" * f
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(head)
            fh.write(body)
    return Path(path)


__all__ = ["read_bvh", "read_motion", "write_bvh"]
