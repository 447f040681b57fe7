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


def check_memory(
    xyz: NDArray[np.float64], source: str, available: int | None = None, n_points: int | None = None
) -> None:
    """Raise :class:`InputError` when the skeleton stage on ``n_points`` points (default: all
    of ``xyz``) would need more memory (:func:`graph_memory`) than is ``available`` (default
    :func:`available_memory`; no check where it cannot be read). The message gives both
    figures and a ``--downsample-voxel`` edge that keeps about as many points as fit: over
    a surface holding ``ρ`` points per m² a voxel of edge ``v`` keeps one point per ``v²``
    where ``ρ v² ≫ 1``, so ``v = √(n / (n_fit ρ))``; ``ρ = ln 2 / (π s²)`` from the median
    nearest-neighbour distance ``s`` of randomly placed points (measured on a sample,
    :func:`_spacing`)."""
    n = int(xyz.shape[0] if n_points is None else n_points)
    avail = available_memory() if available is None else int(available)
    need = graph_memory(n)
    if avail is None or need <= avail:
        return
    fit = max((avail - MEMORY_BASE) // MEMORY_PER_POINT, 0)
    hint = "run on a machine with more memory"
    s = _spacing(np.asarray(xyz, dtype=np.float64)) if fit > 0 and xyz.shape[0] > 1 else 0.0
    if s > 0:
        v = s * np.sqrt(np.pi * n / (np.log(2.0) * fit))
        v = float(np.ceil(v * 1000.0) / 1000.0)  # up to the millimetre
        hint = f"thin it first, e.g. --downsample-voxel {v:g} (about {fit:,} points), or " + hint
    raise InputError(
        f"{source}: {n:,} points need about {need / 1e9:.1f} GB to skeletonise "
        f"({MEMORY_BASE / 1e9:.2f} GB + {MEMORY_PER_POINT} bytes per point, measured); "
        f"{avail / 1e9:.1f} GB is available: {hint} (--no-memory-check runs it anyway)"
    )
