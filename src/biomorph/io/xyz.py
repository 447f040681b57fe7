"""Point clouds as text: XYZ / TXT / CSV / ASC / PTS.

Reading
-------
* The delimiter is sniffed from the first data line: comma, semicolon, or whitespace
  (spaces and/or tabs). Semicolon files whose numbers use a decimal comma (``1,5;2,5;3,5``)
  are accepted.
* An optional header line names the columns (``x y z intensity``, ``X,Y,Z,R,G,B``,
  CloudCompare's ``//X,Y,Z``). Columns named ``x``, ``y``, ``z`` (any case) are the
  coordinates, otherwise the first three columns. Every other column becomes an attribute
  under its header name, or ``column_<k>`` (0-based column index) without a header.
* A leading single-integer line (the point count of Leica PTS files) is skipped.
* Lines starting with ``#`` are comments; blank lines are ignored; CRLF is fine.
* Parsing is a compiled (numba) byte scanner: numbers with at most 2^53 as decimal mantissa
  and a decimal exponent within ±22 (every real-world coordinate, e.g. ``400123.456``) are
  converted with one correctly rounded operation, i.e. bit-identical to ``float()``; longer
  tokens (17-digit reprs) are converted exactly by numpy. Files the scanner declines
  (decimal commas, more than 200 000 long tokens) go through ``np.loadtxt``. Only when
  parsing fails is the file re-scanned line by line to name the offending line.

Malformed input (empty data, a line with a different column count, a non-numeric token,
NaN/inf coordinates, undecodable bytes) raises :class:`FormatError` naming the file and line.

Writing
-------
Shortest round-trip ``repr`` of every float64 (exact read-back), integer attributes as
integers. ``.csv`` is comma-separated with a header; other extensions are space-separated,
with a header line only when there are attributes; ``.pts`` starts with the point count.
Coordinates written are ``cloud.world_xyz`` (offset added back).
"""

from __future__ import annotations

import io
import os
import re
import warnings
from pathlib import Path

import numba
import numpy as np
from numpy.typing import NDArray

from biomorph.core.pointcloud import PointCloud
from biomorph.core.types import PathLike
from biomorph.errors import FormatError, InputError
from biomorph.io._fixed import emit_fixed
from biomorph.io.atomic import write_bytes

_NUMBER = re.compile(
    r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf|infinity)$", re.IGNORECASE
)


def _is_number(token: str) -> bool:
    return bool(_NUMBER.match(token.strip()))


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return [t.strip() for t in line.strip().split(delimiter)]


def _sniff_delimiter(line: str) -> str | None:
    if ";" in line:
        return ";"
    if "," in line:
        return ","
    return None


