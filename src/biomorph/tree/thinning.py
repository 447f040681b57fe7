"""Palágyi & Kuba (1999) directional 3-D thinning with 8 subiterations.

K. Palágyi, A. Kuba: "Directional 3D thinning using 8 subiterations", DGCI 1999, LNCS 1568,
pp. 325–336 -- the thinning Gorte & Pfeifer (2004) and the thesis (seed 001, §2.3.2 iii,
§3.3 iii) use. An iteration consists of 8 subiterations, one per diagonal direction
(U/D × N/S × E/W) in the order USW, DNE, USE, DNW, UNE, DSW, UNW, DSE. In a subiteration a
black voxel is deleted when its 3×3×3 neighbourhood matches one of the deletion templates of
that direction; all matches of a subiteration are found first and deleted together (the
algorithm is parallel within a subiteration; no sequential rechecking). Iterations repeat
until nothing changes.

Templates
---------
The 7 base templates of direction USW are given below, position ``j`` = ``9 p + 3 r + c``
with plane ``p`` (0 = down … 2 = up), row ``r`` (0 = north … 2 = south) and column ``c``
(0 = west … 2 = east); codes: ``w`` white (must be 0), ``b`` black (must be 1), ``p`` at
least one of the ``p`` positions black, ``d`` don't care. The USW set is the closure of the
base templates under the three reflections that fix the USW diagonal (planes through it),
de-duplicated -- 20 templates per subiteration, as the seed states (the closure under the
reflection group adds 2 rotated copies of base template 5: ``full_symmetry=True``); the
other 7 sets follow by mirroring U↔D, N↔S, E↔W. :func:`templates` returns them; the count
per direction is checked in the tests.

Array convention: ``volume[x, y, z]`` with x = east, y = north, z = up (Z-up trees).

Speed: every template is three 26-bit masks (black, white, any-of), a voxel's
neighbourhood one 26-bit word, so a match is three AND/compare operations. A numba kernel
keeps the list of object voxels, scans only those that still have a white face neighbour
(border voxels), and compacts the list once per iteration -- no Python loop per voxel.
"""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np
from numpy.typing import NDArray

from biomorph.errors import ParameterError

__all__ = ["thin_palagyi_kuba", "templates", "DIRECTIONS", "BASE_TEMPLATES"]

#: The 7 base templates of direction USW (Palágyi & Kuba 1999, Fig. 3), coded as above.
BASE_TEMPLATES = (
    "wpbwppwwwwppwbpwwwwwwwwwwww",
    "wppwpbwppwppwbpwppwwwwwwwww",
    "ppppbppppppppbppppwwwwwwwww",
    "dbdwwbwwddddwbdwwdwwwwwwwww",
    "ddddbdddddbddbdddddddwwwwww",
    "ddddbdddddbddbbddddddwwdwwd",
    "ddddbddddddbdbddddwwbwwwwww",
)

#: Subiteration order: (name, (sx, sy, sz)) with s = the side from which voxels are peeled
#: (x: -1 west / +1 east, y: -1 south / +1 north, z: -1 down / +1 up).
DIRECTIONS = (
    ("USW", (-1, -1, 1)),
    ("DNE", (1, 1, -1)),
    ("USE", (1, -1, 1)),
    ("DNW", (-1, 1, -1)),
    ("UNE", (1, 1, 1)),
    ("DSW", (-1, -1, -1)),
    ("UNW", (-1, 1, 1)),
    ("DSE", (1, -1, -1)),
)

_CODE = {"w": 0, "b": 1, "p": 2, "d": 3}


def _parse(s: str) -> NDArray[np.int8]:
    """Template string → ``int8[3, 3, 3]`` indexed ``[dx+1, dy+1, dz+1]``."""
    t = np.empty((3, 3, 3), dtype=np.int8)
    for j, ch in enumerate(s):
        p, r, c = j // 9, (j // 3) % 3, j % 3
        t[c, 2 - r, p] = _CODE[ch]  # dx = c-1, dy = 1-r (row 0 = north = +y), dz = p-1
    return t


def _reflections(t: NDArray[np.int8]) -> list[NDArray[np.int8]]:
    """The three reflections through planes containing the USW diagonal (-1,-1,+1)."""
    return [
        t.transpose(1, 0, 2),  # swap x and y
        t.transpose(0, 2, 1)[:, ::-1, ::-1],  # (dy, dz) -> (-dz, -dy)
        t.transpose(2, 1, 0)[::-1, :, ::-1],
    ]  # (dx, dz) -> (-dz, -dx)


@lru_cache(maxsize=2)
def templates(full_symmetry: bool = False) -> tuple[tuple[NDArray[np.int8], ...], ...]:
    """Deletion templates per subiteration (order of :data:`DIRECTIONS`), each
    ``int8[3, 3, 3]`` indexed ``[dx+1, dy+1, dz+1]`` with codes 0 white, 1 black,
    2 any-of black, 3 don't care.

    ``full_symmetry=False`` (default, as the seed describes it): the 7 base templates and
    their mirror images in the three diagonal planes, de-duplicated -- 20 templates per
    direction. ``full_symmetry=True``: the closure under those reflections (adds the two
    120° rotations about the diagonal of base template 5) -- 22 templates.
    """
    base = [_parse(s) for s in BASE_TEMPLATES]
    usw: list[NDArray[np.int8]] = list(base)
    seen = {t.tobytes() for t in usw}
    i = 0
    while i < len(usw):
        if full_symmetry or i < len(base):
            for r in _reflections(usw[i]):
                r = np.ascontiguousarray(r)
                if r.tobytes() not in seen:
                    seen.add(r.tobytes())
                    usw.append(r)
        i += 1
    out = []
    for _, (sx, sy, sz) in DIRECTIONS:
        ts = []
        for t in usw:
            u = t
            if sx == 1:
                u = u[::-1, :, :]
            if sy == 1:
                u = u[:, ::-1, :]
            if sz == -1:
                u = u[:, :, ::-1]
            ts.append(np.ascontiguousarray(u))
        out.append(tuple(ts))
    return tuple(out)


