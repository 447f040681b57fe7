"""Leaf pillar benchmark: reduction speed, 100,000-leaf field to GLB, time vs triangles,
reduction error on the 450 digitised wheat leaves; fidelity (issue 16): shape classes vs
the digitised leaves, maize LAI, gap fraction vs Beer–Lambert, 10,000 plants meshed + lit,
reduced twisted maize. Prints markdown tables.

Usage: .venv/bin/python bench/leaf.py [--quick] [--only fidelity|speed] [--plot DIR]
(``--quick``: 1,000 plants instead of 10,000 for the fields; ``--plot DIR`` writes
``leaf_classes.png``, data vs fitted class shapes.)
"""

from __future__ import annotations

import heapq
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from biomorph.leaf.canopy import FieldSpec, PlantSpec, build_field, field_mesh, leaf_area_index
from biomorph.leaf.data import shared_leaves, wheat_leaves
from biomorph.leaf.plots import time_vs_triangles
from biomorph.leaf.reduction import (
    _err,
    reduce_leaf,
    reduce_profile,
    reduced_mesh,
)
from biomorph.leaf.shape import LeafShape


def _median_time(fn, repeat: int = 30) -> float:
    fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def original_heap_emulation(x, z, s, w) -> np.ndarray:
    """Emulation of the defects reported for the original implementation, for comparison
    only: errors of neighbours are overwritten inside the heap list without restoring the
    heap order, and the 2nd and next-to-last points are removed first."""
    n = len(x)
    prev, nxt = list(range(-1, n - 1)), list(range(1, n + 1))
    alive = [True] * n
    entries = {i: [float(_err.py_func(i, i - 1, i + 1, x, z, s, w)), i] for i in range(1, n - 1)}
    for i in (1, n - 2):
        entries[i][0] = -1.0
    heap = list(entries.values())
    heapq.heapify(heap)
    order = []
    while heap:
        _, i = heapq.heappop(heap)
        if not alive[i]:
            continue
        a, b = prev[i], nxt[i]
        alive[i] = False
        nxt[a], prev[b] = b, a
        order.append(i)
        for j in (a, b):
            if 0 < j < n - 1:
                entries[j][0] = float(_err.py_func(j, prev[j], nxt[j], x, z, s, w))  # no sift
    return np.array(order, np.int64)


def main() -> None:
    quick = "--quick" in sys.argv
    only = sys.argv[sys.argv.index("--only") + 1] if "--only" in sys.argv else None
    plot = Path(sys.argv[sys.argv.index("--plot") + 1]) if "--plot" in sys.argv else None
    if only in (None, "fidelity"):
        fidelity(quick, plot)
    if only in (None, "speed"):
        speed(quick)


