"""Error-driven greedy insertion: an adaptive triangle mesh of a twisted / undulated leaf.

A structured strip mesh (cross-sections × a few vertices across) cannot follow margin waves
that are out of phase on the two sides of the midrib, nor put vertices only where the
surface bends. Here the mesh is refined on the 3-D surface itself, as terrain
simplification does (Garland & Heckbert 1995, "Fast polygonal approximation of terrains and
height fields", greedy insertion with data-dependent triangulation):

* **Candidates** — the exact surface ``S(s, u)`` evaluated on a fine grid of nodes (``n_s``
  along the visible midrib × ``n_u`` across; a closed end is one node).
* **Domain** — nodes live in the flat parameter domain ``(s, u·ρ(s))`` with ``ρ`` piecewise
  linear (1 on an open end, 0 on a closed one), so the domain is convex and its boundary
  is the leaf's margins and open ends.
* **Start** — the domain's corners (base margins, tip margins or tip point): 1 or 2
  triangles.
* **Step** — the node whose 3-D distance to the current mesh (to the linear interpolation
  of the triangle holding it) is largest is inserted: inside a triangle (+2 triangles) or
  on a margin / open end (+1). The new edges are then **flipped** while that lowers the
  largest error of the two triangles sharing them (lexicographic on (max, sum of squares),
  so flipping terminates), which lets triangles stretch along the blade or across it as
  the surface asks.
* **Budget** — exact: when one triangle is left to add, the worst boundary node is
  inserted instead.

Errors are distances in metres. Pure numpy over a few thousand nodes and a few hundred
triangles (the mesh of one leaf).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from biomorph.core.types import Array
from biomorph.errors import ParameterError

_EPS = 1e-12


@njit(cache=True)
def _dot3(u, v):  # pragma: no cover - compiled
    """``u · v`` of 3-vectors in a fixed order: ``@`` goes through BLAS, whose kernel (and so
    the last bit) depends on the CPU, and the greedy refinement amplifies a last-bit change
    into another mesh (0.44 vs 0.52 mm at 200 triangles on two x86-64 machines)."""
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


@njit(cache=True)
def _dist_tri(p, a, b, c):  # pragma: no cover - compiled
    """Exact distance of point ``p`` to triangle ``abc`` (closest point by regions)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = _dot3(ab, ap)
    d2 = _dot3(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        q = a
    else:
        bp = p - b
        d3 = _dot3(ab, bp)
        d4 = _dot3(ac, bp)
        cp = p - c
        d5 = _dot3(ab, cp)
        d6 = _dot3(ac, cp)
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            q = b
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0 and d1 - d3 > 0.0:
            q = a + ab * (d1 / (d1 - d3))
        elif d6 >= 0.0 and d5 <= d6:
            q = c
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0 and d2 - d6 > 0.0:
            q = a + ac * (d2 / (d2 - d6))
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0 and (d4 - d3) + (d5 - d6) > 0.0:
            q = b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))
        else:
            den = va + vb + vc
            if den == 0.0:  # degenerate triangle: nearest of its corners
                q = a
                for x in (b, c):
                    if _dot3(p - x, p - x) < _dot3(p - q, p - q):
                        q = x
            else:
                q = a + ab * (vb / den) + ac * (vc / den)
    e = p - q
    return np.sqrt(_dot3(e, e))


