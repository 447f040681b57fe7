"""Per-rank plant tables in the spirit of ADEL's ``dimT`` and ``phenT`` (CSV).

Dimension table (``dimT``; lengths in **metres**, one row per leaf rank, ranks 1..n with
none missing):

=============  ====================================================================
column         meaning
=============  ====================================================================
``rank``       phytomer rank on the main stem (1 = lowest leaf)
``L_blade``    final blade length (m), > 0
``W_blade``    maximal blade width (m), > 0
``L_sheath``   sheath length (m), >= 0 (node to collar)
``W_sheath``   sheath diameter (m), >= 0
``L_internode``  internode length (m), >= 0 (node to next node)
``W_internode``  internode diameter (m), >= 0
=============  ====================================================================

Phenology table (``phenT``; times in **Haun stages** = thermal time / phyllochron, one row
per rank, same ranks as the dimension table):

=============  ====================================================================
``rank``       phytomer rank
``tip``        Haun stage at which the blade tip emerges
``col``        Haun stage of ligulation (collar visible, blade fully extended)
``ssi``        Haun stage at which senescence starts (from the tip)
``disp``       Haun stage at which the leaf is fully senescent and disappears
=============  ====================================================================

with ``tip < col <= ssi < disp`` on every row ("phenology out of order" otherwise).
ADEL names the same quantities ``index_phytomer``, ``L_blade``…; its ``phenT`` is given in
thermal time from tip/col/ssi/disp regressions; here the Haun-stage form keeps the table
independent of the phyllochron (multiply by it for °Cd).

Readers return plain ``{column: float64 array}`` dicts (this module knows no plant); every
error names the file, line, column and value.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from biomorph.core.types import PathLike
from biomorph.errors import FormatError, InputError
from biomorph.io.atomic import write_text

Table = dict[str, NDArray[np.float64]]

DIM_COLUMNS = ("rank", "L_blade", "W_blade", "L_sheath", "W_sheath", "L_internode", "W_internode")
PHEN_COLUMNS = ("rank", "tip", "col", "ssi", "disp")
_POSITIVE = ("L_blade", "W_blade")


def _read(path: PathLike, columns: tuple[str, ...]) -> tuple[Table, list[int]]:
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, "file does not exist")
    with p.open(newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        names = [n.strip() for n in (reader.fieldnames or [])]
        missing = [c for c in columns if c not in names]
        if missing:
            raise FormatError(
                p, f"missing column(s) {', '.join(missing)}; expected {','.join(columns)}", line=1
            )
        rows, lines = [], []
        for i, row in enumerate(reader, start=2):
            row = {k.strip(): v for k, v in row.items() if k is not None}
            vals = []
            for c in columns:
                try:
                    v = float(row[c])
                except (TypeError, ValueError):
                    raise FormatError(
                        p, f"column {c}: {row.get(c)!r} is not a number", line=i
                    ) from None
                if not np.isfinite(v):
                    raise FormatError(p, f"column {c}: {v} is not finite", line=i)
                vals.append(v)
            rows.append(vals)
            lines.append(i)
    if not rows:
        raise FormatError(p, "has no rows; expected one row per leaf rank", line=2)
    arr = np.array(rows)
    table = {c: arr[:, k] for k, c in enumerate(columns)}
    _check_ranks(p, table["rank"], lines)
    return table, lines


def _check_ranks(p: Path, rank: NDArray[np.float64], lines: list[int]) -> None:
    for r, ln in zip(rank, lines, strict=True):
        if r != round(r) or r < 1:
            raise FormatError(p, f"rank {r:g} is not a positive whole number", line=ln)
    seen: dict[int, int] = {}
    for r, ln in zip(rank.astype(int), lines, strict=True):
        if r in seen:
            raise FormatError(p, f"rank {r} appears twice (also line {seen[r]})", line=ln)
        seen[r] = ln
    gaps = sorted(set(range(1, max(seen) + 1)) - set(seen))
    if gaps:
        raise FormatError(
            p,
            f"missing rank(s) {', '.join(map(str, gaps))}; expected every rank 1..{max(seen)}",
            line=lines[0],
        )


def _sorted(table: Table) -> Table:
    order = np.argsort(table["rank"])
    return {k: v[order] for k, v in table.items()}


def read_dimensions(path: PathLike) -> Table:
    """Read a dimension table (see the module docstring); sorted by rank."""
    table, lines = _read(path, DIM_COLUMNS)
    check_dimensions(table, path, lines)
    return _sorted(table)


def read_phenology(path: PathLike) -> Table:
    """Read a phenology table (see the module docstring); sorted by rank."""
    table, lines = _read(path, PHEN_COLUMNS)
    check_phenology(table, path, lines)
    return _sorted(table)


def check_dimensions(
    table: Table, path: PathLike | None = None, lines: list[int] | None = None
) -> None:
    """Refuse negative (or, for blades, zero) lengths and widths."""
    n = len(table["rank"])
    for c in DIM_COLUMNS[1:]:
        v = np.asarray(table[c], float)
        bad = np.flatnonzero(v <= 0 if c in _POSITIVE else v < 0)
        if bad.size:
            i = int(bad[0])
            what = "> 0" if c in _POSITIVE else ">= 0"
            msg = (
                f"rank {int(table['rank'][i])}: {c} = {v[i]:g} m; expected {what} "
                "(lengths in metres)"
            )
            if path is not None:
                raise FormatError(path, msg, line=None if lines is None else lines[i])
            raise InputError(msg)
    if n == 0:
        raise InputError("dimension table has no ranks")


def check_phenology(
    table: Table, path: PathLike | None = None, lines: list[int] | None = None
) -> None:
    """Refuse rows whose stages are out of order (``tip < col <= ssi < disp``)."""
    t, c, s, d = (np.asarray(table[k], float) for k in ("tip", "col", "ssi", "disp"))
    bad = np.flatnonzero(~((t < c) & (c <= s) & (s < d)))
    if bad.size:
        i = int(bad[0])
        msg = (
            f"rank {int(table['rank'][i])}: phenology out of order (tip {t[i]:g}, col "
            f"{c[i]:g}, ssi {s[i]:g}, disp {d[i]:g}); expected tip < col <= ssi < disp"
        )
        if path is not None:
            raise FormatError(path, msg, line=None if lines is None else lines[i])
        raise InputError(msg)


def write_table(path: PathLike, table: Table, columns: tuple[str, ...]) -> Path:
    """Write a dimension or phenology table as CSV (atomically)."""
    lines = [",".join(columns)]
    for i in range(len(table["rank"])):
        lines.append(
            ",".join(
                str(int(table[c][i])) if c == "rank" else f"{table[c][i]:.6g}" for c in columns
            )
        )
    return write_text(path, "\n".join(lines) + "\n")


__all__ = [
    "DIM_COLUMNS",
    "PHEN_COLUMNS",
    "check_dimensions",
    "check_phenology",
    "read_dimensions",
    "read_phenology",
    "write_table",
]
