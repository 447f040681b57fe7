"""treeops kernels against naive Python references on random forests."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from biomorph.core import treeops
from biomorph.errors import InputError


def random_forest(n: int, n_roots: int, seed: int) -> np.ndarray:
    """Random forest on ``n`` nodes with shuffled labels (parents not before children)."""
    rng = np.random.default_rng(seed)
    parent = np.full(n, -1)
    for i in range(n_roots, n):
        parent[i] = rng.integers(0, i)
    perm = rng.permutation(n)  # relabel: node i -> perm[i]
    out = np.full(n, -1)
    out[perm] = np.where(parent >= 0, perm[np.maximum(parent, 0)], -1)
    return out


forests = st.builds(
    lambda n, r, s: random_forest(n, min(r, n), s),
    st.integers(1, 60),
    st.integers(1, 4),
    st.integers(0, 10**6),
)


def ancestors(parent, i):
    out = []
    while i >= 0:
        out.append(i)
        i = parent[i]
    return out


@settings(max_examples=60, deadline=None)
@given(forests)
def test_kernels_match_naive(parent):
    n = parent.size
    order = treeops.topological_order(parent)
    pos = np.empty(n, int)
    pos[order] = np.arange(n)
    assert sorted(order.tolist()) == list(range(n))
    assert all(pos[parent[i]] < pos[i] for i in range(n) if parent[i] >= 0)
    vals = np.random.default_rng(n).normal(size=n)
    sub = treeops.subtree_sum(parent, vals, order)
    down = treeops.accumulate_down(parent, vals)
    depth = treeops.depth(parent, order)
    root = treeops.root_of(parent)
    for i in range(n):
        anc = ancestors(parent, i)
        assert np.isclose(down[i], vals[anc].sum())
        assert depth[i] == len(anc) - 1
        assert root[i] == anc[-1]
        below = [j for j in range(n) if i in ancestors(parent, j)]
        assert np.isclose(sub[i], vals[below].sum())
    indptr, indices = treeops.children_csr(parent)
    for i in range(n):
        assert indices[indptr[i] : indptr[i + 1]].tolist() == np.flatnonzero(parent == i).tolist()


def test_cycles_and_bad_indices_are_rejected():
    with pytest.raises(InputError, match="cycle"):
        treeops.topological_order(np.array([-1, 2, 1]))
    with pytest.raises(InputError, match="out of range"):
        treeops.topological_order(np.array([-1, 5]))
    with pytest.raises(InputError, match="out of range"):
        treeops.topological_order(np.array([-1, -3]))
    assert treeops.topological_order(np.zeros(0, int)).size == 0


def test_large_chain_has_no_recursion_limit():
    n = 200_000
    parent = np.arange(-1, n - 1)
    d = treeops.depth(parent)
    assert d[-1] == n - 1
    s = treeops.subtree_sum(parent, np.ones(n))
    assert s[0] == n


def test_per_label_reduces_over_each_label():
    from biomorph.core.treeops import per_label

    labels = np.array([3, 1, 3, 1, 7])
    z = np.array([2.0, 5.0, 9.0, -1.0, 4.0])
    assert per_label(labels, z).tolist() == [9.0, 5.0, 9.0, 5.0, 4.0]
    assert per_label(labels, z, np.minimum).tolist() == [2.0, -1.0, 2.0, -1.0, 4.0]
    assert per_label(np.zeros(0, int), np.zeros(0)).size == 0
