"""The species dataset in the seed's annotation scheme (44 species, ``species.csv``).

Per species: the spine as ten 2-D control points of three cubic Béziers (neck head→shoulder,
back shoulder→hip, tail hip→tip) in a 1000×1000 px side-view frame (y up, head on the left,
skeleton at the bottom centre), six limb-segment lengths in px, wings (0/1), number of legs
with ground contact (0/2/4), weight in kg and class — the seed's 29 PCA dimensions plus the
class — and, beyond the seed, stance, posture, skull type and length, trunk girth,
vertebra counts per region and the hoofed digits of unguligrade species. See ``README.md``
beside this file for how the numbers were made.

Example
-------
>>> ds = load_species()
>>> len(ds), ds.points.shape
(44, (44, 10, 2))
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from biomorph.errors import FormatError, InputError

#: Built-in dataset file.
SPECIES_CSV = Path(__file__).with_name("species.csv")

CLASSES = ("fish", "amphibian", "reptile", "bird", "mammal")
STANCES = ("plantigrade", "digitigrade", "unguligrade")
POSTURES = ("erect", "sprawling", "crouched")
LIMB_COLUMNS = ("upper_arm", "lower_arm", "hand", "upper_leg", "lower_leg", "foot")
POINT_COLUMNS = tuple(f"p{i}{c}" for i in range(10) for c in "xy")
REQUIRED = ("name", "class", "weight_kg", "wings", "legs") + POINT_COLUMNS + LIMB_COLUMNS
#: Defaults for the optional (beyond-seed) columns, per class.
CLASS_DEFAULTS = {
    "fish": dict(
        stance="plantigrade",
        posture="erect",
        skull="fish",
        girth=0.4,
        cervical=0,
        trunk=24,
        caudal=24,
    ),
    "amphibian": dict(
        stance="plantigrade",
        posture="sprawling",
        skull="amphibian",
        girth=0.45,
        cervical=1,
        trunk=16,
        caudal=10,
    ),
    "reptile": dict(
        stance="plantigrade",
        posture="sprawling",
        skull="reptile_long",
        girth=0.5,
        cervical=8,
        trunk=18,
        caudal=35,
    ),
    "bird": dict(
        stance="digitigrade",
        posture="erect",
        skull="bird",
        girth=0.65,
        cervical=14,
        trunk=12,
        caudal=7,
    ),
    "mammal": dict(
        stance="digitigrade",
        posture="erect",
        skull="mammal_long",
        girth=0.6,
        cervical=7,
        trunk=20,
        caudal=18,
    ),
}


@dataclass(frozen=True, eq=False)
class SpeciesTable:
    """Species annotations as structure of arrays (px in the 1000-px frame, y up)."""

    name: tuple[str, ...]
    german: tuple[str, ...]
    cls: tuple[str, ...]
    weight: NDArray[np.float64]  # kg
    wings: NDArray[np.float64]  # 0/1
    legs: NDArray[np.float64]  # 0/2/4
    points: NDArray[np.float64]  # (n, 10, 2) px
    lengths: NDArray[np.float64]  # (n, 6) px, LIMB_COLUMNS order
    stance: tuple[str, ...]
    posture: tuple[str, ...]
    skull: tuple[str, ...]
    skull_length: NDArray[np.float64]  # px
    girth: NDArray[np.float64]  # trunk depth / back chord
    counts: NDArray[np.int64]  # (n, 3) cervical, trunk, caudal vertebrae
    hoof_digits: NDArray[np.int64]  # hoofed digits per foot (unguligrade: 1 or 2, else 0)

    def __len__(self) -> int:
        return len(self.name)

    def index(self, name: str) -> int:
        """Row of species ``name`` (English key or German name)."""
        for i, (a, b) in enumerate(zip(self.name, self.german, strict=True)):
            if name in (a, b):
                return i
        raise InputError(f"no species named {name!r}; known: {', '.join(self.name[:6])} …")

    def rows(self) -> list[dict[str, object]]:
        """One dict per species with every CSV column (for writing and ``dataset`` listing)."""
        out = []
        for i in range(len(self)):
            row: dict[str, object] = {
                "name": self.name[i],
                "german": self.german[i],
                "class": self.cls[i],
                "weight_kg": float(self.weight[i]),
                "wings": int(self.wings[i]),
                "legs": int(self.legs[i]),
            }
            for k, col in enumerate(POINT_COLUMNS):
                row[col] = float(self.points[i].reshape(-1)[k])
            for k, col in enumerate(LIMB_COLUMNS):
                row[col] = float(self.lengths[i, k])
            row.update(
                stance=self.stance[i],
                posture=self.posture[i],
                skull=self.skull[i],
                skull_length=float(self.skull_length[i]),
                girth=float(self.girth[i]),
                cervical=int(self.counts[i, 0]),
                trunk=int(self.counts[i, 1]),
                caudal=int(self.counts[i, 2]),
                hoof_digits=int(self.hoof_digits[i]) if self.hoof_digits[i] else "",
            )
            out.append(row)
        return out


def _num(path: Path, line: int, row: dict[str, str], key: str) -> float:
    raw = (row.get(key) or "").strip()
    try:
        val = float(raw)
    except ValueError:
        raise FormatError(
            path, f"column {key!r} holds {raw!r}; expected a number", line=line
        ) from None
    if not np.isfinite(val):
        raise FormatError(path, f"column {key!r} is {raw}; expected a finite number", line=line)
    return val


def _row_values(path: Path, line: int, row: dict[str, str]) -> dict[str, object]:
    cls = (row.get("class") or "").strip().lower()
    if cls not in CLASSES:
        raise FormatError(
            path, f"class {cls!r} unknown; expected one of {', '.join(CLASSES)}", line=line
        )
    d = CLASS_DEFAULTS[cls]
    weight = _num(path, line, row, "weight_kg")
    if weight <= 0:
        raise FormatError(path, f"weight_kg {weight} must be > 0 kg", line=line)
    wings = _num(path, line, row, "wings")
    legs = _num(path, line, row, "legs")
    if wings not in (0.0, 1.0):
        raise FormatError(path, f"wings {wings} must be 0 or 1", line=line)
    if legs not in (0.0, 2.0, 4.0):
        raise FormatError(
            path, f"legs {legs} must be 0, 2 or 4 (legs with ground contact)", line=line
        )
    pts = np.array([_num(path, line, row, c) for c in POINT_COLUMNS]).reshape(10, 2)
    lengths = np.array([_num(path, line, row, c) for c in LIMB_COLUMNS])
    if np.any(lengths < 0):
        raise FormatError(path, "limb lengths must be >= 0 px", line=line)

    def opt(key: str, cast=str):
        raw = (row.get(key) or "").strip()
        if not raw:
            return d.get(key)
        return cast(raw) if cast is str else _num(path, line, row, key)

    stance, posture, skull = opt("stance"), opt("posture"), opt("skull")
    if stance not in STANCES:
        raise FormatError(
            path, f"stance {stance!r}; expected one of {', '.join(STANCES)}", line=line
        )
    if posture not in POSTURES:
        raise FormatError(
            path, f"posture {posture!r}; expected one of {', '.join(POSTURES)}", line=line
        )
    hooves = _hoof_digits(path, line, row, stance)
    back_chord = float(np.linalg.norm(pts[6] - pts[3]))
    skull_len = opt("skull_length", float)
    if skull_len is None:
        skull_len = 0.45 * back_chord
    return dict(
        name=(row.get("name") or f"species_{line}").strip(),
        german=(row.get("german") or "").strip(),
        cls=cls,
        weight=weight,
        wings=wings,
        legs=legs,
        points=pts,
        lengths=lengths,
        stance=stance,
        posture=posture,
        skull=skull,
        skull_length=float(skull_len),
        girth=float(opt("girth", float)),
        counts=[int(opt(k, float)) for k in ("cervical", "trunk", "caudal")],
        hoof_digits=hooves,
    )


#: Hoofed digits per foot: perissodactyls stand on one (horse: digit III), artiodactyls on
#: two (cattle, deer: III + IV). An unguligrade row without the column is an artiodactyl
#: (most hoofed species).
HOOF_DIGITS = (1, 2)


def _hoof_digits(path: Path, line: int, row: dict[str, str], stance: str) -> int:
    raw = (row.get("hoof_digits") or "").strip()
    if stance != "unguligrade":
        if raw and _num(path, line, row, "hoof_digits") != 0:
            raise FormatError(
                path, f"hoof_digits {raw} on a {stance} species; expected it empty or 0", line=line
            )
        return 0
    if not raw:
        return 2
    v = _num(path, line, row, "hoof_digits")
    if v not in HOOF_DIGITS:
        raise FormatError(
            path,
            f"hoof_digits {raw}; expected 1 (perissodactyl: horse) or 2 (artiodactyl: cattle, "
            "deer)",
            line=line,
        )
    return int(v)


def load_species(path: str | os.PathLike[str] | None = None) -> SpeciesTable:
    """Load the species CSV (default: the built-in 44 species).

    Raises :class:`FormatError` naming the file, line and column on malformed rows.
    """
    p = SPECIES_CSV if path is None else Path(path)
    if not p.is_file():
        raise FormatError(p, "species table does not exist; expected a CSV file")
    with p.open(newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
        if missing:
            raise FormatError(p, f"missing columns {', '.join(missing)}", line=1)
        vals = [_row_values(p, i + 2, row) for i, row in enumerate(reader)]
    if len(vals) < 3:
        raise FormatError(p, f"holds {len(vals)} species; PCA needs at least 3")
    names = [v["name"] for v in vals]
    if len(set(names)) != len(names):
        dup = [n for n in names if names.count(n) > 1][0]
        raise FormatError(p, f"species {dup!r} occurs more than once")
    return SpeciesTable(
        name=tuple(names),
        german=tuple(v["german"] for v in vals),
        cls=tuple(v["cls"] for v in vals),
        weight=np.array([v["weight"] for v in vals]),
        wings=np.array([v["wings"] for v in vals]),
        legs=np.array([v["legs"] for v in vals]),
        points=np.array([v["points"] for v in vals]),
        lengths=np.array([v["lengths"] for v in vals]),
        stance=tuple(v["stance"] for v in vals),
        posture=tuple(v["posture"] for v in vals),
        skull=tuple(v["skull"] for v in vals),
        skull_length=np.array([v["skull_length"] for v in vals]),
        girth=np.array([v["girth"] for v in vals]),
        counts=np.array([v["counts"] for v in vals], dtype=np.int64),
        hoof_digits=np.array([v["hoof_digits"] for v in vals], dtype=np.int64),
    )


def append_species(
    path: str | os.PathLike[str], row: dict[str, object], base: str | os.PathLike[str] | None = None
) -> Path:
    """Append one species row to the CSV at ``path`` (created from ``base``/built-in if absent).

    The whole file is validated by :func:`load_species` before it is written (atomically).
    """
    from biomorph.io.atomic import write_text

    p = Path(path)
    src = p if p.exists() else (SPECIES_CSV if base is None else Path(base))
    table = load_species(src)
    rows = table.rows()
    if row["name"] in table.name:
        raise InputError(f"species {row['name']!r} is already in {src}; choose another --name")
    rows.append(row)
    cols = list(rows[0].keys())
    import io as _io

    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: r.get(k, "") for k in cols})
    # validate the new table before replacing anything
    import tempfile

    with tempfile.NamedTemporaryFile("w", suffix=".csv", delete=False, encoding="utf-8") as tmp:
        tmp.write(buf.getvalue())
    try:
        load_species(tmp.name)
    finally:
        os.unlink(tmp.name)
    return write_text(p, buf.getvalue())


__all__ = [
    "SpeciesTable",
    "load_species",
    "append_species",
    "SPECIES_CSV",
    "CLASSES",
    "STANCES",
    "POSTURES",
    "LIMB_COLUMNS",
    "HOOF_DIGITS",
]
