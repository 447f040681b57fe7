"""First hits of parallel rays by z-buffer: the light of a canopy without a ray tracer.

Every source of :mod:`biomorph.leaf.light` (the sun, each sky sector) sends *parallel*
rays on a jittered square grid of ground points. For parallel rays, the first triangle
each ray meets is what an orthographic z-buffer along the ray direction shows, so instead
of tracing ``d × n`` rays through a BVH, each triangle is projected along the direction
onto the ground plane and scan-converted into the grid (CARIBU's "projection" method does
the same): the cost is one pass over the triangles and one over the grid points per
direction, whatever the depth complexity of the canopy.

* Projection: a point ``p`` goes to the ground point ``p − (p_z / d_z)·d``; the ray to
  ground point ``g`` is ``g + t·d`` (``t`` > 0 towards the sky), and the first hit coming
  down from the sky is the largest ``t = p_z / d_z``, which is affine over a projected
  triangle (interpolated with the barycentric coordinates).
* Samples: ground point ``(i, j)`` sits at its cell centre plus a jitter in
  ``[−½, ½)²`` cells drawn from a hash of ``(seed, direction, i, j)`` (splitmix64), so the
  sampling is stratified, reproducible and the same for every engine
  (:func:`jitter`).
* Periodic fields: cell indices wrap around the ground rectangle, so a triangle's shadow
  that leaves the tile on one side falls into it from the other — the rays see the
  infinite field of copies of the tile, with no edge effect.
* Coverage: a sample on an edge shared by two triangles belongs to both (inclusive test);
  the depth test keeps one, so no ray is lost or counted twice.

Directions are processed in parallel (numba ``prange``, one z-buffer per direction).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from biomorph.core.types import Array

_MASK53 = float(2.0**-53)


@njit(cache=True)
def _mix(x):  # pragma: no cover - compiled
    """splitmix64 finaliser on a uint64."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(cache=True)
def _jit2(seed, k, cell):  # pragma: no cover - compiled
    """Two uniforms in [-0.5, 0.5) for grid cell ``cell`` of direction ``k``."""
    base = _mix(np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(k + 1))
    z1 = _mix(base + np.uint64(2 * cell + 1))
    z2 = _mix(base + np.uint64(2 * cell + 2))
    return (
        float(z1 >> np.uint64(11)) * _MASK53 - 0.5,
        float(z2 >> np.uint64(11)) * _MASK53 - 0.5,
    )


@njit(cache=True)
def _jitter(seed, k, nx, ny):  # pragma: no cover - compiled
    out = np.empty((ny * nx, 2))
    for c in range(ny * nx):
        a, b = _jit2(seed, k, c)
        out[c, 0] = a
        out[c, 1] = b
    return out


def jitter(seed: int, k: int, nx: int, ny: int) -> Array:
    """Jitter ``(ny·nx, 2)`` (in cells, row-major: cell ``j·nx + i``) of direction ``k``."""
    return _jitter(int(seed), int(k), int(nx), int(ny))


@njit(cache=True)
def _raster_one(tri, d, grid, nx, ny, jit, periodic, hit, depth):  # pragma: no cover
    x0, y0 = grid[0], grid[1]
    fx, fy = 1.0 / grid[2], 1.0 / grid[3]  # cells per metre
    iz = 1.0 / d[2]
    ux, uy = d[0] * iz, d[1] * iz
    for t in range(tri.shape[0]):
        # ground points of the corners, in cells, and their ray parameter t = z / d_z
        za, zb, zc = tri[t, 0, 2], tri[t, 1, 2], tri[t, 2, 2]
        ax = (tri[t, 0, 0] - za * ux - x0) * fx
        ay = (tri[t, 0, 1] - za * uy - y0) * fy
        bx = (tri[t, 1, 0] - zb * ux - x0) * fx
        by = (tri[t, 1, 1] - zb * uy - y0) * fy
        cx = (tri[t, 2, 0] - zc * ux - x0) * fx
        cy = (tri[t, 2, 1] - zc * uy - y0) * fy
        det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if abs(det) < 1e-14:
            continue  # seen edge-on
        # the sample of cell i lies in [i, i + 1): only cells floor(min)..floor(max) can
        # hold a sample inside the triangle
        i0 = int(np.floor(min(ax, bx, cx)))
        i1 = int(np.floor(max(ax, bx, cx)))
        j0 = int(np.floor(min(ay, by, cy)))
        j1 = int(np.floor(max(ay, by, cy)))
        if not periodic:
            i0, i1 = max(i0, 0), min(i1, nx - 1)
            j0, j1 = max(j0, 0), min(j1, ny - 1)
        inv = 1.0 / det
        e1x, e1y, e2x, e2y = bx - ax, by - ay, cx - ax, cy - ay
        ta, tb, tc = za * iz, zb * iz, zc * iz
        wrap = i0 < 0 or j0 < 0 or i1 >= nx or j1 >= ny
        for j in range(j0, j1 + 1):
            jj = j % ny if wrap else j
            for i in range(i0, i1 + 1):
                c = jj * nx + (i % nx if wrap else i)
                sx = i + 0.5 + jit[c, 0] - ax
                sy = j + 0.5 + jit[c, 1] - ay
                w1 = (sx * e2y - e2x * sy) * inv
                w2 = (e1x * sy - sx * e1y) * inv
                if min(w1, w2, 1.0 - w1 - w2) < 0.0:
                    continue
                tt = ta + w1 * (tb - ta) + w2 * (tc - ta)
                if tt > depth[c]:
                    depth[c] = tt
                    hit[c] = t


@njit(parallel=True, cache=True)
def _raster(tri, dirs, k0, grid, nx, ny, seed, periodic):  # pragma: no cover
    nd = dirs.shape[0]
    hits = np.full((nd, ny * nx), -1, np.int64)
    for k in prange(nd):
        jit = _jitter(seed, k0 + k, nx, ny)
        depth = np.zeros(ny * nx)  # the ground: a hit must be above it
        _raster_one(tri, dirs[k], grid, nx, ny, jit, periodic, hits[k], depth)
    return hits


def first_hits(
    triangles: Array,
    directions: Array,
    rect: tuple[float, float, float, float],
    cells: tuple[int, int],
    seed: int = 0,
    periodic: bool = True,
    first: int = 0,
) -> NDArray[np.int64]:
    """First triangle (index, or -1: the ground) met by the ray of every grid cell of
    every direction: ``(d, ny·nx)``, cells row-major.

    ``triangles (m, 3, 3)`` Z-up (ground z = 0, canopy above it), ``directions (d, 3)``
    unit vectors towards the sources (``d_z > 0``), ``rect`` the ground rectangle
    ``(x0, y0, x1, y1)`` cut into ``cells = (nx, ny)`` cells, one jittered ray each;
    ``first``: the index of ``directions[0]`` among all the directions (its jitter)."""
    x0, y0, x1, y1 = map(float, rect)
    nx, ny = int(cells[0]), int(cells[1])
    tri = np.ascontiguousarray(triangles, np.float64)
    dirs = np.ascontiguousarray(directions, np.float64).reshape(-1, 3)
    grid = np.array([x0, y0, (x1 - x0) / nx, (y1 - y0) / ny])
    return _raster(tri, dirs, int(first), grid, nx, ny, int(seed), bool(periodic))


__all__ = ["first_hits", "jitter"]
