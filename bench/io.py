"""I/O throughput: LAS / LAZ / PLY / XYZ / NPY point-cloud reads and a BVH parse.

Usage: .venv/bin/python bench/io.py [--full]

* Point clouds of 10^5 and 10^6 points (``--full`` adds 3·10^6) with an intensity and a
  float ``Deviation`` attribute are written once, then read with ``biomorph.io.read_points``
  (median of 3 reads). The reference is the bare library call on the same file
  (``laspy.read`` + coordinate scaling, ``plyfile`` read + x/y/z to float64, ``np.loadtxt``,
  ``np.load`` + x/y/z stacking), so the ratio is biomorph's overhead for validation and
  attribute extraction.
* XYZ is written with 4 decimals (0.1 mm), as real text exports are.
* BVH: a 100,000-frame × 60-joint file (183 channels; built by writing 1,000 random frames
  with ``biomorph.io.bvh.write_bvh`` and repeating the MOTION rows) parsed with
  ``read_bvh``; target < 2 s. Skipped when ``biomorph.io.bvh`` does not exist.

Peak memory is the tracemalloc peak of the read (numpy allocations included). Prints a
markdown table; the load average is printed because the machine is shared.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np


def measure(fn: Callable[[], object], repeat: int = 3) -> tuple[float, float]:
    """(median seconds, peak MB of one traced call)."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return float(np.median(times)), peak / 1e6


def make_cloud(n: int, seed: int = 0):
    from biomorph.core.pointcloud import PointCloud

    rng = np.random.default_rng(seed)
    xyz = rng.uniform(0, 50, (n, 3)) + [400_000.0, 5_500_000.0, 100.0]
    return PointCloud(
        xyz,
        {
            "intensity": rng.integers(0, 65535, n).astype(np.uint16),
            "Deviation": rng.normal(0, 0.01, n).astype(np.float32),
        },
    )


def references(path: Path) -> Callable[[], object]:
    ext = path.suffix
    if ext in (".las", ".laz"):
        import laspy

        def ref():
            las = laspy.read(path)
            return np.stack([las.x, las.y, las.z], axis=1)

        return ref
    if ext == ".ply":
        import plyfile

        def ref_ply():
            v = plyfile.PlyData.read(str(path))["vertex"].data
            return np.stack([np.asarray(v[c], dtype=np.float64) for c in "xyz"], axis=1)

        return ref_ply
    if ext == ".npy":

        def ref_npy():
            a = np.load(path)
            return np.stack([a[c] for c in "xyz"], axis=1)

        return ref_npy
    return lambda: np.loadtxt(path, skiprows=1)


def bench_points(sizes: list[int], tmp: Path) -> list[list[str]]:
    from biomorph.io import read_points, write_points

    rows = []
    for n in sizes:
        cloud = make_cloud(n)
        for ext in (".las", ".laz", ".ply", ".npy", ".xyz"):
            path = tmp / f"c{n}{ext}"
            t0 = time.perf_counter()
            # text clouds in the wild carry mm / 0.1 mm decimals, not 17-digit reprs
            write_points(path, cloud, **({"precision": 4} if ext == ".xyz" else {}))
            t_write = time.perf_counter() - t0
            back = read_points(path)
            assert back.n_points == n
            sec, peak = measure(lambda p=path: read_points(p))
            ref, _ = measure(references(path))
            rows.append(
                [
                    f"{ext[1:].upper()} read",
                    f"{n:,}",
                    f"{sec:.3f}",
                    f"{n / sec / 1e6:.2f}",
                    f"{peak:.0f}",
                    f"{sec / ref:.2f}× ref",
                    f"write {t_write:.2f} s, {path.stat().st_size / 1e6:.1f} MB",
                ]
            )
            path.unlink()
    return rows


def bench_bvh(tmp: Path, frames: int = 100_000, joints: int = 60) -> list[list[str]]:
    try:
        from biomorph.io.bvh import read_bvh, write_bvh
        from biomorph.motion.motion import Motion
    except ModuleNotFoundError:
        return [["BVH parse", "skipped", "", "", "", "", "biomorph.io.bvh absent"]]
    from biomorph.core import transforms as tf
    from biomorph.core.skeleton import JointSkeleton

    rng = np.random.default_rng(0)
    parent = np.array([-1] + [int(rng.integers(max(0, i - 4), i)) for i in range(1, joints)])
    sk = JointSkeleton([f"j{i}" for i in range(joints)], parent, rng.normal(0, 10, (joints, 3)))
    block = 1000
    rot = tf.euler_to_quat(rng.uniform(-90, 90, (block, joints, 3)), "ZXY", degrees=True)
    mo = Motion(sk, rot, rng.normal(0, 50, (block, 3)), 1 / 120)
    small = write_bvh(tmp / "small.bvh", mo)
    head, rest = small.read_bytes().split(b"MOTION", 1)
    lines = rest.split(b"\n", 3)
    body = lines[3] if lines[3].endswith(b"\n") else lines[3] + b"\n"
    big = tmp / "big.bvh"
    copies = frames // block
    with open(big, "wb") as fh:
        fh.write(
            head + b"MOTION\nFrames: " + str(block * copies).encode() + b"\n" + lines[2] + b"\n"
        )
        for _ in range(copies):
            fh.write(body)
    read_bvh(small)  # warm-up (compiled kernels)
    sec, peak = measure(lambda: read_bvh(big), repeat=3)
    n_channels = 6 + 3 * (joints - 1)
    size = big.stat().st_size / 1e6
    return [
        [
            "BVH parse",
            f"{block * copies:,} frames × {joints} joints",
            f"{sec:.3f}",
            f"{block * copies * n_channels / sec / 1e6:.1f} M values/s",
            f"{peak:.0f}",
            f"{sec / 2.0:.2f}× target (2 s)",
            f"{size:.0f} MB file",
        ]
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="add 3·10^6-point clouds")
    args = ap.parse_args(argv)
    sizes = [100_000, 1_000_000] + ([3_000_000] if args.full else [])
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        rows = bench_points(sizes, tmp) + bench_bvh(tmp)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs\n")
    print("| task | size | seconds | M points/s | peak MB | ratio | notes |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