def _decode(path: PathLike, data: bytes) -> str:
    """UTF-8 text; Latin-1 when a header holds e.g. Windows-1252 umlauts (numbers are ASCII
    either way); NUL bytes mean a binary file and are an error naming the line."""
    nul = data.find(b"\x00")
    if nul >= 0:
        raise FormatError(
            path,
            "holds a NUL byte: a binary file, not text; expected numbers "
            "separated by spaces, tabs, commas or semicolons",
            line=data.count(b"\n", 0, nul) + 1,
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _first_lines(text: str, limit: int = 64) -> list[tuple[int, str]]:
    """First ``limit`` non-blank lines as (1-based line number, stripped text)."""
    out: list[tuple[int, str]] = []
    size = 1 << 16
    while True:  # look at a growing prefix only: never copy a large file's text
        prefix = text[:size]
        lines = prefix.split("\n")
        if size < len(text):
            lines = lines[:-1]  # the last line of the prefix may be cut
        out = [(k + 1, ln.strip()) for k, ln in enumerate(lines) if ln.strip()][:limit]
        if len(out) >= limit or size >= len(text):
            return out
        size *= 4


def _scan_for_error(
    path: PathLike, text: str, delimiter: str | None, skip: int, ncols: int
) -> FormatError:
    """Slow path (errors only): find the first line that is not ``ncols`` numbers."""
    for k, raw in enumerate(io.StringIO(text)):
        if k < skip:
            continue
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        tokens = _split(s, delimiter)
        if len(tokens) != ncols:
            return FormatError(
                path,
                f"has {len(tokens)} columns; expected {ncols} like the first data line",
                line=k + 1,
            )
        for j, tok in enumerate(tokens):
            try:
                float(tok)
            except ValueError:
                return FormatError(
                    path, f"column {j + 1} holds {tok[:40]!r}; expected a number", line=k + 1
                )
    return FormatError(path, f"could not be parsed as {ncols} numeric columns")


def _data_line_number(text: str, skip: int, row: int) -> int:
    """1-based line number of data row ``row`` (0-based, blank/comment lines not counted)."""
    seen = -1
    for k, raw in enumerate(io.StringIO(text)):
        if k < skip:
            continue
        s = raw.strip()
        if s and not s.startswith("#"):
            seen += 1
            if seen == row:
                return k + 1
    return skip + 1


def _header_names(line: str, delimiter: str | None) -> list[str]:
    s = line.lstrip("#/").strip()
    return [t.strip().strip('"').strip("'").lstrip("/") for t in _split(s, delimiter)]


def read_table(path: PathLike) -> tuple[NDArray[np.float64], list[str] | None, dict]:
    """Parse a numeric text table: ``(values float64[rows, cols], header names or None, meta)``.

    Raises :class:`FormatError` naming the line of the first malformed row.
    """
    data = Path(path).read_bytes()
    if not data.strip():
        raise FormatError(path, "file is empty; expected lines of x y z numbers")
    text = _decode(path, data)
    head = _first_lines(text)
    if not head:
        raise FormatError(path, "file holds no data lines; expected lines of x y z numbers")
    # header: leading comment/non-numeric lines; the last one before data may name columns
    names: list[str] | None = None
    names_from_comment = False
    skip = 0
    idx = 0
    delimiter: str | None = None
    head = [
        (k, ln if ln.startswith(("#", "//")) else ln.split("#", 1)[0].strip()) for k, ln in head
    ]  # inline comments after data
    head = [(k, ln) for k, ln in head if ln]
    if not head:
        raise FormatError(path, "file holds no data lines; expected lines of x y z numbers")
    while idx < len(head):
        lineno, s = head[idx]
        delimiter = _sniff_delimiter(s)
        tokens = _split(s.lstrip("#/").strip(), delimiter)
        if delimiter == ";":
            tokens = [t.replace(",", ".") for t in tokens]
        numeric = bool(tokens) and all(_is_number(t) for t in tokens)
        if s.startswith("#") or s.startswith("//") or not numeric:
            if tokens and not all(_is_number(t) for t in tokens):
                names = _header_names(s, delimiter)
                names_from_comment = s.startswith("#")
            skip = lineno
            idx += 1
            continue
        if len(tokens) == 1 and idx + 1 < len(head) and re.fullmatch(r"\d+", tokens[0]):
            nxt = _split(head[idx + 1][1], _sniff_delimiter(head[idx + 1][1]))
            if len(nxt) >= 3:  # PTS point-count line
                skip = lineno
                idx += 1
                continue
        break
    if idx >= len(head):
        raise FormatError(
            path, "holds no numeric data lines; expected lines of x y z numbers", line=head[-1][0]
        )
    first_line_no, first = head[idx]
    delimiter = _sniff_delimiter(first)
    decimal_comma = delimiter == ";" and "," in first
    ncols = len(_split(first, delimiter))
    body = text.replace(",", ".") if decimal_comma else text
    values = None
    parser = "loadtxt"
    if not decimal_comma:
        start = 0
        for _ in range(skip):  # byte offset of the first line after the header
            start = data.find(b"\n", start) + 1
        values = _fast_table(data, start, ncols, delimiter)
        parser = "compiled" if values is not None else parser
    if values is None:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                values = np.loadtxt(
                    io.StringIO(body),
                    dtype=np.float64,
                    delimiter=delimiter,
                    comments="#",
                    skiprows=skip,
                    ndmin=2,
                )
        except ValueError:
            raise _scan_for_error(path, body, delimiter, skip, ncols) from None
    if values.shape[0] == 0:
        raise FormatError(path, "holds no data rows; expected lines of x y z numbers")
    if names is not None and names_from_comment and len(names) != values.shape[1]:
        names = None  # a comment, not a header
    if names is not None and len(names) != values.shape[1]:
        # a header that does not match the columns is not a header we can use
        raise FormatError(
            path, f"header names {len(names)} columns but the data has {values.shape[1]}", line=skip
        )
    meta = {
        "format": "xyz",
        "delimiter": {None: "whitespace", ",": "comma", ";": "semicolon"}[delimiter],
        "decimal_comma": decimal_comma,
        "header": names,
        "parser": parser,
        "first_data_line": first_line_no,
        "skip_lines": skip,
    }
    return values, names, meta


# --------------------------------------------------------------------------- compiled scanner
_MAX_SLOW_TOKENS = 200_000


@numba.njit(cache=True)
def _scan_table(buf, start, ncols, delim, max_rows, slow_pos):  # pragma: no cover - compiled
    """Parse rows of ``ncols`` numbers from ``buf[start:]`` (uint8) into a flat float64 array.

    Separators: space, tab, CR and ``delim`` (0 = whitespace only). ``#`` at a line start
    begins a comment. Numbers are converted exactly when the decimal mantissa is at most
    2^53 and the decimal exponent within ±22 (one correctly rounded IEEE operation, so the
    result equals strtod); other tokens are recorded in ``slow_pos`` (start, end) for an
    exact conversion outside. Returns ``(values, rows, status, n_slow)``; status 0 ok,
    1 a line with another column count or a bad token (the caller re-scans for the message),
    2 too many slow tokens (the caller falls back to another parser).
    """
    n = buf.size
    out = np.empty(max_rows * ncols, dtype=np.float64)
    pow10 = np.empty(23, dtype=np.float64)
    pow10[0] = 1.0
    for k in range(1, 23):
        pow10[k] = pow10[k - 1] * 10.0
    row = 0
    col = 0
    n_delim = 0
    n_slow = 0
    i = start
    while i < n:
        c = buf[i]
        if c == 10:  # newline
            if col != 0:
                if col != ncols or (delim != 0 and n_delim != ncols - 1):
                    return out, row, 1, n_slow
                row += 1
            col = 0
            n_delim = 0
            i += 1
            continue
        if c == 32 or c == 9 or c == 13:
            i += 1
            continue
        if delim != 0 and c == delim:
            n_delim += 1
            i += 1
            continue
        if c == 35 and col == 0:  # '#': comment line
            while i < n and buf[i] != 10:
                i += 1
            continue
        if col >= ncols or row >= max_rows:
            return out, row, 1, n_slow
        tok = i
        neg = False
        if c == 43 or c == 45:  # + -
            neg = c == 45
            i += 1
        mant = np.uint64(0)
        ndig = 0
        sig = 0
        exp10 = 0
        overflow = False
        while i < n and 48 <= buf[i] <= 57:
            d = buf[i] - 48
            if sig > 0 or d != 0:
                sig += 1
            if sig <= 19:
                mant = mant * np.uint64(10) + np.uint64(d)
            else:
                overflow = True
                exp10 += 1
            ndig += 1
            i += 1
        if i < n and buf[i] == 46:  # '.'
            i += 1
            while i < n and 48 <= buf[i] <= 57:
                d = buf[i] - 48
                if sig > 0 or d != 0:
                    sig += 1
                if sig <= 19:
                    mant = mant * np.uint64(10) + np.uint64(d)
                    exp10 -= 1
                else:
                    overflow = True
                ndig += 1
                i += 1
        special = False
        value = 0.0
        if ndig == 0:
            # nan / inf / infinity (any case)
            j = i
            word = 0
            letters = 0
            while j < n and letters < 8 and ((65 <= buf[j] <= 90) or (97 <= buf[j] <= 122)):
                word = word * 32 + ((buf[j] | 32) - 96)
                letters += 1
                j += 1
            if letters == 3 and word == (14 * 32 + 1) * 32 + 14:  # nan
                value = np.nan
            elif letters == 3 and word == (9 * 32 + 14) * 32 + 6:  # inf
                value = np.inf
            elif letters == 8 and buf[i] | 32 == 105 and buf[i + 3] | 32 == 105:  # infinity
                value = np.inf
            else:
                return out, row, 1, n_slow
            special = True
            i = j
        elif i < n and (buf[i] == 101 or buf[i] == 69):  # exponent
            i += 1
            eneg = False
            if i < n and (buf[i] == 43 or buf[i] == 45):
                eneg = buf[i] == 45
                i += 1
            if i >= n or not (48 <= buf[i] <= 57):
                return out, row, 1, n_slow
            e = 0
            while i < n and 48 <= buf[i] <= 57:
                if e < 100000:
                    e = e * 10 + (buf[i] - 48)
                i += 1
            exp10 += -e if eneg else e
        # the token must end at a separator
        if i < n:
            t = buf[i]
            if not (t == 32 or t == 9 or t == 13 or t == 10 or (delim != 0 and t == delim)):
                return out, row, 1, n_slow
        if not special:
            if not overflow and mant <= np.uint64(9007199254740992) and -22 <= exp10 <= 22:
                value = float(mant)
                if exp10 >= 0:
                    value = value * pow10[exp10]
                else:
                    value = value / pow10[-exp10]
            else:
                if n_slow >= slow_pos.shape[0]:
                    return out, row, 2, n_slow
                slow_pos[n_slow, 0] = tok
                slow_pos[n_slow, 1] = i
                slow_pos[n_slow, 2] = row * ncols + col
                n_slow += 1
                value = 0.0
        out[row * ncols + col] = -value if neg else value
        col += 1
    if col != 0:
        if col != ncols or (delim != 0 and n_delim != ncols - 1):
            return out, row, 1, n_slow
        row += 1
    return out, row, 0, n_slow


def _fast_table(
    data: bytes, start: int, ncols: int, delimiter: str | None
) -> NDArray[np.float64] | None:
    """Compiled parse of the data lines; ``None`` when the text needs the general parser
    (malformed lines are then reported by the line-by-line scan, exotic numbers parsed by
    numpy)."""
    return _fast_table_status(data, start, ncols, delimiter)[0]


def _fast_table_status(
    data: bytes, start: int, ncols: int, delimiter: str | None
) -> tuple[NDArray[np.float64] | None, int]:
    """``(values or None, status)``: status 0 parsed, 1 malformed (a line with another
    column count or a bad token), 2 too many long tokens for the exact fast path."""
    buf = np.frombuffer(data, dtype=np.uint8)
    max_rows = data.count(b"\n", start) + 1
    slow = np.empty((_MAX_SLOW_TOKENS, 3), dtype=np.int64)
    delim = 0 if delimiter is None else ord(delimiter)
    out, rows, status, n_slow = _scan_table(buf, start, ncols, delim, max_rows, slow)
    if status != 0:
        return None, int(status)
    values = out[: rows * ncols]
    if n_slow:
        toks = [data[a:b] for a, b in slow[:n_slow, :2].tolist()]
        values[slow[:n_slow, 2]] = np.array(toks).astype(np.float64)
    return values.reshape(rows, ncols), 0


def _pick_xyz(names: list[str] | None, ncols: int) -> list[int]:
    if names is not None:
        low = [n.lower() for n in names]
        if all(c in low for c in ("x", "y", "z")):
            return [low.index("x"), low.index("y"), low.index("z")]
    return [0, 1, 2]


def _attribute_dtype(values: NDArray[np.float64]) -> NDArray:
    """Integer columns (all whole numbers within int64) become int64, others stay float64."""
    if (
        values.size
        and np.all(np.isfinite(values))
        and np.all(values == np.round(values))
        and np.abs(values).max() < 2**53
    ):
        return values.astype(np.int64)
    return values


def read_points(path: PathLike) -> PointCloud:
    """Read a text point cloud; see the module docstring for the accepted layouts."""
    values, names, meta = read_table(path)
    ncols = values.shape[1]
    if ncols < 3:
        raise FormatError(
            path,
            f"has {ncols} column(s); expected at least 3 (x y z)",
            line=meta["first_data_line"],
        )
    cols = _pick_xyz(names, ncols)
    xyz = values[:, cols]
    bad = ~np.isfinite(xyz).all(axis=1)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        line = _data_line_number(
            Path(path).read_text("utf-8", errors="replace"), meta["skip_lines"], row
        )
        raise FormatError(path, "coordinate is NaN or inf; expected finite numbers", line=line)
    attrs: dict[str, NDArray] = {}
    for j in range(ncols):
        if j in cols:
            continue
        name = names[j] if names is not None and names[j] else f"column_{j}"
        while name in attrs:
            name = f"{name}_"
        attrs[name] = _attribute_dtype(values[:, j])
    return PointCloud(np.ascontiguousarray(xyz), attrs, meta=meta, source=os.fspath(path))


def _format_block(columns: list[NDArray]) -> tuple[list[str], list[NDArray]]:
    fmts = []
    flat = []
    for c in columns:
        if np.issubdtype(c.dtype, np.integer) or c.dtype == bool:
            fmts.append("%d")
            flat.append(c.astype(np.int64))
        else:
            fmts.append("%r")
            flat.append(c.astype(np.float64))
    return fmts, flat


def write_points(path: PathLike, cloud: PointCloud, precision: int | None = None) -> Path:
    """Write ``cloud`` as text (format by extension). ``precision`` = decimals for floats
    (default: shortest exact representation)."""
    if not isinstance(cloud, PointCloud):
        cloud = PointCloud(np.asarray(cloud, dtype=float))
    xyz = cloud.world_xyz
    if not np.isfinite(xyz).all():
        raise InputError(f"{os.fspath(path)}: cloud has NaN or inf coordinates; cannot write")
    ext = Path(path).suffix.lower()
    delim = "," if ext == ".csv" else " "
    names = ["x", "y", "z"]
    columns = [xyz[:, 0], xyz[:, 1], xyz[:, 2]]
    for k, v in cloud.attributes.items():
        arr = np.asarray(v)
        if arr.ndim == 1 and (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
            names.append(re.sub(r"[\s,;#]+", "_", str(k)) or "attribute")
            columns.append(arr)
        elif arr.ndim == 2 and np.issubdtype(arr.dtype, np.number):
            for j in range(arr.shape[1]):
                names.append(f"{k}_{j}")
                columns.append(arr[:, j])
    fmts, flat = _format_block(columns)
    n = xyz.shape[0]
    lines = []
    if ext == ".pts":
        lines.append(f"{n}\n")
    if ext == ".csv" or len(names) > 3:
        lines.append(delim.join(names) + "\n")
    head = "".join(lines).encode()
    if precision is not None:
        if not 0 <= int(precision) <= 12:
            raise InputError(f"precision={precision}; expected 0 to 12 decimals")
        fast = _format_fixed_block(flat, int(precision), delim)
        if fast is not None:
            return write_bytes(path, head + fast)
        fmts = [f"%.{int(precision)}f" if f == "%r" else f for f in fmts]
    row_fmt = delim.join(fmts) + "\n"
    stacked = np.empty((n, len(flat)), dtype=object)
    for j, c in enumerate(flat):
        stacked[:, j] = c.tolist()
    body = (row_fmt * n) % tuple(stacked.ravel().tolist()) if n else ""
    return write_bytes(path, head + body.encode())


@numba.njit(cache=True)
def _fixed_kernel(floats, ints, kinds, precision, sep):  # pragma: no cover - compiled
    """Rows of fixed-point text: column ``c`` is ``floats[idx]`` (kind 0) or ``ints[idx]``
    (kind 1) with ``idx = kinds[c, 1]``. Returns (bytes, used) or used = -1 when a float is
    non-finite or too large for the integer path (the caller then uses Python formatting)."""
    ncol = kinds.shape[0]
    n = floats.shape[1] if floats.shape[0] > 0 else ints.shape[1]
    out = np.empty(n * ncol * (23 + precision) + 1, dtype=np.uint8)
    scale = 10.0**precision
    p10 = np.int64(1)
    for _ in range(precision):
        p10 *= 10
    digits = np.empty(24, dtype=np.uint8)
    pos = 0
    for i in range(n):
        for c in range(ncol):
            if c > 0:
                out[pos] = sep
                pos += 1
            if kinds[c, 0] == 1:
                q = ints[kinds[c, 1], i]
                neg = q < 0
                frac_digits = 0
                if neg:
                    q = -q
                ip = q
                fp = np.int64(0)
            else:
                v = floats[kinds[c, 1], i]
                if not np.isfinite(v) or abs(v) * scale >= 9.0e18:
                    return out, -1
                neg = v < 0
                q = np.int64(np.round(abs(v) * scale))
                if q == 0:
                    neg = False
                ip = q // p10
                fp = q % p10
                frac_digits = precision
            pos = emit_fixed(out, pos, neg, ip, fp, frac_digits, digits)
        out[pos] = 10
        pos += 1
    return out, pos


def _format_fixed_block(columns: list[NDArray], precision: int, delim: str) -> bytes | None:
    """Compiled fixed-point formatting (``%.{precision}f`` rounding half to even on the
    scaled value, so within half a unit of the last decimal); ``None`` when a value needs
    Python formatting (non-finite attribute, magnitude ≥ 9e18 / 10^precision)."""
    if not columns or len(columns[0]) == 0:
        return b""
    fl = [c for c in columns if c.dtype.kind == "f"]
    it = [c for c in columns if c.dtype.kind != "f"]
    n = len(columns[0])
    floats = np.stack(fl).astype(np.float64) if fl else np.zeros((0, n))
    ints = np.stack(it).astype(np.int64) if it else np.zeros((0, n), dtype=np.int64)
    kinds = np.zeros((len(columns), 2), dtype=np.int64)
    fi = ii = 0
    for c, col in enumerate(columns):
        if col.dtype.kind == "f":
            kinds[c] = (0, fi)
            fi += 1
        else:
            kinds[c] = (1, ii)
            ii += 1
    out, used = _fixed_kernel(floats, ints, kinds, precision, ord(delim))
    if used < 0:
        return None
    return out[:used].tobytes()


__all__ = ["read_points", "write_points", "read_table"]
