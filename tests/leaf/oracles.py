"""Test oracles for the leaf pillar: slow, obviously-correct references of fast kernels."""

from __future__ import annotations

import heapq

import numpy as np

from biomorph.core.types import Array
from biomorph.leaf.reduction import _err


def reduction_order_py(x: Array, z: Array, s: Array, w: Array):
    """Pure-Python reference of :func:`reduction_order` (``heapq`` + version stamps)."""
    n = len(x)

    def err(i: int, a: int, b: int) -> float:
        return float(_err.py_func(i, a, b, x, z, s, w))

    prev = list(range(-1, n - 1))
    nxt = list(range(1, n + 1))
    ver = [0] * n
    alive = [True] * n
    heap = [(err(i, i - 1, i + 1), i, 0) for i in range(1, n - 1)]
    heapq.heapify(heap)
    order, errs = [], []
    while heap:
        key, i, v = heapq.heappop(heap)
        if not alive[i] or v != ver[i]:
            continue
        a, b = prev[i], nxt[i]
        alive[i] = False
        nxt[a], prev[b] = b, a
        order.append(i)
        errs.append(key)
        for j in (a, b):
            if 0 < j < n - 1:
                ver[j] += 1
                heapq.heappush(heap, (err(j, prev[j], nxt[j]), j, ver[j]))
    return np.array(order, np.int64), np.array(errs)