@njit(cache=True)
def _place(pts, dom, idx, tris, is_vertex):  # pragma: no cover - compiled
    """Locate nodes ``idx`` in the domain triangles ``tris (k, 3)``: local face (-1 when
    outside all), distance to that triangle in 3-D, and (max, sum of squares) of it."""
    n = idx.size
    face = np.full(n, -1, np.int64)
    err = np.zeros(n)
    worst = 0.0
    ss = 0.0
    for t in range(tris.shape[0]):
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        ax, ay = dom[a, 0], dom[a, 1]
        m00, m01 = dom[b, 0] - ax, dom[c, 0] - ax
        m10, m11 = dom[b, 1] - ay, dom[c, 1] - ay
        det = m00 * m11 - m01 * m10
        if det == 0.0:
            continue
        for k in range(n):
            if face[k] >= 0:
                continue
            qx, qy = dom[idx[k], 0] - ax, dom[idx[k], 1] - ay
            l1 = (qx * m11 - qy * m01) / det
            l2 = (qy * m00 - qx * m10) / det
            if l1 < -1e-9 or l2 < -1e-9 or l1 + l2 > 1.0 + 1e-9:
                continue
            face[k] = t
            if not is_vertex[idx[k]]:
                e = _dist_tri(pts[idx[k]], pts[a], pts[b], pts[c])
                err[k] = e
                worst = max(worst, e)
                ss += e * e
    return face, err, worst, ss


def _lattice(order: int) -> Array:
    """Barycentric points ``(i, j, k)/order`` with ``i + j + k = order``, corners left out."""
    pts = [
        (i / order, j / order, (order - i - j) / order)
        for i in range(order + 1)
        for j in range(order + 1 - i)
    ]
    return np.array([p for p in pts if max(p) < 1.0])


# sample points checked inside every candidate triangle besides the nodes it holds, so a
# thin triangle between the nodes is measured as well as a fat one (order 6: 25 points, a
# sixth of the triangle apart)
_SAMPLES = _lattice(6)


@njit(cache=True)
def _rho(s, kind):  # pragma: no cover - compiled
    if kind == 1:
        return 1.0 - s
    if kind == 2:
        return s
    if kind == 3:
        return 1.0 - abs(2.0 * s - 1.0)
    return 1.0


@njit(cache=True)
def _surface_at(grid, x, y, kind):  # pragma: no cover - compiled
    """Surface point at domain ``(x, y)`` by bilinear interpolation of the node grid."""
    n_s, n_u = grid.shape[0], grid.shape[1]
    r = _rho(x, kind)
    u = y / r if r > 1e-12 else 0.0
    fi = min(max(x, 0.0), 1.0) * (n_s - 1)
    fj = min(max(u + 0.5, 0.0), 1.0) * (n_u - 1)
    i = min(int(fi), n_s - 2)
    j = min(int(fj), n_u - 2)
    a, b = fi - i, fj - j
    return (
        (1 - a) * (1 - b) * grid[i, j]
        + a * (1 - b) * grid[i + 1, j]
        + (1 - a) * b * grid[i, j + 1]
        + a * b * grid[i + 1, j + 1]
    )


@njit(cache=True)
def _sample_cost(grid, kind, dom, pts, tris, samples):  # pragma: no cover - compiled
    """(max, sum of squares) of the distance of each triangle's sample points on the
    surface to that triangle."""
    worst = 0.0
    ss = 0.0
    for t in range(tris.shape[0]):
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        for k in range(samples.shape[0]):
            w0, w1, w2 = samples[k, 0], samples[k, 1], samples[k, 2]
            x = w0 * dom[a, 0] + w1 * dom[b, 0] + w2 * dom[c, 0]
            y = w0 * dom[a, 1] + w1 * dom[b, 1] + w2 * dom[c, 1]
            e = _dist_tri(_surface_at(grid, x, y, kind), pts[a], pts[b], pts[c])
            worst = max(worst, e)
            ss += e * e
    return worst, ss


@dataclass(frozen=True, eq=False)
class Nodes:
    """Fine surface nodes of one leaf: ``points (N, 3)`` in metres, ``domain (N, 2)``,
    ``boundary (N,)`` (on a margin or an open end), ``grid (N, 2)`` the ``(s, u)`` of each
    node, and the corner nodes of the starting triangulation ``start (T0, 3)``."""

    points: Array
    domain: Array
    boundary: NDArray[np.bool_]
    grid: Array
    start: NDArray[np.int64]
    ij: NDArray[np.int64]  # (N, 2) row and column of each node in the grid
    index: dict[tuple[int, int], int]  # (row, column) -> node; (-1, -1) -> last row
    surface: Array  # (n_s, n_u, 3) the node grid (bilinear surface between nodes)
    kind: int  # 0 both ends open, 1 closed tip, 2 closed base, 3 both closed


