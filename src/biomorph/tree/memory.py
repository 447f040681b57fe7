"""Will the skeleton fit in this machine's memory? A clear stop before it runs out.

The graph method's peak memory grows with the points: its k-nearest-neighbour lists (the
outlier filter's 17 per point, the graph's), the Dijkstra graph and the per-point
distances. Measured with ``bench/tree.py --one N`` (peak resident set of the whole
process, synthetic maple, session 29): 848 MB at 1,000,000 points and 1,443 MB at
2,000,000, i.e. about :data:`MEMORY_BASE` plus :data:`MEMORY_PER_POINT` per point. The
voxel method stays under that line (851 / 1,378 MB on the same clouds, its cell size
derived from them), so the same estimate guards both. A
30-million-point scan of a large tree would need about 18 GB; where the machine has less,
the process would be killed by the kernel with no message, so the pipeline stops first
(:func:`check_memory`, exit 2) and says how far to thin the cloud
(``--downsample-voxel``), or runs anyway with ``--no-memory-check``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from biomorph.errors import InputError

__all__ = [
    "MEMORY_BASE",
    "MEMORY_PER_POINT",
    "available_memory",
    "graph_memory",
    "check_memory",
    "voxel_edge",
]

#: bytes the graph method's process holds whatever the cloud (interpreter, numpy, scipy,
#: numba's compiled kernels): the intercept of the two measurements in the module doc
MEMORY_BASE = 250_000_000
#: bytes of peak memory per point of the prepared cloud (the slope of the two measurements)
MEMORY_PER_POINT = 600


def graph_memory(n_points: int) -> int:
    """Estimated peak memory (bytes) of the skeleton stage on ``n_points`` points (the
    graph method's line; the voxel method stays under it)."""
    return MEMORY_BASE + MEMORY_PER_POINT * int(n_points)


def _read_int(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def available_memory() -> int | None:
    """Bytes this process can still take: the kernel's ``MemAvailable`` (Linux), within a
    container's cgroup limit (v2 ``memory.max`` less ``memory.current``) when there is one;
    elsewhere the free physical pages (``os.sysconf``). None where nothing can be read."""
    avail: int | None = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                avail = int(line.split()[1]) * 1024
                break
    except (OSError, ValueError, IndexError):
        avail = None
    if avail is None:
        try:
            avail = int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            avail = None
    cg = Path("/sys/fs/cgroup")
    limit, used = _read_int(cg / "memory.max"), _read_int(cg / "memory.current")
    if limit is not None and used is not None:
        room = max(limit - used, 0)
        avail = room if avail is None else min(avail, room)
    return avail


def _spacing(xyz: NDArray[np.float64], sample: int = 100_000, seed: int = 0) -> float:
    """The cloud's point spacing (m) from a random sample: the sample's median nearest-
    neighbour distance scaled by √(sample share) (points on surfaces: the spacing goes as
    one over the square root of the density). No k-d tree of the whole cloud is built."""
    n = xyz.shape[0]
    m = min(n, sample)
    pick = np.random.default_rng(seed).choice(n, size=m, replace=False)
    d, _ = cKDTree(xyz[pick]).query(xyz[pick], k=2)
    d = d[:, 1][d[:, 1] > 0]
    return float(np.median(d) * np.sqrt(m / n)) if d.size else 0.0


def _gb(b: float) -> str:
    """Bytes as GB, with two decimals under 10 GB (0.32 and 0.30 must read apart)."""
    return f"{b / 1e9:.2f}" if b < 10e9 else f"{b / 1e9:.1f}"


def voxel_edge(xyz: NDArray[np.float64], fit: int) -> tuple[float, int]:
    """A ``--downsample-voxel`` edge (m, whole millimetres) keeping at most ``fit`` points,
    and the points it keeps (voxels occupied, as :func:`biomorph.tree.cloud.downsample`
    counts them). The first guess is a surface's: a voxel of edge ``v`` over ``ρ`` points
    per m² keeps one point per ``v²`` where ``ρ v² ≫ 1``, so ``v = √(n / (n_fit ρ))``, with
    ``ρ = ln 2 / (π s²)`` from the median nearest-neighbour distance ``s`` of randomly
    placed points (:func:`_spacing`). Real scans are neither random nor flat (the guess
    kept 0.5-1.4x the target on the clouds here), so the count is then measured on the
    cloud (one sort of the voxel keys per step: a few seconds at 30 million points, on
    this error path only) and the edge scaled by ``√(kept / fit)`` until it keeps at most
    ``fit``, within a fifth of it where eight steps allow (the plot, spruce, rTwig and aRchi
    clouds here, thinned to 70 % and 30 %: 0.81-0.99 of the target)."""
    from biomorph.tree.cloud import _voxel_keys

    n = xyz.shape[0]
    s = _spacing(xyz)
    if s <= 0 or fit <= 0:
        return 0.0, n
    v = s * np.sqrt(np.pi * n / (np.log(2.0) * fit))
    over = 0.0  # the largest edge found to keep too many points
    best: tuple[float, int] | None = None  # the smallest edge found to keep few enough
    for _ in range(8):
        v = max(float(np.ceil(v * 1000.0) / 1000.0), 0.001)  # whole mm, as a user types it
        kept = int(np.unique(_voxel_keys(xyz, v)).size)
        if kept > fit:
            over = max(over, v)
        elif best is None or v < best[0]:
            best = (v, kept)
        if best is not None and best[1] >= 0.8 * fit:
            break
        nxt = v * float(np.clip(np.sqrt(kept / fit), 0.5, 2.0))  # count ~ 1 / v²
        if best is not None:  # between the two known edges, a whole millimetre apart
            nxt = min(nxt, best[0] - 0.001)
        nxt = max(nxt, over + 0.001)
        if best is not None and nxt >= best[0]:
            break
        v = nxt
    return best if best is not None else (v, kept)


def check_memory(
    xyz: NDArray[np.float64], source: str, available: int | None = None, n_points: int | None = None
) -> None:
    """Raise :class:`InputError` when the skeleton stage on ``n_points`` points (default: all
    of ``xyz``) would need more memory (:func:`graph_memory`) than is ``available`` (default
    :func:`available_memory`; no check where it cannot be read). The message gives both
    figures and a ``--downsample-voxel`` edge that keeps no more points than fit
    (:func:`voxel_edge`) with the count it keeps."""
    n = int(xyz.shape[0] if n_points is None else n_points)
    avail = available_memory() if available is None else int(available)
    need = graph_memory(n)
    if avail is None or need <= avail:
        return
    fit = max((avail - MEMORY_BASE) // MEMORY_PER_POINT, 0)
    hint = "run on a machine with more memory"
    if fit > 0 and xyz.shape[0] > 1:
        v, kept = voxel_edge(np.asarray(xyz, dtype=np.float64), fit)
        if v > 0 and kept <= fit:
            thin = f"--downsample-voxel {v:g} (keeps {kept:,} points)"
            hint = f"thin it first, e.g. {thin}, or {hint}"
    raise InputError(
        f"{source}: {n:,} points need about {_gb(need)} GB to skeletonise "
        f"({MEMORY_BASE / 1e9:.2f} GB + {MEMORY_PER_POINT} bytes per point, measured); "
        f"{_gb(avail)} GB is available: {hint} (--no-memory-check runs it anyway)"
    )
