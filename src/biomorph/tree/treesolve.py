"""Steps iii-vi of the graph method (Livny et al. 2010): weights and the exact tree solves.

The orientation field (ΣO + ΣE) and the position refinement (ΣA + ΣF) are quadratic forms
whose Hessians are *tree-structured*, solved by O(n) Gaussian elimination from the leaves
to the roots and back-substitution (:func:`solve_tree_system`, numba); the result equals
``scipy.sparse.linalg.spsolve`` on the same matrix (tested). Also the step-vi re-weighting
of the contracted graph. Split out of :mod:`biomorph.tree.livny` (issue 12); the edge
weighting schemes are described there.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.spatial import cKDTree

from biomorph.core import treeops
from biomorph.errors import ParameterError
from biomorph.tree.allometry import edge_length as _edge_length

__all__ = [
    "importance_weights",
    "solve_tree_system",
    "tree_matrix",
    "EDGE_WEIGHTS",
    "orientation_system",
    "orientation_field",
    "refinement_system",
    "refine_positions",
    "reweight_edges",
]


def importance_weights(
    parent: NDArray[np.int64], position: NDArray[np.float64], order: NDArray[np.int64] | None = None
) -> NDArray[np.float64]:
    """Step iii: ``c_v`` = total edge length of the subtree below ``v`` (metres)."""
    el = _edge_length(parent, position)
    return treeops.subtree_sum(parent, el, order) - el


@numba.njit(cache=True)
def _tree_solve(parent, order, diag, off, rhs):
    n = diag.size
    d = diag.copy()
    b = rhs.copy()
    # eliminate leaves upwards: node v couples only to its parent through off[v]
    for k in range(n - 1, -1, -1):
        v = order[k]
        p = parent[v]
        if p >= 0:
            f = off[v] / d[v]
            d[p] -= f * off[v]
            for j in range(b.shape[1]):
                b[p, j] -= f * b[v, j]
    x = np.zeros_like(b)
    for k in range(n):
        v = order[k]
        p = parent[v]
        for j in range(b.shape[1]):
            if p >= 0:
                x[v, j] = (b[v, j] - off[v] * x[p, j]) / d[v]
            else:
                x[v, j] = b[v, j] / d[v]
    return x


def solve_tree_system(
    parent: NDArray[np.int64],
    diag: NDArray[np.float64],
    off: NDArray[np.float64],
    rhs: NDArray[np.float64],
    order: NDArray[np.int64] | None = None,
) -> NDArray[np.float64]:
    """Solve ``A x = rhs`` exactly in O(n) for a symmetric tree-structured matrix.

    ``A[v, v] = diag[v]`` and ``A[v, parent[v]] = A[parent[v], v] = off[v]`` (``off`` at
    roots is ignored); all other entries are zero. ``rhs`` is ``(n,)`` or ``(n, k)``.
    Gaussian elimination in reverse topological order creates no fill-in, so this is the
    exact solution (not an iteration). ``A`` must be positive definite.
    """
    parent = np.asarray(parent, dtype=np.int64)
    order = treeops.topological_order(parent) if order is None else order
    rhs = np.asarray(rhs, dtype=np.float64)
    vec = rhs.ndim == 1
    x = _tree_solve(
        parent,
        np.asarray(order, dtype=np.int64),
        np.asarray(diag, dtype=float),
        np.asarray(off, dtype=float),
        rhs[:, None] if vec else rhs,
    )
    return x[:, 0] if vec else x


def tree_matrix(parent: NDArray[np.int64], diag: NDArray, off: NDArray) -> sparse.csr_matrix:
    """The sparse matrix :func:`solve_tree_system` solves (for tests and scipy solvers)."""
    n = parent.size
    ch = np.flatnonzero(parent >= 0)
    r = np.concatenate([np.arange(n), ch, parent[ch]])
    c = np.concatenate([np.arange(n), parent[ch], ch])
    v = np.concatenate([diag, off[ch], off[ch]])
    return sparse.csr_matrix((v, (r, c)), shape=(n, n))


EDGE_WEIGHTS = ("branch", "livny")


def _edge_weights(
    parent: NDArray[np.int64],
    position: NDArray[np.float64],
    weight: NDArray[np.float64],
    scheme: str,
) -> tuple[NDArray, NDArray]:
    """Per child ``v`` of an edge p→v: the weight of its own terms (ΣE, ΣF) and of the
    pair terms (ΣO, ΣA). ``"livny"``: ``c_v`` and ``(c_p + c_v)/2``; ``"branch"``: ``c̃_v =
    c_v + |e(p, v)|`` for both. Zero at roots (no incoming edge)."""
    ch = parent >= 0
    p = np.where(ch, parent, 0)
    if scheme == "livny":
        return np.where(ch, weight, 0.0), np.where(ch, 0.5 * (weight + weight[p]), 0.0)
    if scheme == "branch":
        w = np.where(ch, weight + _edge_length(parent, position), 0.0)
        return w, w
    raise ParameterError(f"edge_weights {scheme!r}; expected one of {', '.join(EDGE_WEIGHTS)}")


def orientation_system(parent, position, weight, edge_weights: str = "livny"):
    """``(diag, off, rhs)`` of ΣO + ΣE (step iv): the normal equations, divided by 2."""
    n = parent.size
    ch = parent >= 0
    p = np.where(ch, parent, 0)
    e = np.zeros((n, 3))
    e[ch] = position[ch] - position[p[ch]]
    le = np.linalg.norm(e, axis=1)
    good = ch & (le > 0)
    e[good] /= le[good, None]
    w_own, w_pair = _edge_weights(parent, position, weight, edge_weights)
    we = np.where(good, w_own, 0.0) ** 2  # ΣE weight c_v²
    wo = w_pair**2  # ΣO weight ((c_p+c_v)/2)²
    diag = we.copy()
    diag += wo
    np.add.at(diag, p[ch], wo[ch])
    off = -wo
    rhs = we[:, None] * e
    ridge = 1e-12 * max(float(diag.max(initial=0.0)), 1e-30)
    return diag + ridge, off, rhs


def orientation_field(
    parent: NDArray[np.int64],
    position: NDArray[np.float64],
    weight: NDArray[np.float64],
    order=None,
    edge_weights: str = "livny",
) -> NDArray[np.float64]:
    """Step iv: orientations ``o_v`` minimising ΣO + ΣE exactly (``float[n, 3]``).

    Roots have no incoming edge, so no ΣE term; their orientation follows from ΣO.
    ``edge_weights``: ``"livny"`` (the seed's) or ``"branch"`` (see the module doc).
    """
    diag, off, rhs = orientation_system(parent, position, weight, edge_weights)
    return solve_tree_system(parent, diag, off, rhs, order)


def refinement_system(parent, position, weight, orient, edge_weights: str = "livny"):
    """``(diag, off, rhs)`` of ΣA + ΣF (step v) over the edges (parent p, child v)."""
    n = parent.size
    ch = parent >= 0
    p = np.where(ch, parent, 0)
    el = _edge_length(parent, position)
    osum = orient + orient[p]
    nrm = np.linalg.norm(osum, axis=1)
    t = np.zeros((n, 3))
    good = ch & (nrm > 0)
    t[good] = (el[good] / nrm[good])[:, None] * osum[good]  # target of v' - p'
    w_own, w_pair = _edge_weights(parent, position, weight, edge_weights)
    a = w_pair**2  # ΣA weight ((c_u+c_v)/2)²
    f = w_own**2  # ΣF weight c_v²
    m = np.zeros((n, 3))
    m[ch] = 0.5 * (position[ch] + position[p[ch]])  # old edge midpoints
    diag = np.zeros(n)
    diag += a + f / 4
    np.add.at(diag, p[ch], (a + f / 4)[ch])
    off = -a + f / 4
    rhs = a[:, None] * t + (f / 2)[:, None] * m
    np.add.at(rhs, p[ch], (-a[:, None] * t + (f / 2)[:, None] * m)[ch])
    # a tiny anchor to the old positions keeps the system definite where c = 0
    ridge = 1e-9 * max(float(diag.max(initial=0.0)), 1e-30)
    return diag + ridge, off, rhs + ridge * position


def refine_positions(
    parent: NDArray[np.int64],
    position: NDArray[np.float64],
    weight: NDArray[np.float64],
    orient: NDArray[np.float64],
    order=None,
    edge_weights: str = "livny",
) -> NDArray[np.float64]:
    """Step v: new vertex positions minimising ΣA + ΣF exactly (``float[n, 3]``)."""
    diag, off, rhs = refinement_system(parent, position, weight, orient, edge_weights)
    return solve_tree_system(parent, diag, off, rhs, order)


def reweight_edges(
    q: sparse.csr_matrix,
    qpos: NDArray,
    parent: NDArray,
    newpos: NDArray,
    strength: float,
    qtree: cKDTree,
) -> sparse.csr_matrix:
    """Multiply the weight of the Q edge nearest each refined edge by ``1 - s |cos|``."""
    ch = np.flatnonzero(parent >= 0)
    if ch.size == 0:
        return q
    _, a = qtree.query(newpos[parent[ch]])
    _, b = qtree.query(newpos[ch])
    ok = a != b
    a, b, chv = a[ok], b[ok], ch[ok]
    e = newpos[chv] - newpos[parent[chv]]
    ep = qpos[b] - qpos[a]
    ne = np.linalg.norm(e, axis=1) * np.linalg.norm(ep, axis=1)
    cos = np.abs(np.einsum("ij,ij->i", e, ep)) / np.maximum(ne, 1e-30)
    factor = 1.0 - strength * cos
    # locate (a, b) in the CSR structure (both directions)
    q = q.tocsr().copy()
    q.sort_indices()
    m = q.shape[0]
    rows = np.repeat(np.arange(m), np.diff(q.indptr))
    keys = rows * m + q.indices
    for u, v in ((a, b), (b, a)):
        k = u * m + v
        pos = np.searchsorted(keys, k)
        pos = np.minimum(pos, keys.size - 1)
        hit = keys[pos] == k
        # several refined edges may map to one Q edge: apply the strongest factor
        fac = np.ones(keys.size)
        np.minimum.at(fac, pos[hit], factor[hit])
        q.data *= fac
    return q
