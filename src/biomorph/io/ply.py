"""PLY (ASCII or binary) via plyfile: point clouds, skeleton graphs and meshes.

* **Point clouds**: element ``vertex`` with ``x y z`` and any other scalar properties, which
  become attributes under their names (``intensity``, ``red``, ``nx`` …) and are written back
  with their dtypes.
* **Skeleton graphs** (:class:`BranchGraph`): element ``vertex`` with
  ``x y z radius depth tree_id weight`` (``depth`` = branch order; properties only when the
  graph has them) and element ``edge`` with ``vertex1 vertex2`` = (parent, child). When
  reading, edges given the other way round or unordered (as some tools write them) are
  oriented away from the lowest node of each connected component (trees are Z-up).
* **Meshes** (:class:`Mesh`): ``vertex`` with ``x y z`` [``nx ny nz``] [``s t``]
  [``red green blue alpha``], ``face`` with ``vertex_indices`` and one int32 property per
  ``face_ids`` key.

Malformed files (truncated, bad header, non-numeric values, NaN/inf coordinates, no vertex
element, out-of-range indices) raise :class:`FormatError` naming the file (and the header line
where plyfile reports one).
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.core.mesh import Mesh
from biomorph.core.pointcloud import PointCloud
from biomorph.core.types import PathLike
from biomorph.errors import BiomorphError, FormatError, InputError
from biomorph.io.atomic import atomic_path

_GRAPH_FIELDS = ("radius", "depth", "tree_id", "weight")


# --------------------------------------------------------------------------- reading
def _short(exc: BaseException) -> str:
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return msg[:160]


def read_ply(path: PathLike) -> Any:
    """Parse ``path`` with plyfile, all data loaded; library errors become FormatError."""
    from plyfile import PlyData, PlyParseError

    p = Path(path)
    if p.stat().st_size == 0:
        raise FormatError(path, "file is empty; expected a PLY header ('ply' ...)")
    fast = _read_ascii_scalar(path)
    if fast is not None:
        return fast
    try:
        with open(p, "rb") as fh:
            ply = PlyData.read(fh)
            for el in ply.elements:  # force lazily read data (memory-mapped) to load now
                _ = el.data
    except PlyParseError as exc:
        line = getattr(exc, "line", None)
        raise FormatError(
            path, f"malformed PLY ({_short(exc)})", line=line if isinstance(line, int) else None
        ) from None
    except (
        ValueError,
        EOFError,
        IndexError,
        KeyError,
        TypeError,
        OverflowError,
        MemoryError,
        UnicodeDecodeError,
        AttributeError,
        AssertionError,
        StopIteration,
    ) as exc:
        raise FormatError(path, f"malformed or truncated PLY ({_short(exc)})") from None
    except BiomorphError:
        raise
    except Exception as exc:  # noqa: BLE001 - any other parser failure is a format error
        raise FormatError(path, f"unreadable PLY ({type(exc).__name__}: {_short(exc)})") from None
    return ply


# --------------------------------------------------------------------------- ASCII fast path
_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_TYPE_NAMES = {
    "i1": "char",
    "u1": "uchar",
    "i2": "short",
    "u2": "ushort",
    "i4": "int",
    "u4": "uint",
    "f4": "float",
    "f8": "double",
}


class _Element:
    """The part of plyfile's PlyElement interface the readers use."""

    def __init__(self, name: str, data: np.ndarray) -> None:
        self.name = name
        self.data = data
        self.count = len(data)

    def __len__(self) -> int:
        return self.count


class _Ply:
    def __init__(self, elements: list[_Element]) -> None:
        self.elements = elements
        self.text = True

    def __getitem__(self, name: str) -> _Element:
        for el in self.elements:
            if el.name == name:
                return el
        raise KeyError(name)


