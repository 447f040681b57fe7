"""Leaf-pillar file helpers shared by the CLI, the demo and the API.

* :func:`write_leaf_mesh` — a Z-up leaf/canopy mesh by extension (``.obj .ply .glb .can``);
  glTF gets the explicit Z-up → Y-up conversion, CARIBU scenes keep Z-up (CARIBU's own
  convention);
* :func:`read_points_csv` — two named numeric columns of a CSV file with a header line.

Errors name the file and line (:class:`~biomorph.errors.FormatError`).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

from biomorph.errors import FormatError

MESH_EXT = (".obj", ".ply", ".glb", ".can")


def write_leaf_mesh(path: str | Path, mesh: Any, **gltf: Any) -> Path:
    """Write a Z-up leaf/canopy mesh by extension (.obj .ply .glb .can); returns the path.

    Extra keyword arguments go to the glTF writer (``.glb`` only)."""
    from biomorph import io

    path = Path(path)
    ext = path.suffix.lower()
    if ext == ".can":
        from biomorph.io.caribu import write_can

        return write_can(path, mesh)
    if ext == ".glb":
        if gltf:
            from biomorph.io.gltf import write_gltf

            return write_gltf(path, mesh, y_up=False, **gltf)
        return io.write_mesh(path, mesh, y_up=False)
    return io.write_mesh(path, mesh)


def read_points_csv(path: str | Path, columns: tuple[str, ...]) -> tuple[np.ndarray, ...]:
    """Named columns of a CSV file (header line required) as float arrays."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "file does not exist")
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        names = reader.fieldnames or []
        if any(c not in names for c in columns):
            raise FormatError(path, f"expected columns {' and '.join(columns)}; found "
                                    f"{', '.join(names) or 'none'}", line=1)
        vals = []
        for i, row in enumerate(reader, start=2):
            try:
                vals.append([float(row[c]) for c in columns])
            except (TypeError, ValueError):
                raise FormatError(path, f"non-numeric value in {dict(row)}", line=i) from None
    arr = np.array(vals, float).reshape(-1, len(columns))
    return tuple(arr[:, k] for k in range(len(columns)))


__all__ = ["MESH_EXT", "read_points_csv", "write_leaf_mesh"]