def speed(quick: bool) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.leaf.oracles import reduction_order_py  # the pure-Python reference

    rows = []
    wheat = LeafShape.from_preset("wheat")

    # 1. one 1,000-point leaf reduced to a 50-triangle mesh
    t_mesh = _median_time(lambda: reduced_mesh(wheat, 50, n_points=1000))
    red = reduce_leaf(wheat, 1000)
    t_order = _median_time(lambda: reduce_profile(red.s, red.x, red.z, red.w))
    t_py = _median_time(lambda: reduction_order_py(red.x, red.z, red.s, red.w), repeat=5)
    rows.append(
        (
            "1,000-point leaf → 50-triangle mesh (discretise+reduce+mesh)",
            f"{t_mesh * 1e3:.2f} ms",
            "≤ 5 ms",
        )
    )
    rows.append(("  reduction order only, numba heap", f"{t_order * 1e3:.3f} ms", ""))
    rows.append(("  reduction order only, Python heapq reference", f"{t_py * 1e3:.2f} ms", ""))

    # 2. a field of 10,000 plants × 10 leaves to GLB
    plants = 1000 if quick else 10000
    t0 = time.perf_counter()
    spec = FieldSpec(
        plants=plants,
        rows=plants // 100,
        row_spacing=0.15,
        plant=PlantSpec(preset="wheat", leaves=10, age=1.0),
    )
    fld = build_field(spec, seed=1)
    t1 = time.perf_counter()
    mesh = field_mesh(fld, triangles_per_leaf=20, stems=False)
    t2 = time.perf_counter()
    from biomorph.io.gltf import write_gltf

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "field.glb"
        write_gltf(out, mesh, y_up=False)
        size = out.stat().st_size
    t3 = time.perf_counter()
    rows.append(
        (
            f"field {plants:,} plants × 10 leaves = {fld.n_leaves:,} leaves, "
            f"{mesh.n_faces:,} triangles → GLB ({size / 1e6:.0f} MB)",
            f"{t3 - t0:.2f} s (build {t1 - t0:.2f}, mesh {t2 - t1:.2f}, write {t3 - t2:.2f})",
            "≤ 20 s (100,000 leaves)",
        )
    )
    rows.append(("  leaf area index of that field", f"{leaf_area_index(fld, mesh):.2f}", ""))

    print("| measurement | result | target |\n|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} |")

    # 3. time vs triangles (the paper's figure 6)
    budgets = [3, 5, 9, 15, 21, 31, 51, 101, 201]
    times = time_vs_triangles(wheat, budgets, leaves=1000, repeat=3)
    print(
        "\nTime vs triangles per leaf (1,000-leaf field: mesh + projected-area light proxy). "
        "Paper (Fournier & Pradal 2012, fig. 6): computation time falls with the number "
        "of triangles.\n"
    )
    print("| triangles per leaf | time (ms) |\n|---|---|")
    for b, t in zip(budgets, times, strict=True):
        print(f"| {b} | {t * 1e3:.1f} |")

    # 4. error at 9 kept points on the 450 digitised wheat leaves
    root = shared_leaves(required=False)
    if root is not None and (root / "adel" / "So99.csv").exists():
        leaves = wheat_leaves(root)
        ours, emul = [], []
        points = (4, 6, 9, 12, 16, 20)
        by_pts = {p: ([], []) for p in points}
        for leaf in leaves:
            r = reduce_leaf(leaf, 200)
            order = original_heap_emulation(r.x, r.z, r.s, r.w)
            for p in points:
                mask = np.ones(r.s.size, bool)
                mask[order[: r.s.size - p]] = False
                by_pts[p][0].append(r.error(r.kept_for_points(p))[0])
                by_pts[p][1].append(r.error(np.flatnonzero(mask))[0])
            ours.append(by_pts[9][0][-1])
            emul.append(by_pts[9][1][-1])
        print(
            "\nMidrib error at 9 kept points, 450 wheat leaves (So99 + SRSo), max distance "
            "of the 200-point discretisation to the reduced midrib, fraction of L:\n"
        )
        print("| algorithm | median | mean | 90th percentile |\n|---|---|---|---|")
        for name, e in (
            ("this heap (lazy deletion, version stamps)", ours),
            ("emulated original defects", emul),
        ):
            print(
                f"| {name} | {np.median(e):.4f} | {np.mean(e):.4f} | {np.percentile(e, 90):.4f} |"
            )
        print("| original algorithm as reported | 0.0105 | | |")
        print("\nMedian midrib error (fraction of L) vs kept points, 450 wheat leaves:\n")
        print("| kept points | " + " | ".join(map(str, points)) + " |")
        print("|---" * (len(points) + 1) + "|")
        print(
            "| this heap | " + " | ".join(f"{np.median(by_pts[p][0]):.4f}" for p in points) + " |"
        )
        print(
            "| emulated original | "
            + " | ".join(f"{np.median(by_pts[p][1]):.4f}" for p in points)
            + " |"
        )
    else:
        print("\n(wheat data absent: set BIOMORPH_SHARED_DATA; error table skipped)")


# --------------------------------------------------------------------------- fidelity
def _angle_median_curve(leaves):
    """The previous preset method (median of tangent angles), kept as the baseline."""
    from biomorph.leaf.fit import unit_curve

    s = np.linspace(0, 1, 101)
    phi = np.median([lf.phi_at(s) for lf in leaves], axis=0)
    return unit_curve(lambda q: np.interp(q, s, phi))