def _read_ascii_scalar(path: PathLike) -> _Ply | None:
    """Compiled parse of ASCII PLY files whose elements hold only scalar properties (point
    clouds, skeleton graphs). ``None`` for everything else (binary, list properties), which
    plyfile then reads."""
    from biomorph.io.xyz import _fast_table_status

    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None
    try:
        header_lines = head[:end].decode("ascii").splitlines()
    except UnicodeDecodeError:
        return None
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    fmt = None
    for ln in header_lines[1:]:
        tok = ln.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format" and len(tok) >= 2:
            fmt = tok[1]
        elif tok[0] == "element" and len(tok) == 3 and tok[2].isdigit():
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property" and len(tok) == 3 and tok[1] in _PLY_TYPES and elements:
            elements[-1][2].append((tok[2], _PLY_TYPES[tok[1]]))
        else:
            return None  # list properties or anything unusual: plyfile
    if fmt != "ascii" or not elements or any(not props for _, _, props in elements):
        return None
    data = Path(path).read_bytes()
    body_start = data.find(b"\n", end) + 1
    if body_start <= 0:
        raise FormatError(path, "header ends without a newline; truncated PLY")
    newlines = np.flatnonzero(np.frombuffer(data, dtype=np.uint8)[body_start:] == 10)
    line_ends = np.concatenate([newlines + body_start, [len(data)]])
    header_line_count = len(header_lines) + 1
    available = len(newlines) + (0 if data.endswith(b"\n") else 1)  # body lines present
    out: list[_Element] = []
    row = 0
    for name, count, props in elements:
        if row + count > available:
            raise FormatError(
                path,
                f"element '{name}' announces {count} rows but the file ends first; truncated PLY",
            )
        a = body_start if row == 0 else int(line_ends[row - 1]) + 1
        b = int(line_ends[row + count - 1]) + 1 if count else a
        chunk = data[a:b]
        if count and chunk.count(b"\n") + (0 if chunk.endswith(b"\n") else 1) != count:
            return None  # blank lines or other oddities: let plyfile decide
        values, status = (
            _fast_table_status(chunk, 0, len(props), None)
            if count
            else (np.zeros((0, len(props))), 0)
        )
        if status == 2:  # long (17-digit) tokens everywhere: numpy's exact conversion
            try:
                values = np.array(chunk.split()).astype(np.float64).reshape(count, len(props))
            except ValueError:
                values = None
        if values is None or values.shape[0] != count:
            # the line-level scan names the first bad row (1-based line in the file)
            for k, line in enumerate(chunk.split(b"\n")[:count]):
                toks = line.split()
                if len(toks) != len(props):
                    raise FormatError(
                        path,
                        f"element '{name}' row {k} has {len(toks)} values; expected {len(props)}",
                        line=header_line_count + row + k + 1,
                    )
                for t in toks:
                    try:
                        float(t)
                    except ValueError:
                        raise FormatError(
                            path,
                            f"value {t[:30].decode('latin-1')!r} is not a number",
                            line=header_line_count + row + k + 1,
                        ) from None
            return None
        rec = np.empty(count, dtype=[(pn, np.dtype(pt)) for pn, pt in props])
        for j, (pn, pt) in enumerate(props):
            col = values[:, j]
            if pt[0] in "iu":
                info = np.iinfo(np.dtype(pt))
                bad = (
                    ~np.isfinite(col) | (col != np.round(col)) | (col < info.min) | (col > info.max)
                )
                if bad.any():
                    k = int(np.flatnonzero(bad)[0])
                    raise FormatError(
                        path,
                        f"property {pn!r} ({_TYPE_NAMES[pt]}) holds {col[k]!r}"
                        "; expected an integer in range",
                        line=header_line_count + row + k + 1,
                    )
            rec[pn] = col
        out.append(_Element(name, rec))
        row += count
    return _Ply(out)


