"""BranchGraph: a spatially embedded rooted forest (tree pillar, plant structures).

Z-up, metres. ``parent[i] == -1`` marks a root; one graph may hold several trees (see
``tree_id``). Nodes need not be in topological order; :attr:`order` provides one.
"""

from __future__ import annotations

from contextvars import ContextVar
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from biomorph.core import treeops
from biomorph.errors import InputError

#: the cached properties that depend on ``parent`` alone, and those that also depend on
#: ``position``: :meth:`BranchGraph.with_` hands them to the copy where those are unchanged
_PARENT_CACHED = ("order", "roots", "children_csr", "n_children", "leaves", "edges")
_PARENT_CACHED += ("node_depth", "root_index")
_POSITION_CACHED = ("edge_length",)
#: the cached values :meth:`BranchGraph.with_` hands to the graph being built
_INHERIT: ContextVar[dict | None] = ContextVar("_INHERIT", default=None)


@dataclass(frozen=True, eq=False)
class BranchGraph:
    """Rooted forest with node positions and optional per-node attributes.

    Attributes
    ----------
    position : ``float[n, 3]`` node positions (metres, Z up).
    parent : ``int[n]`` parent index, -1 at roots.
    radius : ``float[n]`` branch radius at the node (metres) or ``None``.
    weight : ``float[n]`` importance weight ``c_v`` (subtree edge length, Livny) or ``None``.
    depth : ``int[n]`` branch order (0 = trunk) or ``None``.
    tree_id : ``int[n]`` which tree the node belongs to, or ``None`` (derived from roots).
    """

    position: NDArray[np.float64]
    parent: NDArray[np.int64]
    radius: NDArray[np.float64] | None = None
    weight: NDArray[np.float64] | None = None
    depth: NDArray[np.int64] | None = None
    tree_id: NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        pos = np.asarray(self.position, dtype=float).reshape(-1, 3)
        n = pos.shape[0]
        parent = np.asarray(self.parent, dtype=np.int64).reshape(-1)
        if parent.shape != (n,):
            raise InputError(f"BranchGraph has {n} positions but {parent.size} parents")
        if n and (parent.max() >= n or parent.min() < -1 or np.any(parent == np.arange(n))):
            raise InputError(
                f"BranchGraph parent indices must lie in [-1, {n - 1}] and not "
                "point to the node itself"
            )
        if not np.isfinite(pos).all():
            raise InputError("BranchGraph positions hold NaN or inf")
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "parent", parent)
        for name, dtype in (
            ("radius", float),
            ("weight", float),
            ("depth", np.int64),
            ("tree_id", np.int64),
        ):
            val = getattr(self, name)
            if val is not None:
                arr = np.asarray(val, dtype=dtype).reshape(-1)
                if arr.shape != (n,):
                    raise InputError(f"BranchGraph {name} has {arr.size} values, expected {n}")
                object.__setattr__(self, name, arr)
        for name in ("position", "parent", "radius", "weight", "depth", "tree_id"):
            val = getattr(self, name)
            if val is not None:
                val.setflags(write=False)
        inherit = _INHERIT.get()
        if inherit:
            self.__dict__.update(inherit)  # a copy's: same parents (validated there)
        _ = self.order  # validates acyclicity eagerly

    # ------------------------------------------------------------------ structure
    @property
    def n_nodes(self) -> int:
        return int(self.position.shape[0])

    def __len__(self) -> int:
        return self.n_nodes

    @cached_property
    def order(self) -> NDArray[np.int64]:
        """Topological (breadth-first) order: parents before children."""
        return treeops.topological_order(self.parent)

    @cached_property
    def roots(self) -> NDArray[np.int64]:
        return np.flatnonzero(self.parent < 0)

    @cached_property
    def children_csr(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """``(indptr, indices)``: children of ``i`` are ``indices[indptr[i]:indptr[i+1]]``."""
        return treeops.children_csr(self.parent)

    def children(self, i: int) -> NDArray[np.int64]:
        indptr, indices = self.children_csr
        return indices[indptr[i] : indptr[i + 1]]

    @cached_property
    def n_children(self) -> NDArray[np.int64]:
        return np.diff(self.children_csr[0])

    @cached_property
    def leaves(self) -> NDArray[np.int64]:
        """Tip nodes (no children). Their count is the thesis's NOB."""
        return np.flatnonzero(self.n_children == 0)

    @cached_property
    def edges(self) -> NDArray[np.int64]:
        """``int[m, 2]`` (parent, child) pairs."""
        child = np.flatnonzero(self.parent >= 0)
        return np.stack([self.parent[child], child], axis=1)

    @cached_property
    def edge_length(self) -> NDArray[np.float64]:
        """Length of the edge from each node to its parent (0 at roots)."""
        out = np.zeros(self.n_nodes)
        child = np.flatnonzero(self.parent >= 0)
        out[child] = np.linalg.norm(
            self.position[child] - self.position[self.parent[child]], axis=1
        )
        return out

    @property
    def total_length(self) -> float:
        """Sum of edge lengths (the thesis's TBL), metres."""
        return float(self.edge_length.sum())

    @cached_property
    def node_depth(self) -> NDArray[np.int64]:
        """Number of edges from the root (topological depth, not branch order)."""
        return treeops.depth(self.parent, self.order)

    @cached_property
    def root_index(self) -> NDArray[np.int64]:
        """Root node of each node's tree."""
        return treeops.root_of(self.parent, self.order)

    @cached_property
    def trees(self) -> NDArray[np.int64]:
        """Tree label per node: ``tree_id`` if given, else the rank of the node's root."""
        if self.tree_id is not None:
            return self.tree_id
        return np.searchsorted(self.roots, self.root_index)

    def subtree_sum(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """Sum of ``values`` over each node's subtree (node included)."""
        return treeops.subtree_sum(self.parent, values, self.order)

    def path_length(self) -> NDArray[np.float64]:
        """Distance along the graph from each node's root (metres)."""
        return treeops.accumulate_down(self.parent, self.edge_length, self.order)

    def subtree_length(self) -> NDArray[np.float64]:
        """Total edge length below each node (Livny's importance weight ``c_v``)."""
        return self.subtree_sum(self.edge_length) - self.edge_length

    def with_(self, **changes: object) -> BranchGraph:
        """A copy with some fields replaced. Where ``parent`` (and ``position``) stay, the
        copy starts with this graph's cached order, children, depths and roots (and edge
        lengths): the same values, not computed again."""
        keys: tuple[str, ...] = ()
        if changes.get("parent", self.parent) is self.parent:
            keys = _PARENT_CACHED
            if changes.get("position", self.position) is self.position:
                keys += _POSITION_CACHED
        inherit = {k: self.__dict__[k] for k in keys if k in self.__dict__}
        token = _INHERIT.set(inherit)
        try:
            return replace(self, **changes)  # type: ignore[arg-type]
        finally:
            _INHERIT.reset(token)

    def subgraph(self, keep: NDArray[np.bool_]) -> BranchGraph:
        """Nodes where ``keep`` is true; a kept node whose parent is dropped becomes a root."""
        keep = np.asarray(keep, dtype=bool)
        new_index = np.full(self.n_nodes, -1, dtype=np.int64)
        new_index[keep] = np.arange(int(keep.sum()))
        par = self.parent[keep]
        par = np.where(par >= 0, new_index[np.maximum(par, 0)], -1)
        fields = {
            k: (None if getattr(self, k) is None else getattr(self, k)[keep])
            for k in ("radius", "weight", "depth", "tree_id")
        }
        return BranchGraph(self.position[keep], par, **fields)

    def to_networkx(self):  # pragma: no cover - thin conversion for users and tests
        """A ``networkx.DiGraph`` parent->child with node attributes (off hot paths)."""
        import networkx as nx

        g = nx.DiGraph()
        for i in range(self.n_nodes):
            attrs = {"position": self.position[i]}
            if self.radius is not None:
                attrs["radius"] = float(self.radius[i])
            g.add_node(i, **attrs)
        g.add_edges_from(map(tuple, self.edges))
        return g