def classes_table(root, plot: Path | None) -> None:
    from biomorph.leaf.data import maize_leaves
    from biomorph.leaf.fit import (
        aligned_distances,
        aligned_pairwise,
        curves_of,
        max_distances,
        pairwise,
        shape_families,
        unit_curve,
    )
    from biomorph.leaf.shape import shape_classes

    print("\n### Shape classes vs the digitised leaves (max point distance, units of L)\n")
    print(
        "Distance: both midribs scaled to unit length, compared at the same 101 arc-length "
        "fractions, the largest gap. *Shape*: one insertion angle fitted per leaf (the "
        "preset turned about the leaf base, as ADEL's incline_leaf; the plant's insertion "
        "angle is a separate parameter); *as digitised*: no turn. One shape: the class "
        "preset; families: fewest k-medoids shape families (k <= 4) each with median <= "
        "0.1 L; ADEL-like: nearest member of the class database; baseline: median of "
        "tangent angles (the old presets). Spread: median pairwise distance. Target: median "
        "<= 0.1 L.\n"
    )
    print(
        "| preset | class | leaves | one shape: shape median (p90) | one shape: as digitised "
        "| families: k (worst median) | ADEL-like database (members) | angle-median "
        "baseline | spread shape / digitised | insertion IQR (deg) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    sets = {"wheat": wheat_leaves(root), "maize": maize_leaves(root)}
    curves_for_plot = {}
    for preset, leaves in sets.items():
        classes = shape_classes(preset)
        for key, c in classes.items():
            mine = [lf for lf in leaves if int(lf.name.split()[1][1:]) in c.get("ranks", [])]
            if preset == "wheat":
                mine = [lf for lf in leaves if lf.name.split()[1] == f"r{key}"]
            cur = curves_of(mine)
            ref = unit_curve(LeafShape.from_preset(preset, rank_class=key).phi_at)
            e, turn = aligned_distances(cur, ref)
            raw = max_distances(cur, ref)
            members = [
                unit_curve(LeafShape.from_preset(preset, rank_class=key, member=m).phi_at)
                for m in range(c["n_members"])
            ]
            near = np.min([max_distances(cur, mm) for mm in members], axis=0)
            base = np.median(max_distances(cur, _angle_median_curve(mine)))
            dist, d_raw = aligned_pairwise(cur), pairwise(cur)
            iu = np.triu_indices(len(cur), 1)
            spread = np.median(dist[iu]) if len(cur) > 1 else 0.0
            spread_raw = np.median(d_raw[iu]) if len(cur) > 1 else 0.0
            _, lab, fam = shape_families(dist)
            q = np.percentile(np.degrees(turn), [25, 75])
            print(
                f"| {preset} | {key} | {len(mine)} | {np.median(e):.3f} "
                f"({np.percentile(e, 90):.3f}) | {np.median(raw):.3f} | {len(fam)} "
                f"({max(fam):.3f}) | {np.median(near):.3f} ({c['n_members']}) | {base:.3f} | "
                f"{spread:.3f} / {spread_raw:.3f} | {q[0]:.0f}..{q[1]:.0f} |"
            )
            curves_for_plot[(preset, key)] = (cur, ref, turn)
        allc = curves_of(leaves)
        single = unit_curve(LeafShape.from_preset(preset).phi_at)
        group_of = {r: k for k, c in classes.items() for r in c.get("ranks", [])}
        per_rank, per_rank_raw = [], []
        for lf, cv in zip(leaves, allc, strict=True):
            rank = int(lf.name.split()[1][1:])
            key = str(rank) if preset == "wheat" else group_of[rank]
            cls = unit_curve(LeafShape.from_preset(preset, rank_class=key).phi_at)
            per_rank.append(float(aligned_distances(cv[None], cls)[0][0]))
            per_rank_raw.append(float(np.linalg.norm(cv - cls, axis=1).max()))
        print(
            f"| {preset} | all, by rank class | {len(leaves)} | {np.median(per_rank):.3f} "
            f"({np.percentile(per_rank, 90):.3f}) | {np.median(per_rank_raw):.3f} | | | "
            f"{np.median(max_distances(allc, _angle_median_curve(leaves))):.3f} | | |"
        )
        print(
            f"| {preset} | all, single mature preset | {len(leaves)} | "
            f"{np.median(aligned_distances(allc, single)[0]):.3f} | "
            f"{np.median(max_distances(allc, single)):.3f} | | | | | |"
        )
    if plot is not None:
        _plot_classes(curves_for_plot, plot / "leaf_classes.png")
        print(f"\n(wrote {plot / 'leaf_classes.png'})")


def _plot_classes(curves, path: Path) -> None:
    """Per class: the leaves as digitised with the class preset (top), and each leaf turned
    by its fitted insertion angle onto the preset (bottom: the shape comparison)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    keys = list(curves)
    cols = 6
    rows = 2 * int(np.ceil(len(keys) / cols))
    fig = Figure(figsize=(2.6 * cols, 2.5 * rows))
    FigureCanvasAgg(fig)
    for k, key in enumerate(keys):
        cur, ref, turn = curves[key]
        r0, c0 = divmod(k, cols)
        for row, title in ((2 * r0, "as digitised"), (2 * r0 + 1, "insertion fitted")):
            ax = fig.add_subplot(rows, cols, row * cols + c0 + 1)
            for c, a in zip(cur, turn, strict=True):
                z = c[:, 0] + 1j * c[:, 1]
                if row % 2:
                    z = z * np.exp(-1j * a)  # the leaf turned onto the preset
                ax.plot(z.real, z.imag, color=(0.6, 0.6, 0.6), lw=0.5)
            ax.plot(ref[:, 0], ref[:, 1], color=(0.1, 0.5, 0.1), lw=2.2)
            ax.set_title(f"{key[0]} class {key[1]} (n={len(cur)}), {title}", fontsize=7)
            ax.set_aspect("equal")
            ax.set_xlim(-0.6, 1.05)
            ax.set_ylim(-0.8, 1.05)
            ax.tick_params(labelsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=80)


def maize_lai_table(quick: bool) -> None:
    import warnings

    from biomorph.leaf.thermal import ThermalTime

    print(
        "\n### Mature maize fields (16 leaves, last leaf just ligulated; per-rank blades of "
        "the mature table: Yang & Alley 2005 bell, 0.5 m² per plant; shapes from the data)\n"
    )
    print("| plants/m² | row spacing (m) | plants | LAI | target |\n|---|---|---|---|---|")
    tt = ThermalTime.for_preset("maize")
    t16 = float(tt.thermal_time_of(16, tt.full_extension()))
    for dens in (7.0, 10.0):
        spec = FieldSpec(
            plants=200 if quick else 600,
            rows=10,
            row_spacing=0.75,
            density=dens,
            plant=PlantSpec(preset="maize", leaves=16, thermal_time=t16),
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fld = build_field(spec, seed=1)
        m = field_mesh(fld, 20, stems=False)
        print(f"| {dens:g} | 0.75 | {spec.plants} | {leaf_area_index(fld, m):.2f} | 3–5 |")


def beer_lambert_table() -> None:
    from biomorph.leaf.light import LightOptions, intercept, turbid_canopy

    print(
        "\n### Gap fraction vs Beer–Lambert, random turbid canopies (1 m² periodic tile, "
        "1.5 cm square leaves, 46 sky directions)\n"
    )
    print(
        "Expected P(θ) = exp(−G·LAI/cos θ): horizontal leaves G = cos θ, spherical "
        "G = 0.5. Target: max |difference| <= 0.02 over all directions.\n"
    )
    print(
        "| LAI | leaves | max abs diff, horizontal | max abs diff, spherical | "
        "zenith gap (spherical) | exp(−LAI/2) |\n|---|---|---|---|---|---|"
    )
    for lai in (0.5, 1.0, 2.0, 3.0, 5.0):
        diffs = []
        for hz in (True, False):
            m = turbid_canopy(lai, 1.0, 0.015, int(10 * lai) + hz, hz)
            r = intercept(m, LightOptions(sky=46, ground=(0, 0, 1, 1), ray_spacing=0.006))
            cz = r.directions[:, 2]
            exp = np.exp(-lai) * np.ones_like(cz) if hz else np.exp(-0.5 * lai / cz)
            diffs.append(np.abs(r.gap_by_direction - exp).max())
            z = r.gap_by_direction[0]
        print(
            f"| {lai:g} | {m.n_faces // 2:,} | {diffs[0]:.4f} | {diffs[1]:.4f} | {z:.4f} | "
            f"{np.exp(-lai / 2):.4f} |"
        )


def _timed(fn):
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0, time.process_time() - c0


def big_field_light(quick: bool) -> None:
    import os
    import warnings
    from datetime import datetime

    from biomorph.leaf.light import LightOptions, intercept

    plants = 1000 if quick else 10000
    print(
        f"\n### {plants:,} wheat plants × 10 leaves meshed + light (sun + 46 sky "
        "directions, periodic tile)\n"
    )
    print(
        "zbuffer: our engine (leaf/raster.py, numba, directions over both cores); embree: "
        "the same rays cast with Embree (embreex, one core), the peer measured in the same "
        "run. Wall and CPU (process_time, all threads) seconds; numba compiled beforehand.\n"
    )
    spec = FieldSpec(
        plants=plants,
        rows=int(np.sqrt(plants)),
        row_spacing=0.15,
        density=250.0,
        plant=PlantSpec(preset="wheat", leaves=10, age=1.0),
    )

    def build():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fld = build_field(spec, seed=1)
        return fld, field_mesh(fld, triangles_per_leaf=20, stems=False)

    (fld, mesh), mesh_wall, mesh_cpu = _timed(build)
    when = datetime(2026, 6, 21, 12)
    intercept(mesh, LightOptions(sky=16, ground=fld.tile, max_rays=100))  # compile
    runs = [("zbuffer", 100_000), ("embree", 100_000)]
    if not quick:
        runs.append(("zbuffer", 1_000_000))
    print(
        "| engine | rays / direction | mesh wall (CPU) s | light wall (CPU) s | total wall "
        "(CPU) s | plants/s (wall) | load | gap fraction | intercepted (µmol/s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    results = {}
    for engine, rays in runs:
        opts = LightOptions(when=when, sky=46, ground=fld.tile, max_rays=rays, engine=engine)
        load = os.getloadavg()[0]
        r, wall, cpu = _timed(lambda o=opts: intercept(mesh, o))
        results[(engine, rays)] = (r, wall, cpu)
        print(
            f"| {r.engine} | {rays:,} | {mesh_wall:.1f} ({mesh_cpu:.1f}) | {wall:.1f} "
            f"({cpu:.1f}) | {mesh_wall + wall:.1f} ({mesh_cpu + cpu:.1f}) | "
            f"{plants / (mesh_wall + wall):,.0f} | {load:.1f} | {r.gap_fraction:.4f} | "
            f"{r.energy.sum():,.0f} |"
        )
    z, e = results[("zbuffer", 100_000)], results[("embree", 100_000)]
    print(
        f"\nzbuffer / embree on the same rays: light wall {z[1] / e[1]:.2f}×, CPU "
        f"{z[2] / e[2]:.2f}×; max gap-fraction difference over the 47 directions "
        f"{np.abs(z[0].gap_by_direction - e[0].gap_by_direction).max():.1e}, intercepted "
        f"energy {abs(z[0].energy.sum() / e[0].energy.sum() - 1):.1e} apart. "
        f"{fld.n_leaves:,} leaves, {mesh.n_faces:,} triangles, LAI "
        f"{leaf_area_index(fld, mesh):.2f}. Target: 10,000 plants <= 60 s on 2 cores."
    )


def twisted_reduction_table() -> None:
    from biomorph.leaf.reduction import surface_error

    print(
        "\n### Reduced twisted + undulated maize (30° twist, 4 mm margin waves): largest "
        "distance of the exact surface to the mesh (mm)\n"
    )
    print(
        "Ours: adaptive mesh refined on the 3-D surface (greedy insertion + decimation + "
        "local moves, leaf/refine.py); measured on 400 × 9 surface points and, as a check "
        "on samples unlike the nodes, 1000 × 21. Strips: the paper's reduction (2D midrib "
        "+ width error).\n"
    )
    print(
        "| triangles | ours (400 × 9) | ours (1000 × 21) | strips, paper's 2D error | "
        "ratio | CPU (s) |\n|---|---|---|---|---|---|"
    )
    maize = LeafShape.from_preset("maize")
    reduced_mesh(maize, 20)  # compile
    for b in (50, 200, 400, 800):
        c0 = time.process_time()
        mesh = reduced_mesh(maize, b)
        cpu = time.process_time() - c0
        ours = surface_error(maize, mesh)
        dense = surface_error(maize, mesh, n_s=1000, n_u=21)
        flat = surface_error(maize, reduced_mesh(maize, b, surface=False))
        print(
            f"| {b} | {ours * 1e3:.3f} | {dense * 1e3:.3f} | {flat * 1e3:.2f} | "
            f"{flat / ours:.1f}× | {cpu:.1f} |"
        )
    print("\nTarget: <= 0.5 mm at 200 triangles.")


def fidelity(quick: bool, plot: Path | None) -> None:
    print("## Fidelity (issue 16)")
    root = shared_leaves(required=False)
    if root is not None:
        classes_table(root, plot)
    else:
        print("(leaf data absent: set BIOMORPH_SHARED_DATA; class table skipped)")
    maize_lai_table(quick)
    beer_lambert_table()
    twisted_reduction_table()
    big_field_light(quick)


if __name__ == "__main__":
    main()
