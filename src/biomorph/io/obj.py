"""Wavefront OBJ mesh writing (and reading through trimesh).

``write_mesh`` takes anything :meth:`biomorph.core.mesh.Mesh.from_any` accepts and writes
``v`` (with ``r g b`` in [0, 1] appended when the mesh has vertex colours), ``vt`` and
``vn`` when present, and the faces grouped: one ``g`` group per distinct combination of
``face_ids`` values, named ``<key>_<value>`` joined by ``__`` (e.g. ``g plant_0__leaf_3``).
Faces are written in group order (stable within a group). Numbers use the shortest exact
float representation, so a read-back is bit-identical.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.errors import BiomorphError, FormatError, InputError
from biomorph.io.atomic import write_text

PathLike = str | os.PathLike[str]


def _rows(fmt: str, columns: list[NDArray]) -> str:
    """Format rows of ``columns`` with one ``%``-format (C speed, no per-row Python)."""
    n = len(columns[0]) if columns else 0
    if n == 0:
        return ""
    table = np.empty((n, len(columns)), dtype=object)
    for j, c in enumerate(columns):
        table[:, j] = np.asarray(c).tolist()
    return ((fmt + "\n") * n) % tuple(table.ravel().tolist())


def group_labels(mesh: Mesh) -> tuple[NDArray[np.int64], list[str]]:
    """Group index per face and group names, one per distinct ``face_ids`` combination."""
    if not mesh.face_ids:
        return np.zeros(mesh.n_faces, dtype=np.int64), ["mesh"]
    keys = list(mesh.face_ids)
    table = np.stack([mesh.face_ids[k] for k in keys], axis=1)
    uniq, inverse = np.unique(table, axis=0, return_inverse=True)
    names = ["__".join(f"{k}_{int(v)}" for k, v in zip(keys, row, strict=True)) for row in uniq]
    return inverse.reshape(-1).astype(np.int64), names


def write_mesh(path: PathLike, mesh: Any, object_name: str | None = None) -> Path:
    """Write a mesh as OBJ (groups per face-id combination, normals/uv when present)."""
    m = Mesh.from_any(mesh)
    parts = ["# biomorph OBJ\n"]
    if object_name:
        parts.append(f"o {object_name}\n")
    v = m.vertices
    if m.vertex_colors is not None:
        rgb = m.vertex_colors[:, :3].astype(np.float64) / 255.0
        parts.append(_rows("v %r %r %r %.6g %.6g %.6g",
                           [v[:, 0], v[:, 1], v[:, 2], rgb[:, 0], rgb[:, 1], rgb[:, 2]]))
    else:
        parts.append(_rows("v %r %r %r", [v[:, 0], v[:, 1], v[:, 2]]))
    if m.uv is not None:
        parts.append(_rows("vt %r %r", [m.uv[:, 0], m.uv[:, 1]]))
    if m.normals is not None:
        parts.append(_rows("vn %r %r %r", [m.normals[:, 0], m.normals[:, 1], m.normals[:, 2]]))
    f = m.faces + 1
    if m.uv is not None and m.normals is not None:
        ffmt = "f %d/%d/%d %d/%d/%d %d/%d/%d"
        cols = [f[:, 0], f[:, 0], f[:, 0], f[:, 1], f[:, 1], f[:, 1], f[:, 2], f[:, 2], f[:, 2]]
    elif m.uv is not None:
        ffmt = "f %d/%d %d/%d %d/%d"
        cols = [f[:, 0], f[:, 0], f[:, 1], f[:, 1], f[:, 2], f[:, 2]]
    elif m.normals is not None:
        ffmt = "f %d//%d %d//%d %d//%d"
        cols = [f[:, 0], f[:, 0], f[:, 1], f[:, 1], f[:, 2], f[:, 2]]
    else:
        ffmt = "f %d %d %d"
        cols = [f[:, 0], f[:, 1], f[:, 2]]
    labels, names = group_labels(m)
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(len(names) + 1))
    for g, name in enumerate(names):
        sel = order[bounds[g]:bounds[g + 1]]
        if sel.size == 0:
            continue
        parts.append(f"g {name}\n")
        parts.append(_rows(ffmt, [c[sel] for c in cols]))
    return write_text(path, "".join(parts))


def read_mesh(path: PathLike) -> Mesh:
    """Read any mesh file trimesh understands (OBJ, GLB, STL, OFF ...) as one :class:`Mesh`.

    OBJ groups become ``face_ids["group"]`` (index into the order groups appear)."""
    import trimesh

    p = Path(path)
    if p.stat().st_size == 0:
        raise FormatError(path, "file is empty; expected a mesh")
    try:
        loaded = trimesh.load(p, process=False, maintain_order=True, force=None,
                              group_material=False, skip_materials=True)
    except BiomorphError:
        raise
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for bad files
        msg = str(exc).strip().splitlines()[0][:160] if str(exc).strip() else type(exc).__name__
        raise FormatError(path, f"not a readable mesh ({msg})") from None
    try:
        if isinstance(loaded, trimesh.Scene):
            geoms = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
            if not geoms:
                raise FormatError(path, "holds no triangle meshes")
            parts = [Mesh.from_any(g).with_(face_ids={"group": np.full(len(g.faces), i)})
                     for i, g in enumerate(geoms)]
            mesh = Mesh.merge(parts)
        else:
            mesh = Mesh.from_any(loaded)
    except InputError as exc:
        raise FormatError(path, str(exc)) from None
    if mesh.n_vertices == 0:
        raise FormatError(path, "holds no vertices; expected a mesh")
    return mesh


__all__ = ["write_mesh", "read_mesh", "group_labels"]
