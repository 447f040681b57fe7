"""CARIBU / Canestra scene files (``.can``): one labelled triangle per line.

Line format (as in CARIBU's ``filterT.can``)::

    p <type> <label> 3 x1 y1 z1 x2 y2 z2 x3 y3 z3

``type`` is 1 (a primitive), ``label`` a string of at least 12 digits: the optical
species id (one or more digits), then the plant id (5 digits), the leaf id (3 digits) and
the element id (3 digits). Lines starting with ``#`` are comments, blank lines are ignored.

The writer takes a :class:`~biomorph.core.mesh.Mesh` whose ``face_ids`` may hold
``plant``, ``leaf``, ``element`` and ``optical`` arrays (missing ones default to 0, optical
to 1). Coordinates are written in metres times ``scale`` (``scale=100`` for centimetres,
CARIBU's customary unit). The reader returns a Mesh with unshared vertices (3 per triangle)
and those four id arrays.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from biomorph.core.mesh import Mesh
from biomorph.core.types import PathLike
from biomorph.errors import FormatError, ParameterError
from biomorph.io.atomic import write_text

_LIMITS = {"plant": 99999, "leaf": 999, "element": 999}


def encode_labels(
    optical: np.ndarray, plant: np.ndarray, leaf: np.ndarray, element: np.ndarray
) -> np.ndarray:
    """Canestra labels (strings) from id arrays; raises if an id does not fit its digits."""
    for name, arr in (("plant", plant), ("leaf", leaf), ("element", element)):
        if arr.size and (arr.min() < 0 or arr.max() > _LIMITS[name]):
            raise ParameterError(
                f"CARIBU {name} ids must lie in 0..{_LIMITS[name]}; got "
                f"{int(arr.min())}..{int(arr.max())}"
            )
    if optical.size and optical.min() < 1:
        raise ParameterError(f"CARIBU optical ids must be >= 1; got {int(optical.min())}")
    code = ((optical.astype(np.int64) * 100000 + plant) * 1000 + leaf) * 1000 + element
    return code.astype(str)


def decode_label(label: str) -> tuple[int, int, int, int]:
    """``(optical, plant, leaf, element)`` of a Canestra label string."""
    if len(label) < 12 or not label.isdigit():
        raise ValueError(f"label {label!r} is not 12+ digits")
    return int(label[:-11]), int(label[-11:-6]), int(label[-6:-3]), int(label[-3:])


def write_can(path: PathLike, mesh: Any, scale: float = 1.0, precision: int = 6) -> Path:
    """Write ``mesh`` as a Canestra ``.can`` scene (atomically)."""
    m = Mesh.from_any(mesh)
    f = m.n_faces
    ids = {
        k: np.asarray(m.face_ids.get(k, np.zeros(f, np.int64)), np.int64)
        for k in ("plant", "leaf", "element")
    }
    optical = np.asarray(m.face_ids.get("optical", np.ones(f, np.int64)), np.int64)
    labels = encode_labels(optical, ids["plant"], ids["leaf"], ids["element"])
    tri = (np.asarray(m.vertices)[np.asarray(m.faces)] * scale).reshape(f, 9)
    buf = io.StringIO()
    coords = np.char.mod(f"%.{precision}f", tri)
    body = [" ".join(row) for row in coords]
    for lab, b in zip(labels, body, strict=True):
        buf.write(f"p 1 {lab} 3 {b}\n")
    return write_text(path, buf.getvalue())


def read_can(path: PathLike, scale: float = 1.0) -> Mesh:
    """Read a ``.can`` scene; coordinates are divided by ``scale``."""
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, "file does not exist")
    tris: list[list[float]] = []
    labels: list[tuple[int, int, int, int]] = []
    for i, line in enumerate(p.read_text(errors="replace").splitlines(), start=1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        if tok[0] != "p":
            raise FormatError(p, f"line starts with {tok[0]!r}; expected 'p' (primitive)", line=i)
        if len(tok) < 4:
            raise FormatError(p, "truncated primitive line", line=i)
        try:
            n = int(tok[3])
            lab = decode_label(tok[2])
            vals = [float(t) for t in tok[4:]]
        except ValueError as exc:
            raise FormatError(p, f"bad primitive: {exc}", line=i) from None
        if n != 3 or len(vals) != 9:
            raise FormatError(
                p,
                f"expected a triangle (3 points, 9 numbers); got {n} points "
                f"and {len(vals)} numbers",
                line=i,
            )
        tris.append(vals)
        labels.append(lab)
    if not tris:
        raise FormatError(p, "holds no triangle ('p' line); expected at least one")
    arr = np.array(tris, float).reshape(-1, 3) / scale
    lab = np.array(labels, np.int64).reshape(-1, 4)
    faces = np.arange(arr.shape[0]).reshape(-1, 3)
    return Mesh(
        arr,
        faces,
        face_ids={
            "optical": lab[:, 0],
            "plant": lab[:, 1],
            "leaf": lab[:, 2],
            "element": lab[:, 3],
        },
    )


__all__ = ["decode_label", "encode_labels", "read_can", "write_can"]