def make_nodes(points: Array, s: Array, u: Array, width: Array) -> Nodes:
    """Nodes from a surface grid ``points (n_s, n_u, 3)`` at evenly spaced ``s`` (visible
    fraction, 0 … 1) and ``u`` (``-0.5 … 0.5``), with the blade ``width`` at each ``s``
    (zero: a closed end)."""
    n_s, n_u = points.shape[:2]
    if n_s < 2 or n_u < 3 or n_u % 2 == 0:
        raise ParameterError(f"node grid {n_s} × {n_u}: need >= 2 along and an odd >= 3 across")
    if not (np.allclose(s, np.linspace(0, 1, n_s)) and np.allclose(u, np.linspace(-0.5, 0.5, n_u))):
        raise ParameterError("node grid: s and u must be evenly spaced over [0, 1] and [-0.5, 0.5]")
    closed0, closed1 = (_collapsed(points[k], width[k]) for k in (0, -1))
    if closed0 and closed1:
        rho = 1.0 - np.abs(2.0 * s - 1.0)
    elif closed1:
        rho = 1.0 - s
    elif closed0:
        rho = s.copy()
    else:
        rho = np.ones_like(s)
    rows, mid = [], n_u // 2
    pts, dom, bnd, grid, ij = [], [], [], [], []
    for i in range(n_s):
        cols = [mid] if rho[i] <= 0 else range(n_u)
        first = len(pts)
        for j in cols:
            ij.append((i, j))
            pts.append(points[i, j])
            dom.append((s[i], u[j] * rho[i]))
            grid.append((s[i], u[j]))
            end_open = (i == 0 and not closed0) or (i == n_s - 1 and not closed1)
            bnd.append(rho[i] > 0 and (j in (0, n_u - 1) or end_open))
        rows.append((first, len(pts) - 1))  # (left margin or point, right margin or point)
    start = _start(rows, s, closed0, closed1)
    return Nodes(
        np.asarray(pts, float),
        np.asarray(dom, float),
        np.asarray(bnd),
        np.asarray(grid),
        start,
        np.asarray(ij, np.int64),
        {(i, j): k for k, (i, j) in enumerate(ij)} | {(-1, -1): n_s - 1},
        np.ascontiguousarray(points, float),
        (1 if closed1 else 0) + (2 if closed0 else 0),
    )