def _write_ascii_scalar(path: PathLike, elements: list) -> Path | None:
    """Own ASCII writer for elements of scalar properties (plyfile's is slow); ``None`` when
    an element has list properties."""
    from biomorph.io.atomic import write_text

    header = ["ply", "format ascii 1.0", "comment written by biomorph"]
    bodies = []
    for el in elements:
        data = el.data
        names = data.dtype.names or ()
        if any(data.dtype[n].shape != () or data.dtype[n].kind not in "iuf" for n in names):
            return None
        header.append(f"element {el.name} {len(data)}")
        fmts = []
        cols = []
        for n in names:
            dt = data.dtype[n]
            key = f"{dt.kind}{dt.itemsize}"
            if key not in _TYPE_NAMES:
                return None
            header.append(f"property {_TYPE_NAMES[key]} {n}")
            fmts.append("%d" if dt.kind in "iu" else ("%.9g" if dt.itemsize == 4 else "%r"))
            cols.append(data[n].astype(np.int64 if dt.kind in "iu" else np.float64))
        m = len(data)
        if m:
            table = np.empty((m, len(cols)), dtype=object)
            for j, c in enumerate(cols):
                table[:, j] = c.tolist()
            bodies.append(((" ".join(fmts) + "\n") * m) % tuple(table.ravel().tolist()))
    header.append("end_header")
    return write_text(path, "\n".join(header) + "\n" + "".join(bodies))


def _element(path: PathLike, ply: Any, name: str, required: bool = True) -> Any:
    try:
        return ply[name]
    except KeyError:
        if required:
            names = ", ".join(e.name for e in ply.elements) or "none"
            raise FormatError(
                path, f"has no '{name}' element (elements: {names}); expected one"
            ) from None
        return None


def _vertex_xyz(path: PathLike, vertex: Any) -> NDArray[np.float64]:
    data = vertex.data
    names = data.dtype.names or ()
    missing = [c for c in ("x", "y", "z") if c not in names]
    if missing:
        raise FormatError(
            path, f"vertex element lacks properties {', '.join(missing)}; expected x y z"
        )
    try:
        xyz = np.stack([np.asarray(data[c], dtype=np.float64) for c in "xyz"], axis=1)
    except (TypeError, ValueError) as exc:
        raise FormatError(path, f"vertex x/y/z are not scalar numbers ({_short(exc)})") from None
    if xyz.shape[0] == 0:
        raise FormatError(path, "vertex element is empty; expected at least one vertex")
    bad = ~np.isfinite(xyz).all(axis=1)
    if bad.any():
        raise FormatError(
            path,
            f"vertex {int(np.flatnonzero(bad)[0])} has a NaN or inf "
            "coordinate; expected finite numbers",
        )
    return xyz


def _scalar_props(vertex: Any, skip: set[str]) -> dict[str, NDArray]:
    data = vertex.data
    out: dict[str, NDArray] = {}
    for name in data.dtype.names or ():
        if name in skip:
            continue
        col = data[name]
        if col.dtype == object:  # list property: not a per-point scalar
            continue
        out[name] = np.array(col)
    return out


def read_points(path: PathLike) -> PointCloud:
    """Read the ``vertex`` element of a PLY as a point cloud (all scalar properties kept)."""
    ply = read_ply(path)
    vertex = _element(path, ply, "vertex")
    xyz = _vertex_xyz(path, vertex)
    attrs = _scalar_props(vertex, {"x", "y", "z"})
    meta = {"format": "ply", "ply_text": bool(ply.text), "elements": [e.name for e in ply.elements]}
    return PointCloud(xyz, attrs, meta=meta, source=os.fspath(path))


