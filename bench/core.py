"""Core traversal kernels vs. networkx on random forests (subtree sums, depths, order).

Usage: .venv/bin/python bench/core.py [--full]

Random forests (10 trees, each node's parent drawn among earlier nodes, labels shuffled so
parents do not precede children) of 10^4 .. 10^6 nodes (``--full``: 10^7). biomorph's
``BranchGraph`` topological order + subtree sums + path lengths (numba kernels over parent
arrays) are timed against the networkx reference (DiGraph, topological sort, Python
accumulation), which is run up to 10^5 nodes by default (10^6 with ``--full``); results are
checked equal. Prints a markdown table.
"""

from __future__ import annotations

import argparse
import os
import time
import tracemalloc

import numpy as np


def random_forest(n: int, roots: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    parent = np.full(n, -1)
    idx = np.arange(roots, n)
    parent[roots:] = (rng.random(idx.size) * idx).astype(np.int64)
    perm = rng.permutation(n)
    out = np.full(n, -1)
    out[perm] = np.where(parent >= 0, perm[np.maximum(parent, 0)], -1)
    return out


def ours(parent: np.ndarray, values: np.ndarray):
    from biomorph.core import treeops

    order = treeops.topological_order(parent)
    return (
        treeops.subtree_sum(parent, values, order),
        treeops.depth(parent, order),
        treeops.accumulate_down(parent, values, order),
    )


def reference(parent: np.ndarray, values: np.ndarray):
    import networkx as nx

    g = nx.DiGraph()
    g.add_nodes_from(range(parent.size))
    child = np.flatnonzero(parent >= 0)
    g.add_edges_from(zip(parent[child].tolist(), child.tolist(), strict=True))
    order = list(nx.topological_sort(g))
    sub = values.copy()
    for v in reversed(order):
        for p in g.predecessors(v):
            sub[p] += sub[v]
    depth = np.zeros(parent.size, dtype=np.int64)
    down = values.copy()
    for v in order:
        for c in g.successors(v):
            depth[c] = depth[v] + 1
            down[c] += down[v]
    return sub, depth, down


def timed(fn, *args, trace: bool = True):
    """(result, seconds of an untraced run, tracemalloc peak MB of a second run)."""
    t0 = time.perf_counter()
    out = fn(*args)
    sec = time.perf_counter() - t0
    peak = float("nan")
    if trace:
        tracemalloc.start()
        fn(*args)
        peak = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
    return out, sec, peak


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true")
    args = ap.parse_args(argv)
    sizes = [10_000, 100_000, 1_000_000] + ([10_000_000] if args.full else [])
    ref_limit = 1_000_000 if args.full else 100_000
    ours(random_forest(100, 2, 0), np.ones(100))  # compile / load kernels
    rows = []
    for n in sizes:
        parent = random_forest(n, 10, n)
        values = np.random.default_rng(1).random(n)
        (sub, depth, down), sec, peak = timed(ours, parent, values)
        ratio, note = "", "reference skipped (use --full)"
        if n <= ref_limit:
            (rs, rd, rdown), rsec, _ = timed(reference, parent, values, trace=False)
            ok = np.allclose(sub, rs) and np.array_equal(depth, rd) and np.allclose(down, rdown)
            ratio = f"{rsec / sec:.0f}× faster"
            note = f"networkx {rsec:.2f} s, results {'equal' if ok else 'DIFFER'}"
        rows.append([f"{n:,}", f"{sec:.3f}", f"{peak:.0f}", ratio, note])
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs\n")
    print(
        "| nodes | seconds (order + subtree sum + depth + path sum) | peak MB | vs networkx "
        "| notes |"
    )
    print("|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