def _collapsed(row: Array, width: float) -> bool:
    """A closed end: zero width and every point of the row at the same place (an
    undulation that does not vanish there keeps the row open)."""
    spread = float(np.abs(row - row[len(row) // 2]).max())
    return bool(width <= 0 and spread <= 1e-12 * max(1.0, float(np.abs(row).max())))


def _start(rows, s: Array, closed0: bool, closed1: bool) -> NDArray[np.int64]:
    """Counter-clockwise triangles (domain x along s, y across) over the domain's corners."""
    (b0, b1), (t0, t1) = rows[0], rows[-1]
    if closed0 and closed1:
        k = int(np.argmin(np.abs(s - 0.5)))
        m0, m1 = rows[k]
        return np.array([[b0, m0, m1], [m0, t0, m1]], np.int64)
    if closed1:  # base margins (b0 left u<0, b1 right) and the tip point t0
        return np.array([[b0, t0, b1]], np.int64)
    if closed0:
        return np.array([[b0, t0, t1]], np.int64)
    return np.array([[b0, t0, t1], [b0, t1, b1]], np.int64)


def _barycentric(d: Array, p: int, tri: list[int]) -> Array:
    a, b, c = d[tri[0]], d[tri[1]], d[tri[2]]
    det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
    q = d[p] - a
    l1 = (q[0] * (c[1] - a[1]) - q[1] * (c[0] - a[0])) / det
    l2 = (q[1] * (b[0] - a[0]) - q[0] * (b[1] - a[1])) / det
    return np.array([1.0 - l1 - l2, l1, l2])


def _orient(p: Array, a: int, b: int, c: int) -> float:
    (ax, ay), (bx, by), (cx, cy) = p[a], p[b], p[c]
    return float((bx - ax) * (cy - ay) - (by - ay) * (cx - ax))


class _Mesh:
    """Triangulation of the node domain with per-node location and error."""

    def __init__(self, nodes: Nodes) -> None:
        self.n = nodes
        self.faces: list[list[int]] = [list(map(int, f)) for f in nodes.start]
        self.alive: list[bool] = [True] * len(self.faces)
        self.edge: dict[tuple[int, int], int] = {}
        self.vf: dict[int, set[int]] = {}  # vertex -> its faces
        self.touched: set[int] = set()  # vertices of faces made since last cleared
        for f, tri in enumerate(self.faces):
            self._link(f, tri)
        n = len(nodes.points)
        self.face_of = np.full(n, -1, np.int64)
        self.err = np.zeros(n)
        self.is_vertex = np.zeros(n, bool)
        self.is_vertex[nodes.start.ravel()] = True
        self._assign(np.arange(n), list(range(len(self.faces))))
        if (self.face_of < 0).any():
            raise ParameterError("leaf nodes fall outside the starting triangles")

    # ---------------------------------------------------------------- bookkeeping
    def _link(self, f: int, tri: list[int]) -> None:
        for k in range(3):
            self.edge[(tri[k], tri[(k + 1) % 3])] = f
            self.vf.setdefault(tri[k], set()).add(f)
        self.touched.update(tri)

    def _unlink(self, f: int) -> None:
        tri = self.faces[f]
        for k in range(3):
            self.edge.pop((tri[k], tri[(k + 1) % 3]), None)
            self.vf[tri[k]].discard(f)
        self.alive[f] = False

    def _new(self, tri: list[int]) -> int:
        self.faces.append(tri)
        self.alive.append(True)
        f = len(self.faces) - 1
        self._link(f, tri)
        return f

    def _assign(self, idx: NDArray[np.int64], faces: list[int]) -> None:
        """Locate nodes ``idx`` in ``faces`` (which cover them) and set their errors."""
        tris = np.array([self.faces[f] for f in faces], np.int64)
        loc, err, _, _ = _place(self.n.points, self.n.domain, idx, tris, self.is_vertex)
        if (loc < 0).any():
            raise ParameterError("refinement left leaf nodes outside the mesh")
        self.face_of[idx] = np.asarray(faces, np.int64)[loc]
        self.err[idx] = err

    def members(self, faces: list[int]) -> NDArray[np.int64]:
        fo = self.face_of
        sel = fo == faces[0]
        for f in faces[1:]:
            sel |= fo == f
        return np.flatnonzero(sel)

    # ---------------------------------------------------------------- operations
    def insert(self, p: int) -> None:
        f = int(self.face_of[p])
        tri = self.faces[f]
        bc = _barycentric(self.n.domain, p, tri)
        self.is_vertex[p] = True
        on = np.flatnonzero(np.abs(bc) < 1e-9)
        if on.size:  # on the edge opposite the zero barycentric coordinate
            k = int(on[0])
            a, b = tri[(k + 1) % 3], tri[(k + 2) % 3]
            self._split_edge(p, f, a, b)
        else:
            idx = self.members([f])
            self._unlink(f)
            a, b, c = tri
            new = [self._new([a, b, p]), self._new([b, c, p]), self._new([c, a, p])]
            self._assign(idx, new)
            for e in ((a, b), (b, c), (c, a)):
                self._legalise(e)

    def _split_edge(self, p: int, f: int, a: int, b: int) -> None:
        """Split edge (a, b) of face ``f`` at node ``p`` (and the face across, if any)."""
        g = self.edge.get((b, a))
        c = self._third(f, a, b)
        faces = [f] if g is None else [f, g]
        idx = self.members(faces)
        outer = [(b, c), (c, a)]
        self._unlink(f)
        new = [self._new([a, p, c]), self._new([p, b, c])]
        if g is not None:
            d = self._third(g, b, a)
            self._unlink(g)
            new += [self._new([b, p, d]), self._new([p, a, d])]
            outer += [(a, d), (d, b)]
        self._assign(idx, new)
        for e in outer:
            self._legalise(e)

    def _third(self, f: int, a: int, b: int) -> int:
        return next(v for v in self.faces[f] if v != a and v != b)

    def _cost(self, idx: NDArray[np.int64], faces: list[list[int]]) -> tuple[float, float]:
        nd = self.n
        tris = np.array(faces, np.int64)
        loc, _, worst, ss = _place(nd.points, nd.domain, idx, tris, self.is_vertex)
        if (loc < 0).any():
            return np.inf, np.inf
        w2, s2 = _sample_cost(nd.surface, nd.kind, nd.domain, nd.points, tris, _SAMPLES)
        return max(worst, w2), ss + s2

    def _legalise(self, e0: tuple[int, int]) -> None:
        """Flip edges (stack from ``e0``) while a flip lowers the two faces' error."""
        stack = [e0]
        d = self.n.domain
        while stack:
            a, b = stack.pop()
            f, g = self.edge.get((a, b)), self.edge.get((b, a))
            if f is None or g is None:
                continue
            c, q = self._third(f, a, b), self._third(g, b, a)
            if _orient(d, a, q, c) <= _EPS or _orient(d, b, c, q) <= _EPS:
                continue  # the quad is not convex: the flip would fold
            idx = self.members([f, g])
            old = self._cost(idx, [self.faces[f], self.faces[g]])
            new = self._cost(idx, [[a, q, c], [b, c, q]])
            if not (new[0] < old[0] - 1e-12 or (new[0] <= old[0] and new[1] < old[1] * 0.999)):
                continue
            self._unlink(f)
            self._unlink(g)
            nf = [self._new([a, q, c]), self._new([b, c, q])]
            self._assign(idx, nf)
            stack += [(a, q), (q, b), (b, c), (c, a)]

    def star(self, v: int) -> list[int]:
        return sorted(self.vf.get(v, ()))

    def collapse_cost(self, v: int, w: int) -> tuple[float, list[list[int]]] | None:
        """Largest node error after collapsing vertex ``v`` onto its neighbour ``w`` (and the
        faces left), or None when the collapse would fold the mesh or move a boundary."""
        nd = self.n
        if nd.boundary[v] and not (nd.boundary[w] and _same_side(nd.ij[v], nd.ij[w], nd.index)):
            return None
        star = self.star(v)
        moved = [
            [w if x == v else x for x in self.faces[f]] for f in star if w not in self.faces[f]
        ]
        dead = len(star) - len(moved)
        if not moved or dead != (1 if nd.boundary[v] else 2):
            return None
        if any(_orient(nd.domain, *tri) <= _EPS for tri in moved):
            return None
        self.is_vertex[v] = False
        cost = self._cost(self.members(star), moved)
        self.is_vertex[v] = True
        return cost[0], moved

    def collapse(self, v: int, moved: list[list[int]]) -> None:
        star = self.star(v)
        idx = self.members(star)
        for f in star:
            self._unlink(f)
        self.is_vertex[v] = False
        new = [self._new(tri) for tri in moved]
        self._assign(idx, new)
        for tri in moved:
            for k in range(3):
                self._legalise((tri[k], tri[(k + 1) % 3]))

    def neighbours(self, v: int) -> set[int]:
        return {x for f in self.vf.get(v, ()) for x in self.faces[f]} - {v}

    def face_error(self) -> Array:
        fe = np.zeros(len(self.faces))
        np.maximum.at(fe, self.face_of, np.where(self.is_vertex, 0.0, self.err))
        return fe

    def relocate(self, v: int, reach: int = 2) -> bool:
        """Move vertex ``v`` to the grid node within ``reach`` rows/columns that lowers the
        largest error of its star most (same margin or interior, no fold)."""
        nd = self.n
        if v in set(nd.start.ravel().tolist()):
            return False
        star = self.star(v)
        idx = self.members(star)
        tris = [self.faces[f] for f in star]
        best = self._cost(idx, tris)
        i0, j0 = nd.ij[v]
        choice = None
        d = nd.domain
        for di in range(-reach, reach + 1):
            for dj in range(-reach, reach + 1):
                w = nd.index.get((int(i0) + di, int(j0) + dj))
                if w is None or self.is_vertex[w] or nd.boundary[w] != nd.boundary[v]:
                    continue
                if nd.boundary[v] and not _same_side(nd.ij[v], nd.ij[w], nd.index):
                    continue  # a margin (or open-end) vertex stays on its margin
                moved = [[w if x == v else x for x in tri] for tri in tris]
                if any(_orient(d, *tri) <= _EPS for tri in moved):
                    continue
                self.is_vertex[v], self.is_vertex[w] = False, True
                cost = self._cost(idx, moved)
                self.is_vertex[v], self.is_vertex[w] = True, False
                if cost[0] < best[0] - 1e-12:
                    best, choice = cost, (w, moved)
        if choice is None:
            return False
        w, moved = choice
        for f in star:
            self._unlink(f)
        self.is_vertex[v], self.is_vertex[w] = False, True
        new = [self._new(tri) for tri in moved]
        self._assign(idx, new)
        for tri in moved:
            for k in range(3):
                self._legalise((tri[k], tri[(k + 1) % 3]))
        return True

    def triangles(self) -> NDArray[np.int64]:
        return np.array(
            [t for t, ok in zip(self.faces, self.alive, strict=True) if ok], np.int64
        ).reshape(-1, 3)

    def count(self) -> int:
        return int(sum(self.alive))


def _insert_to(mesh: _Mesh, triangles: int) -> None:
    """Greedy insertion of the worst node until the mesh has ``triangles`` triangles (or
    no node is left to insert)."""
    while mesh.count() < triangles:
        e = np.where(mesh.is_vertex, -1.0, mesh.err)
        if triangles - mesh.count() == 1:
            e = np.where(mesh.n.boundary, e, -1.0)
        p = int(np.argmax(e))
        if e[p] < 0:
            return
        mesh.insert(p)


def adaptive_faces(nodes: Nodes, triangles: int, extra: int = 1000) -> NDArray[np.int64]:
    """Faces (node indices, counter-clockwise in the domain) of exactly ``triangles``
    triangles: greedy insertion up to twice the budget (at most ``extra`` more), then
    decimation back to the budget (it evens out the errors the insertion leaves uneven),
    then local vertex moves on the worst triangle."""
    mesh = _Mesh(nodes)
    if triangles < mesh.count():
        raise ParameterError(
            f"triangle budget {triangles} is below the minimum mesh of this leaf "
            f"({mesh.count()} triangle(s))"
        )
    _insert_to(mesh, triangles + min(triangles, extra))
    if mesh.count() < triangles:
        raise ParameterError(
            f"triangle budget {triangles} exceeds the leaf's {len(nodes.points)} surface "
            f"nodes ({mesh.count()} triangles reached); use more points"
        )
    decimate(mesh, triangles)
    _polish(mesh)
    if mesh.count() != triangles:  # pragma: no cover - guarded by the operations' counts
        raise ParameterError(f"refinement reached {mesh.count()} triangles, not {triangles}")
    return mesh.triangles()


def decimate(mesh: _Mesh, triangles: int) -> None:
    """Collapse vertices (the cheapest first: smallest largest error after the collapse)
    until the mesh has ``triangles`` triangles."""
    fixed = set(mesh.n.start.ravel().tolist())
    cost: dict[int, tuple[float, list[list[int]]] | None] = {}

    def best(v: int):
        opts = [mesh.collapse_cost(v, w) for w in mesh.neighbours(v)]
        opts = [o for o in opts if o is not None]
        return min(opts, key=lambda o: o[0]) if opts else None

    dirty = {v for v in mesh.vf if mesh.vf[v] and v not in fixed}
    interior_only = False
    while mesh.count() > triangles:
        for v in dirty:
            if v not in fixed and mesh.is_vertex[v]:
                cost[v] = best(v)
        last = mesh.count() - triangles == 1  # a boundary vertex (-1 triangle) must go
        cand = [
            (c[0], v)
            for v, c in cost.items()
            if c is not None
            and mesh.is_vertex[v]
            and (not last or mesh.n.boundary[v])
            and not (interior_only and mesh.n.boundary[v])
        ]
        mesh.touched = set()
        if cand:
            _, v = min(cand)
            entry = cost.pop(v)
            assert entry is not None
            mesh.collapse(v, entry[1])
            interior_only = False
        elif last and not interior_only:
            # one triangle too many and only interior vertices (-2 each): add the worst
            # boundary node (+1), then take an interior vertex out
            _insert_to(mesh, mesh.count() + 1)
            interior_only = True
        else:
            raise ParameterError(f"cannot reduce the leaf mesh to {triangles} triangles")
        # a vertex's collapse cost depends only on its star: recompute where a face changed
        dirty = set(mesh.touched)


def _same_side(a, b, index: dict[tuple[int, int], int]) -> bool:
    """Whether boundary node ``b`` (row, column) lies on the straight piece of the boundary
    that boundary node ``a`` (not a corner) lies on: the same open end row, or the same
    margin column (its end corners included) or the closed end point the margin runs to."""
    last_row = index[(-1, -1)]
    if a[0] in (0, last_row):
        return bool(b[0] == a[0])
    closed_end = b[0] in (0, last_row) and (int(b[0]), 0) not in index
    return bool(b[1] == a[1] or closed_end)


def _polish(mesh: _Mesh, rounds: int = 200) -> None:
    """Local search on the worst triangle: move one of its vertices to a nearby node while
    that lowers the largest error (each move also re-flips the star's edges)."""
    for _ in range(rounds):
        fe = mesh.face_error()
        f = int(np.argmax(fe))
        if not any(mesh.relocate(v) for v in list(mesh.faces[f])):
            return


@njit(cache=True)
def _nearest(points, tri, lo, hi):  # pragma: no cover - compiled
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        p = points[i]
        best = np.inf
        for t in range(tri.shape[0]):
            # distance to the triangle's bounding box: a lower bound of its distance
            g = 0.0
            for k in range(3):
                d = max(lo[t, k] - p[k], 0.0, p[k] - hi[t, k])
                g += d * d
            if g >= best * best:
                continue
            best = min(best, _dist_tri(p, tri[t, 0], tri[t, 1], tri[t, 2]))
        out[i] = best
    return out


def point_triangle_distance(points: Array, triangles: Array) -> Array:
    """Distance of each point ``(n, 3)`` to the nearest of ``triangles`` ``(m, 3, 3)``
    (exact: closest point in the face, on an edge or at a corner)."""
    tri = np.ascontiguousarray(triangles, float)
    pts = np.ascontiguousarray(points, float).reshape(-1, 3)
    if tri.shape[0] == 0:
        return np.full(len(pts), np.inf)
    return _nearest(pts, tri, tri.min(axis=1), tri.max(axis=1))


__all__ = ["Nodes", "adaptive_faces", "make_nodes", "point_triangle_distance"]
