"""Mesh: triangle mesh as structure of arrays, the contract every mesh producer and writer uses.

Vertices are metres in the producer's frame (trees and leaves Z-up, creatures Y-up).
Faces are counter-clockwise seen from outside (right-hand rule gives the outward normal).

``face_ids`` labels faces by named integer arrays, e.g. ``{"plant": ..., "leaf": ...}`` for a
canopy or ``{"bone": ...}`` for a creature; writers turn each distinct combination into an
OBJ group and into PLY face properties.

Example
-------
>>> import numpy as np
>>> m = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
>>> round(m.area(), 3)
0.5
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.errors import InputError


def _readonly(arr: NDArray) -> NDArray:
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Mesh:
    """An immutable triangle mesh.

    Attributes
    ----------
    vertices : ``float64[n, 3]`` positions (metres).
    faces : ``int64[m, 3]`` vertex indices per triangle, counter-clockwise from outside.
    normals : ``float64[n, 3]`` unit vertex normals or ``None``.
    uv : ``float64[n, 2]`` texture coordinates or ``None``.
    vertex_colors : ``uint8[n, 4]`` RGBA or ``None``.
    face_ids : named ``int64[m]`` labels per face (``{"plant": ..., "leaf": ...}``).
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]
    normals: NDArray[np.float64] | None = None
    uv: NDArray[np.float64] | None = None
    vertex_colors: NDArray[np.uint8] | None = None
    face_ids: dict[str, NDArray[np.int64]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = np.array(self.vertices, dtype=np.float64, copy=True)
        if v.size == 0:
            v = v.reshape(0, 3)
        if v.ndim != 2 or v.shape[1] != 3:
            raise InputError(f"mesh vertices have shape {v.shape}; expected (n, 3)")
        if not np.isfinite(v).all():
            raise InputError("mesh vertices hold NaN or inf; expected finite coordinates")
        f_in = np.asarray(self.faces)
        if f_in.size and not np.issubdtype(f_in.dtype, np.integer):
            if not np.all(np.isfinite(f_in)) or np.any(f_in != np.round(f_in)):
                raise InputError("mesh faces hold non-integer indices")
        f = np.array(f_in, dtype=np.int64, copy=True)
        if f.size == 0:
            f = f.reshape(0, 3)
        if f.ndim != 2 or f.shape[1] != 3:
            raise InputError(f"mesh faces have shape {f.shape}; expected (m, 3) triangles")
        n, m = v.shape[0], f.shape[0]
        if m and (f.min() < 0 or f.max() >= n):
            raise InputError(
                f"mesh face index out of range [0, {n - 1}] (found {int(f.min())}..{int(f.max())})"
            )
        object.__setattr__(self, "vertices", _readonly(v))
        object.__setattr__(self, "faces", _readonly(f))
        for name, width, dtype in (
            ("normals", 3, np.float64),
            ("uv", 2, np.float64),
            ("vertex_colors", 4, np.uint8),
        ):
            val = getattr(self, name)
            if val is None:
                continue
            raw = np.asarray(val)
            if name == "vertex_colors" and raw.ndim == 2 and raw.shape[1] == 3:
                raw = np.concatenate([raw, np.full((raw.shape[0], 1), 255, raw.dtype)], axis=1)
            if name == "vertex_colors" and np.issubdtype(raw.dtype, np.floating):
                raw = np.clip(np.round(raw * 255.0), 0, 255)
            arr = np.array(raw, dtype=dtype, copy=True)
            if arr.shape != (n, width):
                raise InputError(f"mesh {name} has shape {arr.shape}; expected ({n}, {width})")
            object.__setattr__(self, name, _readonly(arr))
        ids: dict[str, NDArray[np.int64]] = {}
        for key, val in dict(self.face_ids or {}).items():
            arr = np.array(val, dtype=np.int64, copy=True).reshape(-1)
            if arr.shape != (m,):
                raise InputError(
                    f"mesh face_ids[{key!r}] has {arr.size} values; expected one per face ({m})"
                )
            ids[str(key)] = _readonly(arr)
        object.__setattr__(self, "face_ids", ids)

    # ------------------------------------------------------------------ sizes
    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def __len__(self) -> int:
        return self.n_faces

    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(min, max) corners of the vertex bounding box (metres)."""
        if self.n_vertices == 0:
            raise InputError("mesh has no vertices")
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    # ------------------------------------------------------------------ geometry
    def face_normals_unnormalised(self) -> NDArray[np.float64]:
        """Cross products ``(b - a) x (c - a)`` per face: direction = normal, length = 2·area."""
        tri = self.vertices[self.faces]
        return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])

    def face_areas(self) -> NDArray[np.float64]:
        """Area of each triangle (square metres)."""
        return 0.5 * np.linalg.norm(self.face_normals_unnormalised(), axis=1)

    def area(self) -> float:
        """Total surface area (square metres)."""
        return float(self.face_areas().sum())

    def face_normals(self) -> NDArray[np.float64]:
        """Unit face normals ``(m, 3)``; zero for degenerate triangles."""
        c = self.face_normals_unnormalised()
        norm = np.linalg.norm(c, axis=1, keepdims=True)
        return np.divide(c, norm, out=np.zeros_like(c), where=norm > 0)

    def compute_normals(self) -> Mesh:
        """A copy with area-weighted unit vertex normals (isolated vertices get ``(0,0,0)``)."""
        c = self.face_normals_unnormalised()  # length 2·area: area weighting for free
        n = self.n_vertices
        idx = self.faces.reshape(-1)  # corner -> vertex; each face's cross product per corner
        acc = (
            np.stack(
                [np.bincount(idx, weights=np.repeat(c[:, k], 3), minlength=n) for k in range(3)],
                axis=1,
            )
            if idx.size
            else np.zeros((n, 3))
        )
        norm = np.linalg.norm(acc, axis=1, keepdims=True)
        normals = np.divide(acc, norm, out=np.zeros_like(acc), where=norm > 0)
        return replace(self, normals=normals)

    # ------------------------------------------------------------------ combination
    @staticmethod
    def merge(meshes: Iterable[Any]) -> Mesh:
        """Concatenate meshes (anything :meth:`from_any` accepts), offsetting face indices.

        Optional per-vertex arrays are kept only if every part has them; a ``face_ids`` key
        missing from some parts is filled with -1 there.
        """
        parts = [Mesh.from_any(m) for m in meshes]
        if not parts:
            return Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
        offsets = np.cumsum([0] + [p.n_vertices for p in parts[:-1]])
        vertices = np.concatenate([p.vertices for p in parts])
        faces = np.concatenate([p.faces + o for p, o in zip(parts, offsets, strict=True)])
        extra: dict[str, NDArray | None] = {}
        for name in ("normals", "uv", "vertex_colors"):
            vals = [getattr(p, name) for p in parts]
            extra[name] = np.concatenate(vals) if all(v is not None for v in vals) else None
        keys: list[str] = []
        for p in parts:
            keys.extend(k for k in p.face_ids if k not in keys)
        face_ids = {
            k: np.concatenate([p.face_ids.get(k, np.full(p.n_faces, -1, np.int64)) for p in parts])
            for k in keys
        }
        return Mesh(vertices, faces, face_ids=face_ids, **extra)

    def with_(self, **changes: Any) -> Mesh:
        """A copy with some fields replaced."""
        return replace(self, **changes)

    # ------------------------------------------------------------------ conversion
    def to_trimesh(self):
        """A ``trimesh.Trimesh`` (no processing: vertices and faces kept as they are)."""
        import trimesh

        kwargs: dict[str, Any] = {}
        if self.normals is not None:
            kwargs["vertex_normals"] = self.normals
        if self.vertex_colors is not None:
            kwargs["vertex_colors"] = self.vertex_colors
        tm = trimesh.Trimesh(
            vertices=np.array(self.vertices), faces=np.array(self.faces), process=False, **kwargs
        )
        if self.uv is not None:
            tm.visual = trimesh.visual.TextureVisuals(uv=np.array(self.uv))
        for key, val in self.face_ids.items():
            tm.face_attributes[key] = np.array(val)
        return tm

    @classmethod
    def from_any(cls, obj: Any) -> Mesh:
        """Coerce ``obj`` to a :class:`Mesh`.

        Accepts a Mesh, a ``(vertices, faces)`` tuple/list, a mapping with keys ``vertices``
        and ``faces`` (plus optional ``normals``, ``uv``, ``vertex_colors``, ``face_ids``),
        an object with ``.mesh`` / ``.to_mesh()``, or a ``trimesh.Trimesh``.
        """
        if isinstance(obj, Mesh):
            return obj
        if isinstance(obj, Mapping):
            if "vertices" not in obj or "faces" not in obj:
                raise InputError(
                    "mesh dict needs keys 'vertices' and 'faces'; got "
                    f"{', '.join(map(str, obj)) or 'none'}"
                )
            allowed = {"vertices", "faces", "normals", "uv", "vertex_colors", "face_ids"}
            return cls(**{k: v for k, v in obj.items() if k in allowed})
        if isinstance(obj, tuple | list) and len(obj) == 2:
            return cls(obj[0], obj[1])
        mod = type(obj).__module__ or ""
        if mod.startswith("trimesh"):
            return _from_trimesh(obj)
        to_mesh = getattr(obj, "to_mesh", None)
        if callable(to_mesh):
            return cls.from_any(to_mesh())
        inner = getattr(obj, "mesh", None)
        if inner is not None and inner is not obj:
            return cls.from_any(inner)
        raise InputError(
            f"cannot make a mesh from {type(obj).__name__}; expected Mesh, "
            "(vertices, faces), a dict with those keys or trimesh.Trimesh"
        )


def _from_trimesh(obj: Any) -> Mesh:
    import trimesh

    if isinstance(obj, trimesh.Scene):
        geoms = (
            [g for g in obj.dump() if isinstance(g, trimesh.Trimesh)]
            if hasattr(obj, "dump")
            else []
        )
        return Mesh.merge(geoms)
    if not isinstance(obj, trimesh.Trimesh):
        raise InputError(f"cannot make a triangle mesh from {type(obj).__name__}")
    n = len(obj.vertices)
    normals = None
    cached = getattr(getattr(obj, "_cache", None), "cache", {})
    if "vertex_normals" in cached:  # only if computed or given, never forced
        normals = np.asarray(obj.vertex_normals)
    uv = None
    colors = None
    vis: Any = obj.visual  # ColorVisuals or TextureVisuals: checked by kind below
    if getattr(vis, "kind", None) == "texture" and getattr(vis, "uv", None) is not None:
        if len(vis.uv) == n:
            uv = np.asarray(vis.uv)
    elif getattr(vis, "kind", None) == "vertex":
        colors = np.asarray(vis.vertex_colors)
    face_ids = {
        k: np.asarray(v)
        for k, v in getattr(obj, "face_attributes", {}).items()
        if np.asarray(v).shape == (len(obj.faces),)
        and np.issubdtype(np.asarray(v).dtype, np.integer)
    }
    return Mesh(
        np.asarray(obj.vertices),
        np.asarray(obj.faces),
        normals=normals,
        uv=uv,
        vertex_colors=colors,
        face_ids=face_ids,
    )


__all__ = ["Mesh"]