def _orient_edges(
    path: PathLike, n: int, a: NDArray[np.int64], b: NDArray[np.int64], z: NDArray[np.float64]
) -> NDArray[np.int64]:
    """Parent array from undirected edges: BFS from the lowest node of each component."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    adj = coo_matrix((np.ones(a.size), (a, b)), shape=(n, n)).tocsr()
    adj = ((adj + adj.T) > 0).astype(np.int8)
    n_comp, labels = connected_components(adj, directed=False)
    if adj.nnz // 2 > n - n_comp:
        raise FormatError(
            path,
            f"edges form a cycle ({adj.nnz // 2} edges for {n} vertices "
            f"in {n_comp} components); expected a forest",
        )
    order = np.lexsort((z, labels))  # lowest z first within each component
    roots = order[np.r_[True, labels[order][1:] != labels[order][:-1]]]
    # a virtual node n joined to every root: one BFS orients the whole forest
    ext = coo_matrix(
        (np.ones(roots.size), (np.full(roots.size, n), roots)), shape=(n + 1, n + 1)
    ).tocsr()
    big = (adj.tocoo(), ext)
    rows = np.concatenate([big[0].row, ext.tocoo().row, ext.tocoo().col])
    cols = np.concatenate([big[0].col, ext.tocoo().col, ext.tocoo().row])
    full = coo_matrix((np.ones(rows.size, np.int8), (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    _, pred = breadth_first_order(full, n, directed=True, return_predecessors=True)
    parent = pred[:n].astype(np.int64)
    parent[(parent == n) | (parent < 0)] = -1
    return parent


def read_graph(path: PathLike) -> BranchGraph:
    """Read a skeleton PLY (``vertex`` + ``edge`` elements) as a :class:`BranchGraph`."""
    ply = read_ply(path)
    vertex = _element(path, ply, "vertex")
    xyz = _vertex_xyz(path, vertex)
    n = xyz.shape[0]
    edge = _element(path, ply, "edge", required=False)
    names = vertex.data.dtype.names or ()
    if edge is None or len(edge.data) == 0:
        parent = np.full(n, -1, dtype=np.int64)
    else:
        en = edge.data.dtype.names or ()
        if not {"vertex1", "vertex2"} <= set(en):
            raise FormatError(
                path, f"edge element has properties {', '.join(en)}; expected vertex1 vertex2"
            )
        try:
            a = np.asarray(edge.data["vertex1"]).astype(np.int64)
            b = np.asarray(edge.data["vertex2"]).astype(np.int64)
        except (TypeError, ValueError) as exc:
            raise FormatError(path, f"edge indices are not integers ({_short(exc)})") from None
        bad = (a < 0) | (a >= n) | (b < 0) | (b >= n) | (a == b)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise FormatError(
                path,
                f"edge {k} joins vertices {a[k]} and {b[k]}; expected two "
                f"different indices in [0, {n - 1}]",
            )
        counts = np.bincount(b, minlength=n)
        parent = np.full(n, -1, dtype=np.int64)
        if counts.max() <= 1:
            parent[b] = a
        try:
            if counts.max() > 1:
                raise InputError("not parent->child")
            g0 = BranchGraph(xyz, parent)  # validates acyclicity
            del g0
        except InputError:
            parent = _orient_edges(path, n, a, b, xyz[:, 2])
    fields: dict[str, NDArray | None] = {}
    for key in _GRAPH_FIELDS:
        src = "order" if key == "depth" and "depth" not in names and "order" in names else key
        if src in names:
            col = np.asarray(vertex.data[src])
            if col.dtype == object:
                raise FormatError(path, f"vertex property {src!r} is a list; expected a scalar")
            vals = col.astype(np.float64)
            if not np.isfinite(vals).all():
                raise FormatError(
                    path,
                    f"vertex property {src!r} holds NaN or inf at vertex "
                    f"{int(np.flatnonzero(~np.isfinite(vals))[0])}",
                )
            fields[key] = vals
    try:
        return BranchGraph(xyz, parent, **fields)
    except InputError as exc:
        raise FormatError(path, str(exc)) from None


def read_mesh(path: PathLike) -> Mesh:
    """Read a PLY mesh (triangles; polygons are fan-triangulated) keeping face id properties."""
    ply = read_ply(path)
    vertex = _element(path, ply, "vertex")
    xyz = _vertex_xyz(path, vertex)
    face = _element(path, ply, "face", required=False)
    names = set(vertex.data.dtype.names or ())
    faces = np.zeros((0, 3), dtype=np.int64)
    face_ids: dict[str, NDArray] = {}
    if face is not None and len(face.data):
        fn = face.data.dtype.names or ()
        key = (
            "vertex_indices"
            if "vertex_indices" in fn
            else ("vertex_index" if "vertex_index" in fn else None)
        )
        if key is None:
            raise FormatError(
                path,
                "face element lacks 'vertex_indices'; expected a list property of vertex indices",
            )
        polys = face.data[key]
        try:
            lens = np.fromiter((len(p) for p in polys), dtype=np.int64, count=len(polys))
        except TypeError:
            raise FormatError(path, "face vertex_indices is not a list property") from None
        if lens.size and lens.min() < 3:
            raise FormatError(
                path,
                f"face {int(np.argmin(lens))} has {int(lens.min())} vertices; expected at least 3",
            )
        flat = (
            np.concatenate([np.asarray(p, dtype=np.int64) for p in polys])
            if lens.size
            else np.zeros(0, np.int64)
        )
        starts = np.cumsum(np.r_[0, lens[:-1]])
        ntri = lens - 2
        owner = np.repeat(np.arange(lens.size), ntri)
        k = np.arange(ntri.sum()) - np.repeat(np.cumsum(np.r_[0, ntri[:-1]]), ntri)
        base = starts[owner]
        faces = np.stack([flat[base], flat[base + k + 1], flat[base + k + 2]], axis=1)
        for name in fn:
            if name == key or face.data[name].dtype == object:
                continue
            col = np.asarray(face.data[name])
            if np.issubdtype(col.dtype, np.integer):
                face_ids[name] = col.astype(np.int64)[owner]
    normals = None
    if {"nx", "ny", "nz"} <= names:
        normals = np.stack(
            [np.asarray(vertex.data[c], np.float64) for c in ("nx", "ny", "nz")], axis=1
        )
    uv = None
    for u, v in (("s", "t"), ("u", "v"), ("texture_u", "texture_v")):
        if {u, v} <= names:
            uv = np.stack(
                [np.asarray(vertex.data[u], np.float64), np.asarray(vertex.data[v], np.float64)],
                axis=1,
            )
            break
    colors = None
    if {"red", "green", "blue"} <= names:
        cols = [np.asarray(vertex.data[c]) for c in ("red", "green", "blue")]
        alpha = np.asarray(vertex.data["alpha"]) if "alpha" in names else np.full(xyz.shape[0], 255)
        colors = np.clip(np.stack(cols + [alpha], axis=1), 0, 255).astype(np.uint8)
    try:
        return Mesh(xyz, faces, normals=normals, uv=uv, vertex_colors=colors, face_ids=face_ids)
    except InputError as exc:
        raise FormatError(path, str(exc)) from None


# --------------------------------------------------------------------------- writing
def _write(path: PathLike, elements: list, text: bool) -> Path:
    from plyfile import PlyData

    if text:
        done = _write_ascii_scalar(path, elements)
        if done is not None:
            return done
    data = PlyData(elements, text=text)
    with atomic_path(path) as tmp:
        data.write(str(tmp))
    return Path(path)


def _safe_name(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_]+", "_", str(name))
    return s or "attribute"


def write_points(path: PathLike, cloud: PointCloud, text: bool = False) -> Path:
    """Write a point cloud as PLY ``vertex`` element (float64 x y z + every 1-D attribute)."""
    from plyfile import PlyElement

    if not isinstance(cloud, PointCloud):
        cloud = PointCloud(np.asarray(cloud, dtype=float))
    xyz = cloud.world_xyz
    if not np.isfinite(xyz).all():
        raise InputError(f"{os.fspath(path)}: cloud has NaN or inf coordinates; cannot write")
    fields: list[tuple[str, NDArray]] = [("x", xyz[:, 0]), ("y", xyz[:, 1]), ("z", xyz[:, 2])]
    for k, v in cloud.attributes.items():
        arr = np.asarray(v)
        if arr.dtype == bool:
            arr = arr.astype(np.uint8)
        if arr.dtype.kind not in "iuf" or arr.dtype.itemsize > 8:
            raise InputError(
                f"{os.fspath(path)}: attribute {k!r} has dtype {arr.dtype}; "
                "PLY properties must be integers or floats"
            )
        if arr.dtype == np.int64 or arr.dtype == np.uint64:
            if arr.size and (
                arr.min() < np.iinfo(np.int32).min or arr.max() > np.iinfo(np.int32).max
            ):
                arr = arr.astype(np.float64)
            else:
                arr = arr.astype(np.int32)
        if arr.ndim == 1:
            fields.append((_safe_name(k), arr))
        elif arr.ndim == 2:
            fields.extend((_safe_name(f"{k}_{j}"), arr[:, j]) for j in range(arr.shape[1]))
    rec = np.empty(xyz.shape[0], dtype=[(name, a.dtype) for name, a in fields])
    for name, a in fields:
        rec[name] = a
    return _write(path, [PlyElement.describe(rec, "vertex")], text)


def write_graph(path: PathLike, graph: BranchGraph, text: bool = False) -> Path:
    """Write a :class:`BranchGraph` as skeleton PLY (vertex x y z [radius depth tree_id
    weight] + edge vertex1 vertex2 = parent, child)."""
    from plyfile import PlyElement

    if not isinstance(graph, BranchGraph):
        graph = getattr(graph, "graph", graph)
    if not isinstance(graph, BranchGraph):
        raise InputError(f"{os.fspath(path)}: expected a BranchGraph, got {type(graph).__name__}")
    pos = graph.position
    cols: list[tuple[str, NDArray]] = [("x", pos[:, 0]), ("y", pos[:, 1]), ("z", pos[:, 2])]
    if graph.radius is not None:
        cols.append(("radius", graph.radius.astype(np.float64)))
    if graph.depth is not None:
        cols.append(("depth", graph.depth.astype(np.int32)))
    cols.append(("tree_id", np.asarray(graph.trees).astype(np.int32)))
    if graph.weight is not None:
        cols.append(("weight", graph.weight.astype(np.float64)))
    vert = np.empty(graph.n_nodes, dtype=[(k, a.dtype) for k, a in cols])
    for k, a in cols:
        vert[k] = a
    e = graph.edges
    edge = np.empty(e.shape[0], dtype=[("vertex1", np.int32), ("vertex2", np.int32)])
    edge["vertex1"] = e[:, 0]
    edge["vertex2"] = e[:, 1]
    return _write(
        path, [PlyElement.describe(vert, "vertex"), PlyElement.describe(edge, "edge")], text
    )


def write_mesh(path: PathLike, mesh: Any, text: bool = False) -> Path:
    """Write a mesh (anything :meth:`Mesh.from_any` accepts) as PLY with face id properties."""
    from plyfile import PlyElement

    m = Mesh.from_any(mesh)
    cols: list[tuple[str, NDArray]] = [
        (c, m.vertices[:, i].astype(np.float32)) for i, c in enumerate("xyz")
    ]
    if m.normals is not None:
        cols += [(c, m.normals[:, i].astype(np.float32)) for i, c in enumerate(("nx", "ny", "nz"))]
    if m.uv is not None:
        cols += [("s", m.uv[:, 0].astype(np.float32)), ("t", m.uv[:, 1].astype(np.float32))]
    if m.vertex_colors is not None:
        cols += [
            (c, m.vertex_colors[:, i]) for i, c in enumerate(("red", "green", "blue", "alpha"))
        ]
    if np.abs(m.vertices).max(initial=0) > 1e4:  # large coordinates keep float64 precision
        cols[:3] = [(c, m.vertices[:, i]) for i, c in enumerate("xyz")]
    vert = np.empty(m.n_vertices, dtype=[(k, a.dtype) for k, a in cols])
    for k, a in cols:
        vert[k] = a
    fdtype: list[tuple] = [("vertex_indices", np.int32, (3,))]
    fdtype += [(_safe_name(k), np.int32) for k in m.face_ids]
    face = np.empty(m.n_faces, dtype=fdtype)
    face["vertex_indices"] = m.faces
    for k, v in m.face_ids.items():
        face[_safe_name(k)] = v
    return _write(
        path, [PlyElement.describe(vert, "vertex"), PlyElement.describe(face, "face")], text
    )


def ply_kind(path: PathLike) -> str:
    """``"graph"`` (has an edge element), ``"mesh"`` (has faces) or ``"points"``, from the
    header only."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError as exc:
        raise FormatError(path, f"cannot open ({exc.strerror})") from None
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise FormatError(path, "not a PLY file: expected 'ply' ... 'end_header'", line=1)
    counts = dict(re.findall(rb"^element\s+(\S+)\s+(\d+)", head[:end], flags=re.M))
    if int(counts.get(b"edge", 0)) > 0:
        return "graph"
    if int(counts.get(b"face", 0)) > 0:
        return "mesh"
    return "points"


__all__ = [
    "read_points",
    "write_points",
    "read_graph",
    "write_graph",
    "read_mesh",
    "write_mesh",
    "ply_kind",
]
