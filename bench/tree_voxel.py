"""Benchmark of the tree pillar's part A: voxel method speed and accuracy, ground removal.

Run:  .venv/bin/python bench/tree_voxel.py [--quick] [--section speed|accuracy|ground]

Prints markdown tables:

1. **speed** -- the voxel method on a synthetic maple scan at grid widths 161 and 300
   (phase times t1..t4), and the thinning alone vs ``skimage.morphology.skeletonize``
   (3-D, Lee 1994) and ``kimimaro.skeletonize`` (TEASAR) on the same preprocessed volume,
   with our ratio to each.
2. **accuracy** -- voxel skeletons of synthetic trees (presets × clean / noisy+occluded ×
   seeds) against their ground truth: F1 within tolerance, NOB and TBL ratios, radius error.
3. **ground** -- grid vs CSF ground removal on synthetic scans with known ground labels
   (flat, tilted 10°, hilly) and on the TreeLS pine plot (no labels: proxies).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from biomorph.core.pointcloud import PointCloud
from biomorph.tree.ground import remove_ground
from biomorph.tree.metrics import compare_to_truth
from biomorph.tree.synthetic import generate_tree, simulate_scan
from biomorph.tree.thinning import thin_palagyi_kuba
from biomorph.tree.voxel import preprocess_volume, skeletonize_voxel, voxelize

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "trees"


def _best(fn, repeat: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def speed(quick: bool) -> None:
    truth = generate_tree("maple", seed=0)
    scan = simulate_scan(truth, n_points=60_000 if quick else 150_000, seed=0, ground=False)
    ext = float(np.ptp(scan.xyz, axis=0).max())
    thin_palagyi_kuba(np.ones((3, 3, 3), bool))  # JIT warm-up (cached on disk afterwards)
    print(
        "\n### Voxel method: full pipeline (synthetic maple, "
        f"{scan.n_points} points, extent {ext:.1f} m)\n"
    )
    print(
        "| grid width | cell (m) | grid | t1 voxelise (s) | t2 preprocess (s) | t3 thin (s) "
        "| t4 graph (s) | total (s) | nodes | target |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    vols = {}
    for width, target in ((161, 10), (300, 60)):
        cell = ext / width * 1.0001
        vs = skeletonize_voxel(scan, cell_size=cell)
        tm = vs.timings
        print(
            f"| {width} | {cell:.4f} | {'×'.join(map(str, vs.grid['shape']))} | "
            f"{tm['t1']:.2f} | {tm['t2']:.2f} | {tm['t3']:.2f} | {tm['t4']:.2f} | "
            f"{tm['total']:.2f} | {vs.graph.n_nodes} | < {target} s "
            f"{'✓' if tm['total'] < target else '✗'} |"
        )
        counts, _ = voxelize(scan.xyz, cell)
        vol, _ = preprocess_volume(counts, disc_radius=vs.grid["disc_radius"])
        vols[width] = vol
    print("\n### Thinning alone on the same preprocessed volume\n")
    print(
        "| grid width | object voxels | ours: Palágyi–Kuba (s) | skimage Lee (s) | "
        "kimimaro TEASAR (s) | ours / skimage | ours / kimimaro |"
    )
    print("|---|---|---|---|---|---|---|")
    rep = 1 if quick else 3
    for width, vol in vols.items():
        t_ours, _ = _best(lambda v=vol: thin_palagyi_kuba(v), rep)
        try:
            from skimage.morphology import skeletonize as sk

            t_sk, _ = _best(lambda v=vol: sk(v), rep)
        except Exception:  # noqa: BLE001 - optional peer: any failure is "not measured"
            t_sk = float("nan")
        try:
            import kimimaro

            lab = vol.astype(np.uint32)
            t_ki, _ = _best(
                lambda lab=lab: kimimaro.skeletonize(
                    lab, anisotropy=(1, 1, 1), dust_threshold=10, progress=False, parallel=1
                ),
                rep,
            )
        except Exception:  # noqa: BLE001 - optional peer: any failure is "not measured"
            t_ki = float("nan")
        print(
            f"| {width} | {int(vol.sum())} | {t_ours:.3f} | {t_sk:.3f} | {t_ki:.3f} | "
            f"{t_ours / t_sk:.2f} | {t_ours / t_ki:.2f} |"
        )


def accuracy(quick: bool) -> None:
    presets = ["aspen", "conifer"] if quick else ["maple", "birch", "aspen", "conifer"]
    seeds = [0] if quick else [0, 1, 2]
    print(
        "\n### Voxel method accuracy on synthetic trees (tolerance 0.1 m, 60k points, 3 scanners)\n"
    )
    print(
        "| preset | scan | seeds | F1 | precision | recall | NOB ratio | TBL ratio | "
        "radius err (>3 cm) | DBH err | total (s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for preset in presets:
        for label, kw in (
            ("clean", dict(noise=0.0, occlusion=False)),
            ("noise 5 mm + occlusion", dict(noise=0.005, occlusion=True)),
        ):
            rows = []
            for seed in seeds:
                truth = generate_tree(preset, seed=seed)
                scan = simulate_scan(truth, n_points=60_000, seed=seed, ground=False, **kw)
                vs = skeletonize_voxel(scan)
                m = compare_to_truth(vs.graph, truth, tolerance=0.1)
                rows.append(
                    [
                        m["f1"],
                        m["precision"],
                        m["recall"],
                        m["nob_ratio"],
                        m["tbl_ratio"],
                        m["radius_error"],
                        m["dbh_error"],
                        vs.timings["total"],
                    ]
                )
            a = np.nanmean(np.array(rows, dtype=float), axis=0)
            print(
                f"| {preset} | {label} | {len(seeds)} | {a[0]:.3f} | {a[1]:.3f} | "
                f"{a[2]:.3f} | {a[3]:.2f} | {a[4]:.2f} | {a[5]:.3f} | {a[6]:+.3f} | "
                f"{a[7]:.1f} |"
            )


def _tilt(c: PointCloud, deg: float) -> PointCloud:
    a = np.radians(deg)
    rot = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    return c.with_(xyz=c.xyz @ rot.T)


def _hilly(c: PointCloud) -> PointCloud:
    xyz = c.xyz.copy()
    xyz[:, 2] += 0.6 * np.sin(xyz[:, 0] / 2.5) + 0.4 * np.cos(xyz[:, 1] / 3.0)
    return c.with_(xyz=xyz)


def ground(quick: bool) -> None:
    print(
        "\n### Ground removal on synthetic scans with known labels (ground = 20 % of 20k points)\n"
    )
    print("| terrain | method | precision | recall | F1 | wood lost (%) | seconds |")
    print("|---|---|---|---|---|---|---|")
    presets = ["maple", "conifer"] if quick else ["maple", "birch", "aspen", "conifer"]
    for terrain, f in (
        ("flat", lambda c: c),
        ("tilted 10°", lambda c: _tilt(c, 10)),
        ("hilly ±1 m", _hilly),
    ):
        for method in ("grid", "csf"):
            agg = []
            for preset in presets:
                truth = generate_tree(preset, seed=0)
                scan = f(simulate_scan(truth, n_points=20_000, seed=0))
                lab = scan.attributes["is_ground"]
                t = time.perf_counter()
                _, mask = remove_ground(scan, method=method)
                dt = time.perf_counter() - t
                tp = (mask & lab).sum()
                fp = (mask & ~lab).sum()
                p = tp / max(tp + fp, 1)
                r = tp / max(lab.sum(), 1)
                agg.append([p, r, 2 * p * r / max(p + r, 1e-12), fp / (~lab).sum() * 100, dt])
            a = np.mean(agg, axis=0)
            print(
                f"| {terrain} | {method} | {a[0]:.4f} | {a[1]:.4f} | {a[2]:.4f} | "
                f"{a[3]:.2f} | {a[4]:.2f} |"
            )
    path = SHARED / "treels_pine_plot.laz"
    if not path.exists():
        print(f"\n(pine plot not found at {path}; skipped)")
        return
    import laspy

    las = laspy.read(path)
    xyz = np.column_stack([las.x, las.y, las.z]).astype(float)
    cloud = PointCloud(xyz - xyz.min(axis=0), source=str(path))
    print(f"\n### Ground removal on the TreeLS pine plot ({cloud.n_points} points, no labels)\n")
    print(
        "Proxies: *veg. below 0.3 m* = non-ground points less than 0.3 m above the "
        "lowest ground point of their 1 m cell (missed ground); *ground above 0.5 m* = "
        "ground points more than 0.5 m above their cell's lowest point (stems/branches "
        "called ground); *roughness* = std of ground heights about a 1 m-cell median "
        "surface.\n"
    )
    print(
        "| method | ground points | veg. below 0.3 m | ground above 0.5 m | roughness (m) | "
        "seconds |"
    )
    print("|---|---|---|---|---|---|")
    for method in ("grid", "csf"):
        t = time.perf_counter()
        _, mask = remove_ground(cloud, method=method)
        dt = time.perf_counter() - t
        ij = np.floor(cloud.xyz[:, :2]).astype(int)
        key = ij[:, 0] * 1000 + ij[:, 1]
        uniq, inv = np.unique(key, return_inverse=True)
        gmin = np.full(uniq.size, np.inf)
        np.minimum.at(gmin, inv, np.where(mask, cloud.xyz[:, 2], np.inf))
        cmin = np.full(uniq.size, np.inf)
        np.minimum.at(cmin, inv, cloud.xyz[:, 2])
        h_g = cloud.xyz[:, 2] - gmin[inv]
        miss = int((~mask & np.isfinite(h_g) & (h_g < 0.3)).sum())
        high = int((mask & (cloud.xyz[:, 2] - cmin[inv] > 0.5)).sum())
        gz = cloud.xyz[mask, 2]
        med = np.zeros(uniq.size)
        for k in np.unique(inv[mask]):  # per cell (100 cells)
            med[k] = np.median(cloud.xyz[mask & (inv == k), 2])
        rough = float(np.std(gz - med[inv[mask]]))
        print(f"| {method} | {int(mask.sum())} | {miss} | {high} | {rough:.3f} | {dt:.2f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller runs (CI smoke test)")
    ap.add_argument("--section", choices=["speed", "accuracy", "ground"], action="append")
    args = ap.parse_args(argv)
    sections = args.section or ["speed", "accuracy", "ground"]
    print(
        f"tree_voxel benchmark ({time.strftime('%Y-%m-%d %H:%M')}, python {sys.version.split()[0]})"
    )
    for s in sections:
        {"speed": speed, "accuracy": accuracy, "ground": ground}[s](args.quick)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