#: neighbour offsets in bit order (centre excluded)
_OFFSETS = np.array(
    [
        (dx, dy, dz)
        for dx in (-1, 0, 1)
        for dy in (-1, 0, 1)
        for dz in (-1, 0, 1)
        if (dx, dy, dz) != (0, 0, 0)
    ],
    dtype=np.int64,
)


@lru_cache(maxsize=2)
def _masks(full_symmetry: bool = False) -> NDArray[np.uint32]:
    """``uint32[8, n_templates, 3]``: (black, white, any-of) bit masks per template."""
    ts = templates(full_symmetry)
    out = np.zeros((8, len(ts[0]), 3), dtype=np.uint32)
    for d, tset in enumerate(ts):
        for k, t in enumerate(tset):
            for bit, (dx, dy, dz) in enumerate(_OFFSETS):
                code = t[dx + 1, dy + 1, dz + 1]
                if code < 3:  # slot 0 black, 1 white, 2 any-of
                    out[d, k, (1, 0, 2)[code]] |= np.uint32(1 << bit)
            assert t[1, 1, 1] == 1
    return out


@numba.njit(cache=True, nogil=True)
def _thin_kernel(
    vol: NDArray[np.uint8], masks: NDArray[np.uint32], offsets: NDArray[np.int64], max_iter: int
) -> int:
    """Thin ``vol`` (padded by one white voxel on every side) in place; returns iterations."""
    nx, ny, nz = vol.shape
    n = 0
    for x in range(1, nx - 1):
        for y in range(1, ny - 1):
            for z in range(1, nz - 1):
                if vol[x, y, z]:
                    n += 1
    pts = np.empty((n, 3), dtype=np.int64)
    k = 0
    for x in range(1, nx - 1):
        for y in range(1, ny - 1):
            for z in range(1, nz - 1):
                if vol[x, y, z]:
                    pts[k, 0] = x
                    pts[k, 1] = y
                    pts[k, 2] = z
                    k += 1
    alive = np.ones(n, dtype=np.bool_)
    cand = np.empty(n, dtype=np.int64)
    nt = masks.shape[1]
    it = 0
    while it < max_iter:
        it += 1
        deleted_total = 0
        for d in range(8):
            nc = 0
            for i in range(n):
                if not alive[i]:
                    continue
                x, y, z = pts[i, 0], pts[i, 1], pts[i, 2]
                # border voxel: at least one white face neighbour
                if (
                    vol[x - 1, y, z]
                    and vol[x + 1, y, z]
                    and vol[x, y - 1, z]
                    and vol[x, y + 1, z]
                    and vol[x, y, z - 1]
                    and vol[x, y, z + 1]
                ):
                    continue
                cfg = np.uint32(0)
                for b in range(26):
                    if vol[x + offsets[b, 0], y + offsets[b, 1], z + offsets[b, 2]]:
                        cfg |= np.uint32(1) << np.uint32(b)
                for t in range(nt):
                    blk = masks[d, t, 0]
                    wht = masks[d, t, 1]
                    anyb = masks[d, t, 2]
                    if (cfg & blk) == blk and (cfg & wht) == 0 and (anyb == 0 or (cfg & anyb) != 0):
                        cand[nc] = i
                        nc += 1
                        break
            for j in range(nc):  # parallel deletion: all matches of this subiteration
                i = cand[j]
                vol[pts[i, 0], pts[i, 1], pts[i, 2]] = 0
                alive[i] = False
            deleted_total += nc
        if deleted_total == 0:
            break
        # compact the list of object voxels
        m = 0
        for i in range(n):
            if alive[i]:
                pts[m, 0] = pts[i, 0]
                pts[m, 1] = pts[i, 1]
                pts[m, 2] = pts[i, 2]
                alive[m] = True
                m += 1
        n = m
    return it


def thin_palagyi_kuba(
    volume: NDArray[np.bool_],
    *,
    max_iter: int = 10_000,
    full_symmetry: bool = False,
    return_iterations: bool = False,
) -> NDArray[np.bool_] | tuple[NDArray[np.bool_], int]:
    """Curve-thin a binary volume with the Palágyi–Kuba 8-subiteration algorithm.

    Parameters
    ----------
    volume : ``bool[X, Y, Z]`` object voxels (x east, y north, z up). Not modified.
    max_iter : cap on full iterations (each = 8 subiterations); the algorithm stops
        earlier when an iteration deletes nothing.
    full_symmetry : use the 22-template closure instead of the seed's 20 templates per
        direction (see :func:`templates`).
    return_iterations : also return the number of iterations run.

    Returns
    -------
    The thinned volume (same shape, bool): a one-voxel-wide curve skeleton that keeps the
    topology (26-connected objects, 6-connected background) of the input.
    """
    vol = np.asarray(volume)
    if vol.ndim != 3:
        raise ParameterError(f"thinning needs a 3-D volume; got shape {vol.shape}")
    pad = np.zeros(tuple(s + 2 for s in vol.shape), dtype=np.uint8)
    pad[1:-1, 1:-1, 1:-1] = vol.astype(bool)
    its = _thin_kernel(pad, _masks(bool(full_symmetry)), _OFFSETS, int(max_iter))
    out = pad[1:-1, 1:-1, 1:-1].astype(bool)
    return (out, int(its)) if return_iterations else out
