"""Wavefront OBJ mesh writing (and reading through trimesh).

``write_mesh`` takes anything :meth:`biomorph.core.mesh.Mesh.from_any` accepts and writes
``v`` (with ``r g b`` in [0, 1] appended when the mesh has vertex colours), ``vt`` and
``vn`` when present, and the faces grouped: one ``g`` group per distinct combination of
``face_ids`` values, named ``<key>_<value>`` joined by ``__`` (e.g. ``g plant_0__leaf_3``).
Faces are written in group order (stable within a group). Numbers use the shortest exact
float representation, so a read-back is bit-identical.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.core.types import PathLike
from biomorph.errors import BiomorphError, FormatError, InputError
from biomorph.io.atomic import write_text


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
        parts.append(
            _rows(
                "v %r %r %r %.6g %.6g %.6g",
                [v[:, 0], v[:, 1], v[:, 2], rgb[:, 0], rgb[:, 1], rgb[:, 2]],
            )
        )
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
        sel = order[bounds[g] : bounds[g + 1]]
        if sel.size == 0:
            continue
        parts.append(f"g {name}\n")
        parts.append(_rows(ffmt, [c[sel] for c in cols]))
    return write_text(path, "".join(parts))


_V = re.compile(rb"^[ \t]*v[ \t]+([^\r\n#]*)", re.M)
_VT = re.compile(rb"^[ \t]*vt[ \t]+([^\r\n#]*)", re.M)
_VN = re.compile(rb"^[ \t]*vn[ \t]+([^\r\n#]*)", re.M)
_F = re.compile(rb"^[ \t]*f[ \t]+([^\r\n#]*)", re.M)
_G = re.compile(rb"^[ \t]*g(?:[ \t]+([^\r\n#]*))?[ \t]*$", re.M)
_GROUP_NAME = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*?)_(-?\d+)$")


def _numbers(lines: list[bytes], ncols: int) -> np.ndarray | None:
    """``lines`` of ``ncols`` numbers each as float64 (compiled scanner), or ``None``."""
    from biomorph.io.xyz import _fast_table

    if not lines:
        return np.zeros((0, ncols))
    return _fast_table(b"\n".join(lines) + b"\n", 0, ncols, None)


def _face_ids_from_groups(names: list[str], group_of_face: np.ndarray) -> dict[str, np.ndarray]:
    """Group names written by :func:`write_mesh` (``plant_0__leaf_3``) back to face ids; other
    names give ``face_ids["group"]`` = index of the group in file order."""
    parsed: list[list[tuple[str, int]]] | None = []
    for name in names:
        parts = [_GROUP_NAME.match(x) for x in name.split("__")] if name else [None]
        if not all(parts):
            parsed = None
            break
        parsed.append([(m.group(1), int(m.group(2))) for m in parts])  # type: ignore[union-attr]
    if parsed:
        keys = [k for k, _ in parsed[0]]
        if all([k for k, _ in row] == keys for row in parsed) and keys != ["mesh"]:
            table = np.array([[v for _, v in row] for row in parsed], dtype=np.int64)
            return {k: table[group_of_face, j] for j, k in enumerate(keys)}
    if len(names) > 1:
        return {"group": group_of_face.astype(np.int64)}
    return {}


def _read_obj(path: PathLike, data: bytes) -> Mesh | None:
    """Vectorised OBJ parse of triangle meshes with absolute indices; ``None`` when the file
    needs the general reader (polygons, relative indices, per-corner uv/normal indices)."""
    v_lines = _V.findall(data)
    f_lines = _F.findall(data)
    if not v_lines or not f_lines:
        return None
    ncol_v = len(v_lines[0].split())
    if ncol_v not in (3, 4, 6, 7):
        return None
    verts = _numbers(v_lines, ncol_v)
    if verts is None:
        return None
    refs_text = b"\n".join(f_lines) + b"\n"
    if b"-" in refs_text:
        return None
    first = f_lines[0].split()
    if len(first) != 3:
        return None
    per_ref = first[0].count(b"/") + 1
    if b"//" in first[0]:
        per_ref = 2
    flat = _numbers([ln.replace(b"//", b" ").replace(b"/", b" ") for ln in f_lines], 3 * per_ref)
    if flat is None:
        return None
    if not np.isfinite(flat).all() or np.any(flat != np.round(flat)) or np.any(flat < 1):
        raise FormatError(path, "face indices must be positive whole numbers (1-based)")
    idx = flat.reshape(-1, 3, per_ref).astype(np.int64) - 1
    faces = idx[:, :, 0]
    same_index = per_ref == 1 or bool(np.all(idx == idx[:, :, :1]))
    colors = None
    if ncol_v in (6, 7):
        rgb = verts[:, ncol_v - 3 :]
        colors = np.clip(np.round(rgb * (255.0 if rgb.max(initial=0) <= 1 else 1.0)), 0, 255)
        colors = np.concatenate([colors, np.full((len(verts), 1), 255.0)], axis=1)
    uv = normals = None
    if same_index and per_ref >= 2:
        vt = _numbers(_VT.findall(data), 2) if b"//" not in first[0] else None
        vn = _numbers(_VN.findall(data), 3) if per_ref == 3 or b"//" in first[0] else None
        uv = vt if vt is not None and len(vt) == len(verts) else None
        normals = vn if vn is not None and len(vn) == len(verts) else None
    elif not same_index:
        return None
    # groups: split the file at 'g' lines and count the faces of each chunk
    pieces = _G.split(data)
    names = [""]
    counts = [len(_F.findall(pieces[0]))]
    for k in range(1, len(pieces), 2):
        names.append((pieces[k] or b"").decode("utf-8", "replace").strip())
        counts.append(len(_F.findall(pieces[k + 1])))
    if counts[0] == 0:
        names, counts = names[1:], counts[1:]
    group_of_face = np.repeat(np.arange(len(counts)), counts)
    face_ids = (
        _face_ids_from_groups(names, group_of_face) if group_of_face.size == len(faces) else {}
    )
    try:
        return Mesh(
            verts[:, :3],
            faces,
            normals=normals,
            uv=uv,
            vertex_colors=None if colors is None else colors.astype(np.uint8),
            face_ids=face_ids,
        )
    except InputError as exc:
        raise FormatError(path, str(exc)) from None


def read_mesh(path: PathLike) -> Mesh:
    """Read a mesh file as one :class:`Mesh`.

    OBJ triangle meshes are parsed here (vectorised): ``v`` (+ RGB), ``vt``, ``vn`` and
    ``g`` groups, whose names as written by :func:`write_mesh` (``plant_0__leaf_3``) become
    ``face_ids`` again (other group names: ``face_ids["group"]``). Polygons, relative
    indices and per-corner uv/normal indices, and every other format trimesh understands
    (GLB, STL, OFF …) go through trimesh."""
    import trimesh

    p = Path(path)
    if p.stat().st_size == 0:
        raise FormatError(path, "file is empty; expected a mesh")
    if p.suffix.lower() == ".obj":
        own = _read_obj(path, p.read_bytes())
        if own is not None:
            if not np.isfinite(own.vertices).all():
                raise FormatError(path, "vertex coordinates hold NaN or inf")
            return own
    try:
        loaded = trimesh.load(
            p,
            process=False,
            maintain_order=True,
            force=None,
            group_material=False,
            skip_materials=True,
        )
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
            parts = [
                Mesh.from_any(g).with_(face_ids={"group": np.full(len(g.faces), i)})
                for i, g in enumerate(geoms)
            ]
            mesh = Mesh.merge(parts)
        else:
            mesh = Mesh.from_any(loaded)
    except InputError as exc:
        raise FormatError(path, str(exc)) from None
    if mesh.n_vertices == 0:
        raise FormatError(path, "holds no vertices; expected a mesh")
    return mesh


__all__ = ["write_mesh", "read_mesh", "group_labels"]
