"""Tree pillar benchmark: speed, accuracy on synthetic trees, agreement on real clouds.

    .venv/bin/python bench/tree.py              # 14k + 100k timing, accuracy, real data
    .venv/bin/python bench/tree.py --full       # + 1,000,000 points
    .venv/bin/python bench/tree.py --only speed|accuracy|real [--seeds 3]
    .venv/bin/python bench/tree.py --only peers [--clouds rtwig_cloud.txt] [--no-pytlidar]
    .venv/bin/python bench/tree.py --only truth [--seeds 3] [--sizes 60000 240000]
    .venv/bin/python bench/tree.py --only sparse [--seeds 2]   # twig recall, volume at 5 cm
    .venv/bin/python bench/tree.py --only stand [--seeds 4]    # plot crown partition
    .venv/bin/python bench/tree.py --only density [--clouds ...]  # real clouds thinned
    .venv/bin/python bench/tree.py --only seeds [--clouds ...]    # repeatability, >= 4 seeds
    .venv/bin/python bench/tree.py --only jitter [--clouds ...]   # ties broken otherwise
    .venv/bin/python bench/tree.py --only runs    # run cylinders vs pytlidar's LSF cylinder
    .venv/bin/python bench/tree.py --only models [--models 5]  # uncertainty, chosen model
    .venv/bin/python bench/tree.py --only peers --with-models    # + column: 5 models, chosen
    .venv/bin/python bench/tree.py --only peers --fine    # + column: --residual-threshold 0.5
    .venv/bin/python bench/tree.py --only peers --coarse  # + column: --residual-threshold 1

``peers`` prints one table per real cloud: measure × (each reference model, biomorph graph,
biomorph voxel, pytlidar -- PyPI's Python TreeQSM, install with ``pip install --no-deps
pytlidar plotly``), with wall and CPU seconds of the same run; every model is read as a
BranchGraph and measured by the same functions (:mod:`biomorph.tree.metrics`).
``truth`` compares volume (total and per diameter class), length and F1 with the synthetic
truth of the presets (clean and 8 mm noise + occlusion + leaves).

Prints markdown tables with the thesis's figures beside ours. Each timing runs in a fresh
subprocess so its peak memory (``ru_maxrss``) is its own. Times are wall-clock seconds on
whatever machine runs this (the figures in docs/tree.md name theirs).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from biomorph.tree.residual import RESIDUAL_FINE

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "trees"

THESIS_GRAPH = {"14k": "~1,200 s (t3 ≈ 1,100 s gradient descent)", "livny": "~7 s (Livny 2010)"}
THESIS_ACC = {
    "graph": "NOB 91–103 %, TBL 89–101 % (B4/B5; B6 NOB 170 %)",
    "voxel": "NOB 115–140 %, TBL 75–102 %",
}
TARGET = "NOB ±10 %, TBL ±5 %, F1 ≥ 0.9, radius error ≤ 15 % (> 3 cm branches)"


def _cloud(n: int, seed: int = 0, occlusion: bool = True):
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    truth = generate_tree("maple", seed=seed)
    return truth, simulate_scan(
        truth, n_points=n, seed=seed, noise=0.003, ground=False, occlusion=occlusion
    )


def one_timing(n: int) -> dict:
    """Run in a subprocess: full graph pipeline on an n-point synthetic maple."""
    from biomorph.tree.pipeline import skeletonize

    truth, cloud = _cloud(n, occlusion=n <= 200_000)
    skeletonize(cloud.select(np.arange(min(2000, n))), ground=None)  # numba warm-up
    t0 = time.perf_counter()
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    skel = skeletonize(cloud, ground=None)
    total = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    t = skel.timings
    return {
        "points": cloud.n_points,
        "total": total,
        "cpu": cpu,
        **{
            k: t.get(k, 0.0)
            for k in (
                "prepare",
                "t1",
                "t2",
                "t3",
                "t4",
                "radius_fit",
                "order",
                "metrics",
                "neighbour_graph",
                "bridging",
                "dijkstra",
                "contraction",
                "optimisation",
                "radii",
            )
        },
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "nodes": skel.graph.n_nodes,
        "iterations": t.get("iterations"),
    }


def speed(full: bool) -> None:
    sizes = [14_000, 100_000] + ([1_000_000] if full else [])
    rows = []
    for n in sizes:
        out = subprocess.run(
            [sys.executable, __file__, "--one", str(n)],
            capture_output=True,
            text=True,
            check=True,
            cwd=ROOT,
        )
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    print(
        "\n### Graph method, full pipeline (prepare, Livny i–viii, RANSAC radii, orders, metrics)\n"
    )
    print(
        "| points | total s | CPU s | prepare | t1 roots | t2 graph+Dijkstra+contraction | "
        "t3 optimisation | t4 cleanup | radius fit | metrics | peak MB | nodes | thesis |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        thesis = THESIS_GRAPH["14k"] if r["points"] <= 20_000 else "—"
        print(
            f"| {r['points']:,} | {r['total']:.2f} | {r['cpu']:.1f} | {r['prepare']:.2f} | "
            f"{r['t1']:.2f} | "
            f"{r['t2']:.2f} | {r['t3']:.2f} | {r['t4']:.2f} | {r['radius_fit']:.2f} | "
            f"{r['metrics']:.2f} | {r['peak_mb']:.0f} | {r['nodes']:,} | {thesis} |"
        )
    print(
        "\nSub-phases (s): "
        + "; ".join(
            f"{r['points']:,}: kNN {r['neighbour_graph']:.2f}, bridging {r['bridging']:.2f}, "
            f"Dijkstra {r['dijkstra']:.2f}, contraction {r['contraction']:.2f}, "
            f"exact solves ×{int(r['iterations'] or 0)} {r['optimisation']:.2f}"
            for r in rows
        )
    )
    print(
        f"Targets: 14k < 2 s; 1M < 60 s and < 6 GB. Thesis: {THESIS_GRAPH['14k']}; "
        f"{THESIS_GRAPH['livny']}."
    )


def accuracy(seeds: int, points: int, tip_support: float | None = None) -> None:
    from biomorph.tree.metrics import compare_to_truth
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.synthetic import PRESETS, generate_tree, simulate_scan

    conditions = {
        "clean": dict(noise=0.002, occlusion=False, scanners=4),
        "noisy+occluded": dict(noise=0.008, occlusion=True, scanners=2, leaves=0.05),
    }
    print(
        f"\n### Accuracy on synthetic trees ({points:,} points, seeds 0..{seeds - 1}, "
        "median over seeds" + (f", graph tip_support={tip_support}" if tip_support else "") + ")\n"
    )
    print(
        "| preset | condition | method | NOB % | TBL % | TBL % of observed | observed | F1 | "
        "radius err | DBH err | seconds |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    summary: dict[str, list] = {"graph": [], "voxel": []}
    for preset in sorted(PRESETS):
        for cname, kw in conditions.items():
            res: dict[str, list] = {"graph": [], "voxel": []}
            for seed in range(seeds):
                truth = generate_tree(preset, seed=seed)
                cloud = simulate_scan(truth, n_points=points, seed=seed, ground=True, **kw)
                for method in ("graph", "voxel"):
                    t0 = time.perf_counter()
                    try:
                        skel = skeletonize(
                            cloud,
                            method=method,
                            tip_support=tip_support if method == "graph" else None,
                        )
                    except Exception as exc:  # noqa: BLE001 - report and carry on
                        print(f"<!-- {preset} {cname} {method} seed {seed}: {exc} -->")
                        continue
                    dt = time.perf_counter() - t0
                    c = compare_to_truth(skel.world_graph(), truth, cloud=cloud)
                    res[method].append(
                        [
                            c["nob_ratio"],
                            c["tbl_ratio"],
                            c["f1"],
                            c["radius_error"] or np.nan,
                            c["dbh_error"] or np.nan,
                            dt,
                            c["tbl_ratio_observed"],
                            c["observed_fraction"],
                        ]
                    )
            for method, vals in res.items():
                if not vals:
                    continue
                v = np.nanmedian(np.array(vals, dtype=float), axis=0)
                summary[method].append(v)
                print(
                    f"| {preset} | {cname} | {method} | {100 * v[0]:.0f} | {100 * v[1]:.0f} "
                    f"| {100 * v[6]:.0f} | {100 * v[7]:.0f} % | {v[2]:.3f} | "
                    f"{100 * v[3]:.1f} % | {100 * v[4]:+.1f} % | {v[5]:.1f} |"
                )
    for method, vals in summary.items():
        if vals:
            a = np.array(vals)
            print(
                f"\n{method}: NOB {100 * a[:, 0].min():.0f}–{100 * a[:, 0].max():.0f} %, "
                f"TBL {100 * a[:, 1].min():.0f}–{100 * a[:, 1].max():.0f} % "
                f"({100 * a[:, 6].min():.0f}–{100 * a[:, 6].max():.0f} % of the observed "
                "truth), "
                f"F1 {a[:, 2].min():.3f}–{a[:, 2].max():.3f}, radius error "
                f"{100 * np.nanmax(a[:, 3]):.1f} % max. Thesis: {THESIS_ACC[method]}."
            )
    print(f"Targets (graph): {TARGET}.")


def real() -> None:
    from biomorph.io import read_graph, read_points
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.reference import compare_to_reference, read_qsm_csv

    if not DATA.is_dir():
        print(f"\n(real data not found at {DATA}; skipped)")
        return
    print("\n### Agreement with reference models (tolerance 5 cm)\n")
    print(
        "| cloud | reference | tips (ref) | length m (ref) | base radius cm (ref) | "
        "radius profile err | F1 | seconds |"
    )
    print("|---|---|---|---|---|---|---|---|")
    cases = [
        (
            "rtwig_cloud.txt",
            "SimpleForest QSM",
            lambda c: read_qsm_csv(DATA / "rtwig_QSM_simpleforest.csv"),
        ),
        (
            "plantscan3d_A3B4.asc",
            "plantscan3d MTG",
            lambda c: (lambda m: m.with_(position=m.position + c.xyz.mean(axis=0)))(
                read_graph(DATA / "plantscan3d_A3B4.mtg")
            ),
        ),
    ]
    for name, label, ref_fn in cases:
        cloud = read_points(DATA / name)
        ref = ref_fn(cloud)
        t0 = time.perf_counter()
        skel = skeletonize(cloud)
        dt = time.perf_counter() - t0
        c = compare_to_reference(skel.world_graph(), ref, tolerance=0.05)
        print(
            f"| {name} | {label} | {c['tips']} ({c['tips_reference']}) | {c['length']:.2f} "
            f"({c['length_reference']:.2f}) | {100 * c['base_radius']:.2f} "
            f"({100 * c['base_radius_reference']:.2f}) | "
            f"{100 * c['radius_profile_error']:.0f} % | {c['f1']:.3f} | {dt:.2f} |"
        )
    print("\n### Other real clouds (graph method, defaults)\n")
    print(
        "| cloud | points | pieces bridged | trees | NOB | TBL m | trunk r cm | DBH cm | seconds |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in (
        "adtree_tree1.xyz",
        "adtree_tree7.xyz",
        "treels_spruce.laz",
        "archi_tree2.las",
        "treels_pine_plot.laz",
    ):
        cloud = read_points(DATA / name)
        t0 = time.perf_counter()
        skel = skeletonize(cloud)
        dt = time.perf_counter() - t0
        m = skel.metrics
        dbh = [d for d in (m.get("dbh") or []) if d]
        tr = m["trunk_radius"]
        print(
            f"| {name} | {cloud.n_points:,} | {skel.info['components']} | {m['n_trees']} | "
            f"{m['nob']} | {m['tbl']:.1f} | {100 * np.median(tr):.1f} | "
            f"{100 * np.median(dbh) if dbh else float('nan'):.1f} | {dt:.1f} |"
        )


# ----------------------------------------------------------------------------- peers (issue 13)

#: the clouds of the peer table, and the reference models that come with them
PEER_CLOUDS = (
    "rtwig_cloud.txt",
    "plantscan3d_A3B4.asc",
    "adtree_tree1.xyz",
    "adtree_tree7.xyz",
    "archi_tree2.las",
    "treels_spruce.laz",
    "treels_pine_plot.laz",
    "adtree_tiny_for_debug.xyz",
)
#: pytlidar is a single-tree method (TreeQSM): a plot of several trees is not its input
SINGLE_TREE_ONLY = {"treels_pine_plot.laz"}


def cylinders_to_graph(start, axis, length, radius, parent, order):
    """A cylinder model (``parent`` 0-based, -1 = none) as a BranchGraph: one node at the end
    of every cylinder plus one at the start of every root cylinder; each node carries its
    cylinder's radius and branch order, so tree A's metrics read every model alike."""
    from biomorph.core.graph import BranchGraph

    start = np.asarray(start, float).reshape(-1, 3)
    end = start + np.asarray(axis, float).reshape(-1, 3) * np.asarray(length, float)[:, None]
    parent = np.asarray(parent, np.int64)
    m = parent.size
    roots = np.flatnonzero(parent < 0)
    par = np.where(parent >= 0, parent, m + np.searchsorted(roots, np.arange(m)))
    rad = np.asarray(radius, float)
    dep = np.asarray(order, np.int64)
    return BranchGraph(
        np.vstack([end, start[roots]]),
        np.concatenate([par, np.full(roots.size, -1)]),
        radius=np.concatenate([rad, rad[roots]]),
        depth=np.concatenate([dep, dep[roots]]),
    )


def read_treeqsm_mat(path: Path):
    """TreeQSM's ``OptQSM.cylinder`` (MATLAB, 1-based parents, 0 = none) as a BranchGraph."""
    import scipy.io as sio

    q = sio.loadmat(path, squeeze_me=True, struct_as_record=False)["OptQSM"]
    c = q.cylinder
    return cylinders_to_graph(
        c.start, c.axis, c.length, c.radius, np.asarray(c.parent, np.int64) - 1, c.BranchOrder
    )


def run_pytlidar(xyz: NDArray) -> dict:
    """PyTLidar's TreeQSM on the points, with its own input estimate (``define_input``);
    no plots or files. Returns the BranchGraph, wall and CPU seconds (or ``error``)."""
    import contextlib
    import io
    import logging
    import os
    import tempfile

    os.environ.setdefault("MPLBACKEND", "Agg")
    logging.getLogger("matplotlib.font_manager").setLevel(logging.ERROR)
    try:
        from PyTLidar.treeqsm import treeqsm
        from PyTLidar.Utils.define_input import define_input
    except ImportError:
        return {"error": "pytlidar not installed (pip install --no-deps pytlidar plotly)"}
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        with contextlib.redirect_stdout(io.StringIO()), tempfile.TemporaryDirectory() as tmp:
            inp = define_input(np.asarray(xyz, float), 1, 1, 1)[0]
            inp.update(plot=0, savetxt=0, savemat=0, disp=0, savepdf=0)
            models, _ = treeqsm(np.asarray(xyz, float), inp, results_location=tmp)
        c = models[0]["cylinder"]
        par = np.asarray(c["parent"], np.int64)
        par = par - 1 if par.min() >= 0 and par[0] == 0 and par.size > 1 and par[1] == 1 else par
        g = cylinders_to_graph(
            c["start"], c["axis"], c["length"], c["radius"], par, c["BranchOrder"]
        )
        out: dict = {"graph": g}
    except Exception as exc:  # noqa: BLE001 - a peer failing is a result, not a crash
        out = {"error": f"{type(exc).__name__}: {str(exc)[:80]}"}
    out.update(wall=time.perf_counter() - t0, cpu=time.process_time() - c0)
    return out


def run_biomorph(cloud, method: str, graph_kw: dict | None = None) -> dict:
    """One pipeline run; ``graph_kw`` are extra keywords of ``livny.skeletonize_graph``
    not yet in the options (``level_merge``, ``reach``: the issue-13 variants)."""
    import functools

    from biomorph.tree import livny
    from biomorph.tree.pipeline import skeletonize

    t0, c0 = time.perf_counter(), time.process_time()
    orig = livny.skeletonize_graph
    if graph_kw:
        livny.skeletonize_graph = functools.partial(orig, **graph_kw)
    try:
        base, kw = method_options(method)
        skel = skeletonize(cloud, method=base, **kw)
        out: dict = {"graph": skel.world_graph(), "trees": skel.metrics.get("n_trees")}
        if skel.cloud is not None:
            out["wood"] = skel.cloud.xyz + skel.offset  # above ground, no foliage/outliers
    except Exception as exc:  # noqa: BLE001 - reported in the table
        out = {"error": f"{type(exc).__name__}: {str(exc)[:80]}"}
    finally:
        livny.skeletonize_graph = orig
    out.update(wall=time.perf_counter() - t0, cpu=time.process_time() - c0)
    return out


def method_options(method: str) -> tuple[str, dict]:
    """``"graph-runs"`` / ``"voxel-runs"``: the method without the run cylinders
    (``run_cylinders=False``; the graph method's default since session 19);
    ``"graph+runs"`` / ``"voxel+runs"``: with them; ``"graph-limbs"`` / ``"voxel-limbs"``:
    without turning reversed limbs round (``reversed_limbs=False``, session 21);
    ``"graph+fine"`` / ``"voxel+fine"``: ``--residual-threshold`` :data:`FINE_RESIDUAL`
    (session 28); ``"graph+coarse"`` / ``"voxel+coarse"``: ``--residual-threshold 1`` (the
    fixed default before session 29's ``auto``); anything else as given (its default)."""
    if method.endswith("-limbs"):
        return method[: -len("-limbs")], {"reversed_limbs": False}
    if method.endswith("-runs"):
        return method[: -len("-runs")], {"run_cylinders": False}
    if method.endswith("+fine"):
        return method[: -len("+fine")], {"residual_threshold": FINE_RESIDUAL}
    if method.endswith("+coarse"):
        return method[: -len("+coarse")], {"residual_threshold": 1.0}
    base, _, extra = method.partition("+")
    return base, ({"run_cylinders": True} if extra == "runs" else {})


#: ``--residual-threshold`` of the ``+fine`` methods and the ``--fine`` peer column: half
#: a node spacing (docs/tree.md, session 28), what ``auto`` chooses on a clean scan whose
#: twigs present a surface (session 29)
FINE_RESIDUAL = RESIDUAL_FINE

#: graph variant shown beside the default by ``--variant`` (docs/tree.md "Topology, peers
#: and speed"): the opt-in adaptive level merge of issue 13's session 7
VARIANT = {"level_merge": "adaptive"}


def model_measures(graph, xyz: NDArray, refs: dict, wood: NDArray | None = None) -> dict:
    """The peer-table measures of one model (tree A's metrics; F1 against each reference).

    ``wood``: the points the biomorph graph run kept as wood (above the ground, foliage and
    outliers removed); the far share is reported on them too, the same set for every model.
    """
    from biomorph.tree.metrics import class_labels, cylinder_fit, tree_attributes, volume_by_class
    from biomorph.tree.reference import compare_to_reference

    attrs = tree_attributes(graph)
    fit = cylinder_fit(graph, xyz)
    vc = volume_by_class(graph)
    row = {
        "volume": sum(a["total_volume"] for a in attrs) * 1e3,
        "length": sum(a["total_length"] for a in attrs),
        "trunk": max(a["trunk_length"] for a in attrs),
        "tips": int(graph.leaves.size),
        "max_order": max(a["max_order"] for a in attrs),
        "far": 100 * fit["far_share"],
    }
    if wood is not None and len(wood):
        row["far wood"] = 100 * cylinder_fit(graph, wood)["far_share"]
    for lab in class_labels():
        row[f"V {lab}"] = vc[lab]["volume"] * 1e3
        for key, tag in (("residual", "res"), ("axis_residual", "axres")):
            res = fit["classes"][lab][key]
            row[f"{tag} {lab}"] = 100 * res if np.isfinite(res) else float("nan")
    for name, ref in refs.items():
        row[f"F1 vs {name}"] = compare_to_reference(graph, ref, tolerance=0.05)["f1"]
    return row


PEER_ROWS = [
    ("volume", "volume L", "{:.1f}"),
    ("length", "length m", "{:.1f}"),
    ("trunk", "trunk length m", "{:.2f}"),
    ("tips", "tips", "{:d}"),
    ("max_order", "max order", "{:d}"),
]


def _fmt(v, f: str) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "—"
    return f.format(int(v)) if "d" in f else f.format(v)


def _warm_up(with_pytlidar: bool) -> None:
    """One untimed run of every contestant on a small synthetic tree first: numba's compiled
    kernels load from (or, after an edit, go into) the cache, and the imports happen, before
    any timed run — a cold first run cost biomorph 7 s on the rTwig cloud."""
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    cloud = simulate_scan(generate_tree("aspen", seed=0), n_points=5000, seed=0)
    t0 = time.perf_counter()
    for method in ("graph", "voxel"):
        run_biomorph(cloud, method)
    if with_pytlidar:
        run_pytlidar(cloud.xyz)
    print(f"(warm-up, untimed: {time.perf_counter() - t0:.1f} s)")


def run_models(cloud, n: int) -> dict:
    """``n`` graph models, the nearest to the points kept (:mod:`biomorph.tree.models`),
    as a peer-table column."""
    from biomorph.tree.models import reconstruct_models

    t0, c0 = time.perf_counter(), time.process_time()
    try:
        m = reconstruct_models(cloud, n)
        out: dict = {"graph": m.skeleton.world_graph()}
    except Exception as exc:  # noqa: BLE001 - reported in the table
        out = {"error": f"{type(exc).__name__}: {str(exc)[:80]}"}
    out.update(wall=time.perf_counter() - t0, cpu=time.process_time() - c0)
    return out


def _peer_columns(
    cloud,
    refs: dict,
    with_pytlidar: bool,
    variant: bool,
    runs: bool,
    models: int = 0,
    fine: bool = False,
    coarse: bool = False,
) -> dict:
    """The peer table's columns: each reference, our methods (and variants), pytlidar;
    ``models`` > 1: also the graph method's chosen model of that many."""
    cols: dict[str, dict] = {k: {"graph": g, "wall": None, "cpu": None} for k, g in refs.items()}
    cols["biomorph graph"] = run_biomorph(cloud, "graph")
    if models > 1:
        cols[f"graph, {models} models"] = run_models(cloud, models)
    if variant:
        cols["graph " + ", ".join(map(str, VARIANT.values()))] = run_biomorph(
            cloud, "graph", VARIANT
        )
    if fine:
        cols["graph+fine"] = run_biomorph(cloud, "graph+fine")
    if coarse:
        cols["graph+coarse"] = run_biomorph(cloud, "graph+coarse")
    cols["biomorph voxel"] = run_biomorph(cloud, "voxel")
    if runs:
        cols["graph-runs"] = run_biomorph(cloud, "graph-runs")
    if with_pytlidar:
        cols["pytlidar"] = run_pytlidar(cloud.xyz)
    return cols


def reference_models(name: str, xyz: NDArray) -> dict:
    """The published reference models of a shared cloud, in its frame (name → graph)."""
    from biomorph.io import read_graph
    from biomorph.tree.reference import read_qsm_csv

    refs: dict = {}
    if name == "rtwig_cloud.txt":
        refs["TreeQSM"] = read_treeqsm_mat(DATA / "rtwig_QSM_treeqsm.mat")
        refs["SimpleForest"] = read_qsm_csv(DATA / "rtwig_QSM_simpleforest.csv")
    if name == "plantscan3d_A3B4.asc":
        m = read_graph(DATA / "plantscan3d_A3B4.mtg")
        refs["plantscan3d"] = m.with_(position=m.position + xyz.mean(axis=0))
    return refs


def peers(
    names: tuple[str, ...],
    with_pytlidar: bool = True,
    variant: bool = False,
    runs: bool = False,
    models: int = 0,
    fine: bool = False,
    coarse: bool = False,
) -> None:
    from biomorph.io import read_points
    from biomorph.tree.metrics import class_labels

    if not DATA.is_dir():
        print(f"\n(real data not found at {DATA}; skipped)")
        return
    _warm_up(with_pytlidar)
    for name in names:
        cloud = read_points(DATA / name)
        xyz = cloud.xyz
        refs = reference_models(name, xyz)
        cols = _peer_columns(
            cloud,
            refs,
            with_pytlidar and name not in SINGLE_TREE_ONLY,
            variant,
            runs,
            models,
            fine,
            coarse,
        )
        meas = {}
        for k, c in cols.items():
            if "graph" in c:
                try:
                    meas[k] = model_measures(
                        c["graph"], xyz, refs, cols["biomorph graph"].get("wood")
                    )
                except Exception as exc:  # noqa: BLE001 - reported in the table
                    c["error"] = f"{type(exc).__name__}: {str(exc)[:80]}"
        print(f"\n### {name} ({cloud.n_points:,} points)\n")
        print("| measure | " + " | ".join(cols) + " |")
        print("|---|" + "---|" * len(cols))
        rows = list(PEER_ROWS)
        rows += [(f"F1 vs {r}", f"F1@5 cm vs {r}", "{:.3f}") for r in refs]
        rows += [(f"V {lab}", f"volume {lab} L", "{:.2f}") for lab in class_labels()]
        rows += [("far", "points > 10 cm from every cylinder %", "{:.1f}")]
        rows += [("far wood", "wood points > 10 cm from every cylinder %", "{:.1f}")]
        rows += [
            (f"res {lab}", f"median signed residual {lab} % of r", "{:+.0f}")
            for lab in class_labels()
        ]
        # each point to its nearest axis, not surface: an over-thick cylinder among thin
        # ones no longer lends its inside points to their surfaces (metrics.cylinder_fit)
        rows += [
            (f"axres {lab}", f"same, nearest axis {lab} % of r", "{:+.0f}")
            for lab in class_labels()
        ]
        for key, label, f in rows:
            cells = [_fmt(meas[k].get(key), f) if k in meas else "—" for k in cols]
            print(f"| {label} | " + " | ".join(cells) + " |")
        for what in ("wall", "cpu"):
            cells = [_fmt(c.get(what), "{:.1f}") for c in cols.values()]
            print(f"| {what} s | " + " | ".join(cells) + " |")
        for k, c in cols.items():
            if "error" in c:
                print(f"\n{k}: {c['error']}")
        if (
            "pytlidar" in cols
            and "error" not in cols["pytlidar"]
            and "error" not in cols["biomorph graph"]
        ):
            g, p = cols["biomorph graph"], cols["pytlidar"]
            print(
                f"\nSpeed: pytlidar / biomorph graph = {p['wall'] / g['wall']:.1f}× wall, "
                f"{p['cpu'] / g['cpu']:.1f}× CPU (same run)."
            )
        sys.stdout.flush()


def truth_table(seeds: int, sizes: tuple[int, ...], methods: tuple[str, ...]) -> None:
    """Synthetic truth: total volume, volume per diameter class, length and F1 (issue 13);
    method ``graph+variant``: the graph method with :data:`VARIANT`."""
    import functools

    from biomorph.tree import livny
    from biomorph.tree.metrics import class_labels, compare_to_truth, volume_by_class
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.synthetic import PRESETS, generate_tree, simulate_scan

    conditions = {
        "clean": dict(noise=0.002, occlusion=False, scanners=4),
        "8 mm+occl.": dict(noise=0.008, occlusion=True, scanners=2, leaves=0.05),
    }
    labs = class_labels()
    print(
        f"\n### Against synthetic truth (seeds 0..{seeds - 1}, median over seeds; "
        "ratios to the truth in %)\n"
    )
    print(
        "| preset | condition | points | method | volume | "
        + " | ".join(labs)
        + " | length | length / observed | F1 | s |"
    )
    print("|---|---|---|---|---|" + "---|" * len(labs) + "---|---|---|---|")
    for preset in sorted(PRESETS):
        for cname, kw in conditions.items():
            for n in sizes:
                res: dict[str, list] = {m: [] for m in methods}
                for seed in range(seeds):
                    truth = generate_tree(preset, seed=seed)
                    cloud = simulate_scan(truth, n_points=n, seed=seed, ground=True, **kw)
                    vt = volume_by_class(truth)
                    tv = sum(v["volume"] for v in vt.values())
                    for method in methods:
                        t0 = time.perf_counter()
                        orig = livny.skeletonize_graph
                        if method == "graph+variant":
                            livny.skeletonize_graph = functools.partial(orig, **VARIANT)
                        try:
                            base, mkw = method_options(method)
                            g = skeletonize(cloud, method=base, **mkw).world_graph()
                        except Exception as exc:  # noqa: BLE001 - report and carry on
                            print(f"<!-- {preset} {cname} {n} {method} {seed}: {exc} -->")
                            continue
                        finally:
                            livny.skeletonize_graph = orig
                        dt = time.perf_counter() - t0
                        vc = volume_by_class(g)
                        c = compare_to_truth(g, truth, cloud=cloud)
                        cls = [
                            vc[lab]["volume"] / vt[lab]["volume"]
                            if vt[lab]["volume"] > 1e-6
                            else np.nan
                            for lab in labs
                        ]
                        res[method].append(
                            [
                                sum(v["volume"] for v in vc.values()) / tv,
                                *cls,
                                c["tbl_ratio"],
                                c["tbl_ratio_observed"],
                                c["f1"],
                                dt,
                            ]
                        )
                for method, vals in res.items():
                    if not vals:
                        continue
                    v = np.nanmedian(np.array(vals, dtype=float), axis=0)
                    cells = " | ".join(_fmt(100 * x, "{:.0f}") for x in v[1 : 1 + len(labs)])
                    print(
                        f"| {preset} | {cname} | {n:,} | {method} | {100 * v[0]:.0f} | "
                        f"{cells} | {100 * v[-4]:.0f} | {100 * v[-3]:.0f} | {v[-2]:.3f} | "
                        f"{v[-1]:.1f} |"
                    )
                sys.stdout.flush()
    print(
        "\nTargets: volume ±10 %, each class ±20 %, length ±10 %, F1 ≥ 0.9. "
        "*length / observed*: the model's length over the truth's length that the scan saw "
        "(a point within its radius + 3 cm; `metrics.compare_to_truth`): wood no point "
        "lies on is not in the cloud."
    )


def sparse_twigs(seeds: int, voxel: float = 0.05, variant: bool = False) -> None:
    """Twig recall on sparse scans (issue 13): presets scanned at 60,000 points (5 mm
    noise, occlusion, no leaves), voxel-thinned to one point per ``voxel`` m; twig = truth
    samples of branches under 2.5 cm diameter, recall within 5 cm."""
    from scipy.spatial import cKDTree

    from biomorph.tree.cloud import downsample
    from biomorph.tree.metrics import _interp_radius, compare_to_truth, resample_graph
    from biomorph.tree.neighbours import estimate_spacing
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    print(f"\n### Sparse scans: one point per {voxel * 100:.0f} cm voxel\n")
    print(
        "| preset | seed | variant | points | spacing m | twig recall | recall | F1 "
        "| tips / truth |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    import functools

    from biomorph.tree import livny

    runs = {"default": None}
    if variant:
        runs[", ".join(map(str, VARIANT.values()))] = VARIANT
    for preset in ("birch", "maple"):
        for seed in range(seeds):
            truth = generate_tree(preset, seed=seed)
            scan = simulate_scan(
                truth, n_points=60_000, seed=seed, noise=0.005, ground=False, occlusion=True
            )
            cl = downsample(scan, "voxel", voxel_size=voxel, seed=seed)
            pt, ect, tt = resample_graph(truth, 0.0125)
            twig = _interp_radius(truth, ect, tt) < 0.0125
            for label, kw in runs.items():
                orig = livny.skeletonize_graph
                if kw:
                    livny.skeletonize_graph = functools.partial(orig, **kw)
                try:
                    g = skeletonize(cl, method="graph").world_graph()
                finally:
                    livny.skeletonize_graph = orig
                ps, _, _ = resample_graph(g, 0.0125)
                d, _ = cKDTree(ps).query(pt[twig])
                c = compare_to_truth(g, truth, tolerance=0.05)
                print(
                    f"| {preset} | {seed} | {label} | {cl.n_points:,} | "
                    f"{estimate_spacing(cl.xyz):.3f} | {np.mean(d <= 0.05):.2f} | "
                    f"{c['recall']:.2f} | {c['f1']:.3f} | {g.leaves.size} / {truth.leaves.size} |"
                )
                sys.stdout.flush()


def sparse_volume_table(seeds: int, voxel: float = 0.05) -> None:
    """Wood volume per diameter class on sparse scans (the presets at 60,000 points, 5 mm
    noise, occlusion, voxel-thinned to one point per ``voxel`` m), % of the truth: the
    graph method without run cylinders (``graph-runs``) and by default (with them)."""
    from biomorph.tree.cloud import downsample
    from biomorph.tree.metrics import class_labels, volume_by_class
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.synthetic import PRESETS, generate_tree, simulate_scan

    labs = class_labels()
    print(f"\n### Sparse scans, volume per class: one point per {voxel * 100:.0f} cm voxel\n")
    print("| preset | seed | points | method | volume | " + " | ".join(labs) + " |")
    print("|---|---|---|---|---|" + "---|" * len(labs))
    for preset in sorted(PRESETS):
        for seed in range(seeds):
            truth = generate_tree(preset, seed=seed)
            scan = simulate_scan(
                truth, n_points=60_000, seed=seed, noise=0.005, ground=False, occlusion=True
            )
            cl = downsample(scan, "voxel", voxel_size=voxel, seed=seed)
            vt = volume_by_class(truth)
            tv = sum(v["volume"] for v in vt.values())
            for method in ("graph-runs", "graph"):
                base, kw = method_options(method)
                vc = volume_by_class(skeletonize(cl, method=base, **kw).world_graph())
                cells = " | ".join(f"{100 * vc[k]['volume'] / vt[k]['volume']:.0f}" for k in labs)
                total = 100 * sum(v["volume"] for v in vc.values()) / tv
                print(f"| {preset} | {seed} | {cl.n_points:,} | {method} | {total:.0f} | {cells} |")
                sys.stdout.flush()


def stand_table(seeds: int, methods: tuple[str, ...]) -> None:
    """A plot's crown partition against synthetic truth (issue 13): stands of conifers
    (:func:`~biomorph.tree.synthetic.generate_stand`) scanned once from outside, clean
    (2 mm, 4 scanners) and noisy (8 mm, 3 scanners), both with occlusion. Per run: stems
    found, share of wood points on their true tree (each point takes its nearest skeleton
    node's tree), height error against the tree's highest scanned point (median / worst)
    and the range of trunk length / scanned height."""
    from scipy.spatial import cKDTree

    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.synthetic import generate_stand, simulate_scan

    conditions = {
        "clean": dict(noise=0.002, occlusion=True, scanners=4),
        "8 mm": dict(noise=0.008, occlusion=True, scanners=3),
    }
    print("\n### Plot crown partition against synthetic stands (conifers, one scan)\n")
    print(
        "| trees | points | condition | seed | method | stems | on their tree | "
        "|dh| median / max m | trunk / height | s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n_trees, n_points in ((7, 150_000), (4, 50_000)):
        for cname, kw in conditions.items():
            for seed in range(seeds):
                truth = generate_stand("conifer", n_trees, seed=seed)
                cloud = simulate_scan(truth, n_points=n_points, seed=seed, ground=True, **kw)
                node = cloud.attributes["node"]
                t_true = np.where(node >= 0, truth.tree_id[np.maximum(node, 0)], -1)
                base = truth.position[truth.roots]
                for method in methods:
                    t0 = time.perf_counter()
                    s = skeletonize(cloud, method=method)
                    dt = time.perf_counter() - t0
                    g = s.world_graph()
                    d, j = cKDTree(base[:, :2]).query(g.position[g.roots, :2])
                    match = {
                        int(g.tree_id[r]): int(truth.tree_id[truth.roots][jj]) if dd < 0.5 else -1
                        for r, jj, dd in zip(g.roots, j, d, strict=True)
                    }
                    _, near = cKDTree(g.position).query(cloud.xyz)
                    label = np.array([match.get(int(t), -1) for t in g.tree_id])[near]
                    wood = t_true >= 0
                    dh, ratio = [], []
                    for r in g.roots:
                        t = int(g.tree_id[r])
                        if match[t] < 0:
                            continue
                        top = cloud.xyz[t_true == match[t], 2].max()
                        dh.append(abs(g.position[g.tree_id == t, 2].max() - g.position[r, 2] - top))
                        ratio.append(s.metrics["trees"][t]["trunk_length"] / top)
                    found = len({v for v in match.values() if v >= 0})
                    print(
                        f"| {n_trees} | {n_points:,} | {cname} | {seed} | {method} | "
                        f"{found}/{n_trees} | {np.mean(label[wood] == t_true[wood]):.3f} | "
                        f"{np.median(dh):.2f} / {np.max(dh):.2f} | "
                        f"{min(ratio):.2f}–{max(ratio):.2f} | {dt:.1f} |"
                    )
                    sys.stdout.flush()


#: shares of a real cloud's points kept by :func:`density_table` (random, seed 0)
DENSITY_FRACTIONS = (1.0, 0.5, 0.25)


def density_table(names: tuple[str, ...], methods: tuple[str, ...]) -> None:
    """The same real cloud thinned at random to half and a quarter of its points: how far
    the model moves from the full cloud's (a sparser scan of the same tree, as an MLS or
    UAV scan, or TLS from fewer positions, would give). Volume, length, trunk length and
    the share of the *full* cloud's points > 10 cm from every cylinder, per method; ratios
    to the full-density model, F1@5 cm against the full-density model's skeleton."""
    from biomorph.io import read_points
    from biomorph.tree.metrics import cylinder_fit, tree_attributes
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.reference import compare_to_reference

    if not DATA.is_dir():
        print(f"\n(real data not found at {DATA}; skipped)")
        return
    print("\n### Real clouds thinned at random (seed 0): the model against the full cloud's\n")
    print(
        "| cloud | method | points kept | volume L (× full) | length m (× full) | "
        "trunk m (× full) | trees (fragments) | far % of all points | F1 vs full | s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        cloud = read_points(DATA / name)
        for method in methods:
            full = None
            rng = np.random.default_rng(0)
            for frac in DENSITY_FRACTIONS:
                n = int(round(frac * cloud.n_points))
                keep = np.sort(rng.choice(cloud.n_points, n, replace=False))
                t0 = time.perf_counter()
                try:
                    base, kw = method_options(method)
                    s = skeletonize(cloud.select(keep), method=base, **kw)
                except Exception as exc:  # noqa: BLE001 - reported in the table
                    print(f"| {name} | {method} | {frac:.0%} | {type(exc).__name__}: {exc} |")
                    continue
                dt = time.perf_counter() - t0
                g = s.world_graph()
                attrs = tree_attributes(g)
                row = (
                    sum(a["total_volume"] for a in attrs) * 1e3,
                    sum(a["total_length"] for a in attrs),
                    max(a["trunk_length"] for a in attrs),
                )
                if full is None:
                    full = (row, g)
                cells = [
                    f"{v:.1f} ({v / f:.2f})" if f > 0 else f"{v:.1f}"
                    for v, f in zip(row, full[0], strict=True)
                ]
                f1 = compare_to_reference(g, full[1], tolerance=0.05)["f1"]
                far = 100 * cylinder_fit(g, cloud.xyz)["far_share"]
                trees = f"{s.metrics.get('n_trees')} ({s.metrics.get('n_fragments', 0)})"
                print(
                    f"| {name} | {method} | {frac:.0%} ({n:,}) | "
                    + " | ".join(cells)
                    + f" | {trees} | {far:.1f} | {f1:.3f} | {dt:.1f} |"
                )
                sys.stdout.flush()


def seed_table(
    names: tuple[str, ...], methods: tuple[str, ...], seeds: int, *, jitter: bool = False
) -> None:
    """Repeatability: the same cloud through the same pipeline with ``seeds`` random seeds
    (the RANSAC circle fits draw from it): total volume, trunk length and tips, their
    range and spread ((max - min) / mean).

    ``jitter``: seed 0 every time, but draw ``k > 0`` moves every point at random (uniform,
    seeded ``k``) by :data:`JITTER_SHARE` of the cloud's lattice step, less than the
    resolution the file was stored at: on a grid-snapped scan that breaks its ties between
    equal distances another way, as another tool's rounding may. Then a last column checks
    that the points shuffled and moved by a georeferencing offset (:data:`GEO_OFFSET`)
    give the file's model (volume, tips; exact
    on a cloud stored on a decimal lattice, docs/tree.md session 33)."""
    from biomorph.io import read_points
    from biomorph.tree.cloud import coordinate_lattice
    from biomorph.tree.metrics import tree_attributes
    from biomorph.tree.pipeline import skeletonize

    if not DATA.is_dir():
        print(f"\n(real data not found at {DATA}; skipped)")
        return
    if jitter:
        print(
            f"\n### Repeatability over {seeds} draws of a jitter of ±{JITTER_SHARE:g} of the "
            f"cloud's lattice step (±{JITTER:g} m off a lattice; seed 0)\n"
        )
        print(
            "| cloud | method | jitter m | volume L: range (spread) | trunk m: range (spread) "
            "| tips: range | shuffled + moved: volume L, tips |"
        )
        print("|---|---|---|---|---|---|---|")
    else:
        print(f"\n### Repeatability over random seeds 0..{seeds - 1} (same cloud, same options)\n")
        print(
            "| cloud | method | volume L: range (spread) | trunk m: range (spread) | tips: range |"
        )
        print("|---|---|---|---|---|")

    def span(v: list[float], f: str) -> str:
        return f"{f.format(min(v))}–{f.format(max(v))} ({(max(v) - min(v)) / np.mean(v):.0%})"

    def model(c, method: str, seed: int) -> tuple[float, float, int]:
        base, kw = method_options(method)
        g = skeletonize(c, method=base, seed=seed, **kw).world_graph()
        attrs = tree_attributes(g)
        vol = sum(a["total_volume"] for a in attrs) * 1e3
        return vol, max(a["trunk_length"] for a in attrs), int(g.leaves.size)

    for name in names:
        cloud = read_points(DATA / name)
        step = coordinate_lattice(cloud)
        amp = JITTER_SHARE * float(np.nanmax(step)) if np.isfinite(step).any() else JITTER
        for method in methods:
            runs = []
            for k in range(seeds):
                if jitter:
                    c = cloud
                    if k:
                        rng = np.random.default_rng(k)
                        c = cloud.with_(xyz=cloud.xyz + rng.uniform(-amp, amp, cloud.xyz.shape))
                    runs.append(model(c, method, 0))
                else:
                    runs.append(model(cloud, method, k))
            vol, trunk, tips = (list(v) for v in zip(*runs, strict=True))
            cells = [name, method, span(vol, "{:.1f}"), span(trunk, "{:.2f}")]
            cells.append(f"{min(tips)}–{max(tips)}")
            if jitter:
                other = cloud.select(np.random.default_rng(0).permutation(cloud.n_points))
                v, _, t = model(other.with_(xyz=other.xyz + GEO_OFFSET), method, 0)
                same = "same" if t == tips[0] and abs(v - vol[0]) <= 1e-9 * vol[0] else "differs"
                cells.insert(2, f"{amp:g}")
                cells.append(f"{v:.1f}, {t} ({same})")
            print("| " + " | ".join(cells) + " |")
            sys.stdout.flush()


#: the jitter of :func:`seed_table`: this share of the cloud's lattice step (its coarsest
#: axis's; :func:`~biomorph.tree.cloud.coordinate_lattice`) -- below the resolution the
#: file was stored at, but no longer on its lattice, so ties between equal distances break
#: by the jitter (a jitter the lattice rounds away changes nothing) ...
JITTER_SHARE = 0.1
#: ... and off any lattice this many metres, far below any scanner's precision
JITTER = 1e-5
#: a georeferencing offset (m; UTM-like easting, northing, height)
GEO_OFFSET = np.array([512345.678, 5401234.567, 300.0])


def _radius_error(v: NDArray, r: float) -> str:
    """Median (IQR) of the relative radius error, %."""
    e = 100 * (np.asarray(v) / r - 1)
    if e.size == 0:
        return "—"
    q1, q2, q3 = np.percentile(e, [25, 50, 75])
    return f"{q2:+.0f} ({q1:+.0f}…{q3:+.0f})"


def _run_sections(r: float, noise: float, half: bool, npts: int, rng) -> tuple:
    """One synthetic run: ``npts`` points on a 10-radius piece of a cylinder of radius ``r``
    along x (the half facing a scanner on +z, or all of it), Gaussian range noise along z;
    the start guess as a one-sided skeleton gives it: 0.6 r towards the viewer, the axis
    tilted 5°, the radius twice the truth."""
    s = rng.uniform(0.0, 10 * r, npts)
    th = rng.uniform(0.0, np.pi if half else 2 * np.pi, npts)
    pts = np.column_stack([s, r * np.cos(th), r * np.sin(th)])
    pts[:, 2] += rng.normal(0.0, noise, npts)
    mid = np.array([5 * r, 0.0, 0.6 * r])
    tilt = np.radians(5.0)
    a0 = np.array([np.cos(tilt), 0.0, np.sin(tilt)])
    return pts, mid, a0, 2 * r


def run_cylinder_table(trials: int = 200) -> None:
    """Cylinders fitted to runs of points (tree/run_cylinders.py, ``--run-cylinders``)
    against pytlidar's TreeQSM least-squares cylinder on the same synthetic runs, same
    start guess: radius error, and the share our quality tests keep."""
    from biomorph.tree import radius as rd
    from biomorph.tree import run_cylinders as rc

    try:
        from PyTLidar.TreeQSMSteps.LSF import least_squares_cylinder
    except ImportError:  # pragma: no cover - the peers extra is missing
        least_squares_cylinder = None
    print(
        f"\n### Run cylinders vs pytlidar's least-squares cylinder ({trials} runs per row, "
        "same points and start; radius error median (IQR) %)\n"
    )
    print(
        "| radius mm | range noise mm | seen | points | ours | ours kept (share) | "
        "pytlidar | time pytlidar / ours |"
    )
    print("|---|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(0)
    # the kernel compiled (or loaded from numba's cache) before any timing
    p, m, a, r0 = _run_sections(0.01, 0.001, True, 12, rng)
    rc.fit_run_cylinders(p, np.array([0, 12]), np.arange(12), m[None], a[None], np.array([r0]))
    for r, noise, half, npts in (
        (0.004, 0.001, True, 24),
        (0.01, 0.001, True, 12),
        (0.01, 0.001, True, 48),
        (0.01, 0.002, False, 24),
        (0.01, 0.004, True, 48),
        (0.025, 0.002, True, 24),
        (0.025, 0.008, True, 48),
    ):
        runs = [_run_sections(r, noise, half, npts, rng) for _ in range(trials)]
        xyz = np.vstack([p for p, *_ in runs])
        indptr = np.arange(trials + 1, dtype=np.int64) * npts
        t0 = time.perf_counter()
        fits = rc.fit_run_cylinders(
            xyz,
            indptr,
            np.arange(xyz.shape[0]),
            np.array([m for _, m, _, _ in runs]),
            np.array([a for _, _, a, _ in runs]),
            np.array([r0 for *_, r0 in runs]),
        )
        t_ours = time.perf_counter() - t0
        kept = fits.usable(rd.RELIABLE_COVERAGE)
        fitted = fits.radius

        peer, t_peer = "—", float("nan")
        if least_squares_cylinder is not None:
            t0 = time.perf_counter()
            pr = []
            for p, m, a, r0 in runs:
                c = least_squares_cylinder(p, {"axis": a, "start": m - 5 * r * a, "radius": r0})
                pr.append(abs(c["radius"]))
            t_peer = time.perf_counter() - t0
            peer = _radius_error(pr, r)
        print(
            f"| {1e3 * r:.0f} | {1e3 * noise:.0f} | {'half' if half else 'all'} | {npts} | "
            f"{_radius_error(fitted[fitted > 0], r)} | "
            f"{_radius_error(fitted[kept], r)} ({kept.mean():.0%}) | "
            f"{peer} | {t_peer / t_ours:.0f}× |"
        )
        sys.stdout.flush()


def run_twig_table(names: tuple[str, ...]) -> None:
    """On the real clouds: what the run cylinders change on the twigs they measure
    (median, mm) beside the twig offset's looks at every modelled twig (first … last, the
    applied offset and the scan's noise bias), the volume and the < 2.5 cm class's
    surface residual without and with run cylinders (the graph method's default, opt-in
    for voxel)."""
    from biomorph.io import read_points
    from biomorph.tree.pipeline import skeletonize

    if not DATA.is_dir():
        print(f"\n(real data not found at {DATA}; skipped)")
        return
    print("\n### Run cylinders on real twigs beside the twig offset\n")
    print(
        "| cloud | method | run nodes | twig nodes | runs − model on twigs mm | "
        "twig looks mm first … last (applied; noise bias) | volume L no runs → runs | "
        "residual < 2.5 cm no runs → runs |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in names:
        cloud = read_points(DATA / name)
        for method in ("graph", "voxel"):
            on = skeletonize(cloud, method=method, run_cylinders=True)
            off = skeletonize(cloud, method=method, run_cylinders=False)
            rc = on.info.get("run_cylinders") or {}
            tw = (on.info.get("twig_offset") or {}).get(0, {})
            lk = tw.get("looks", [])
            looks = f"{1e3 * lk[0]:.2f} … {1e3 * lk[-1]:.2f}" if lk else "–"
            shift = rc.get("twig_shift")
            vol = [sum(t["total_volume"] for t in s.metrics["trees"]) * 1e3 for s in (off, on)]
            res = [s.metrics["fit"]["classes"]["<2.5cm"]["residual"] for s in (off, on)]
            print(
                f"| {name} | {method} | {rc.get('nodes', 0)} | {rc.get('twig_nodes', 0)} | "
                f"{_fmt(None if shift is None else 1e3 * shift, '{:+.2f}')} | {looks} "
                f"({1e3 * tw.get('offset', 0.0):.2f}; {1e3 * tw.get('bias', 0.0):.2f}) | "
                f"{vol[0]:.1f} → {vol[1]:.1f} | {res[0]:+.3f} → {res[1]:+.3f} |"
            )
            sys.stdout.flush()


def _models_summary(cloud, n: int, method: str) -> tuple:
    """Model 0 and the chosen one of :func:`~biomorph.tree.models.reconstruct_models`
    (world graphs), its stats and the CPU seconds."""
    from biomorph.tree.models import reconstruct_models
    from biomorph.tree.options import SkeletonizeOptions

    c0 = time.process_time()
    m = reconstruct_models(cloud, n, options=SkeletonizeOptions(method=method))
    cpu = time.process_time() - c0
    st = m.skeleton.info["models"]
    return m, st, cpu


def models_table(
    seeds: int, sizes: tuple[int, ...], n: int, names: tuple[str, ...], methods: tuple[str, ...]
) -> None:
    """Several models per cloud (:mod:`biomorph.tree.models`): model 0 (the default run)
    against the model nearest to the points, the volume's spread over the models; on the
    synthetic presets against the truth, on the real clouds against their references."""
    from biomorph.io import read_points
    from biomorph.tree.metrics import compare_to_truth, tree_attributes, volume_by_class
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.reference import compare_to_reference
    from biomorph.tree.synthetic import PRESETS, generate_tree, simulate_scan

    conditions = {
        "clean": dict(noise=0.002, occlusion=False, scanners=4),
        "8 mm+occl.": dict(noise=0.008, occlusion=True, scanners=2, leaves=0.05),
    }
    print(f"\n### {n} models per cloud: model 0 (default) vs the nearest to the points\n")
    print(
        "| preset | condition | points | seed | method | volume % model 0 → chosen (scale) | "
        "models: mean ± sd (min–max) % | length % | trunk % model 0 → chosen | "
        "classes ±20 % model 0 → chosen | F1 model 0 → chosen | cpu ÷ model 0's s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for preset in sorted(PRESETS):
        for cname, kw in conditions.items():
            for size in sizes:
                for seed in range(seeds):
                    truth = generate_tree(preset, seed=seed)
                    cloud = simulate_scan(truth, n_points=size, seed=seed, ground=True, **kw)
                    vt = volume_by_class(truth)
                    tv = sum(v["volume"] for v in vt.values())
                    tt = max(a["trunk_length"] for a in tree_attributes(truth))
                    for method in methods:
                        m, st, cpu = _models_summary(cloud, n, method)
                        r0, rb = m.runs[0], m.runs[m.best]
                        cb = compare_to_truth(m.skeleton.world_graph(), truth)
                        # model 0's F1 needs its graph: the same run again only if it
                        # was not the one kept
                        f0 = (
                            cb["f1"]
                            if m.best == 0
                            else compare_to_truth(
                                skeletonize(cloud, method=method).world_graph(), truth
                            )["f1"]
                        )
                        v = st["volume_L"]

                        def within(r, vt=vt) -> str:
                            ok = [
                                abs(r.classes[k] / c["volume"] - 1) <= 0.2
                                for k, c in vt.items()
                                if c["volume"] > 1e-6
                            ]
                            return f"{sum(ok)}/{len(ok)}"

                        print(
                            f"| {preset} | {cname} | {size:,} | {seed} | {method} | "
                            f"{100 * r0.volume / tv:.0f} → {100 * rb.volume / tv:.0f} "
                            f"({rb.scale:.3g}) | {v['mean'] / 10 / tv:.0f} ± "
                            f"{v['sd'] / 10 / tv:.0f} ({v['min'] / 10 / tv:.0f}–"
                            f"{v['max'] / 10 / tv:.0f}) | {100 * cb['tbl_ratio']:.0f} | "
                            f"{100 * r0.trunk_length / tt:.0f} → "
                            f"{100 * rb.trunk_length / tt:.0f} | "
                            f"{within(r0)} → {within(rb)} | {f0:.3f} → {cb['f1']:.3f} | "
                            f"{cpu / max(r0.seconds, 1e-9):.1f} |"
                        )
                        sys.stdout.flush()
    if not DATA.is_dir():
        print(f"\n(real data not found at {DATA}; skipped)")
        return
    print(f"\n### {n} models per real cloud\n")
    print(
        "| cloud | method | volume L model 0 → chosen (scale) | "
        "models: mean ± sd (min–max) L, CV | trunk m model 0 → chosen | "
        "distance mm model 0 → chosen | F1 vs references |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in names:
        cloud = read_points(DATA / name)
        refs = reference_models(name, cloud.xyz)
        for method in methods:
            m, st, _ = _models_summary(cloud, n, method)
            r0, rb = m.runs[0], m.runs[m.best]
            g = m.skeleton.world_graph()
            v = st["volume_L"]
            f1 = ", ".join(
                f"{k} {compare_to_reference(g, ref, tolerance=0.05)['f1']:.3f}"
                for k, ref in refs.items()
            )
            print(
                f"| {name} | {method} | {1e3 * r0.volume:.1f} → {1e3 * rb.volume:.1f} "
                f"({rb.scale:.3g}) | {v['mean']:.1f} ± {v['sd']:.1f} ({v['min']:.1f}–"
                f"{v['max']:.1f}), {100 * v['cv']:.1f} % | {r0.trunk_length:.2f} → "
                f"{rb.trunk_length:.2f} | {1e3 * r0.distance:.2f} → {1e3 * rb.distance:.2f} | "
                f"{f1 or '—'} |"
            )
            sys.stdout.flush()


def twig_noise_table(seeds: int, n: int) -> None:
    """What the twig offset's noise model (:func:`biomorph.tree.radius._noise_median`)
    predicts an exact twig model would read, beside what the scan's points read about the
    truth itself (session 23): the synthetic presets, clean and at 8 mm range noise."""
    from scipy.spatial import cKDTree

    from biomorph.tree.metrics import resample_graph, surface_distance
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.radius import _noise_median
    from biomorph.tree.synthetic import PRESETS, generate_tree, simulate_scan

    conditions = {
        "clean": dict(noise=0.002, occlusion=False, scanners=4),
        "8 mm+occl.": dict(noise=0.008, occlusion=True, scanners=2, leaves=0.05),
    }
    bins = ((0.003, 0.005), (0.005, 0.0075), (0.0075, 0.0125))
    print(
        f"\n### The twig look about the exact truth vs the noise model ({n:,} points; "
        "median signed distance of the points within one radius of the truth's surface, mm; "
        "predicted at the scan's measured scatter; the model's radius over the truth's at "
        "the model's nodes within 3 cm of a true axis, same bins)\n"
    )
    head = " | ".join(f"r {1e3 * a:g}-{1e3 * b:g} mm read / predicted" for a, b in bins)
    print(
        f"| preset | condition | seed | scatter mm | {head} | applied offset mm | model / true r |"
    )
    print("|---|---|---|---|" + "---|" * len(bins) + "---|---|")
    for preset in sorted(PRESETS):
        for cname, kw in conditions.items():
            for seed in range(seeds):
                truth = generate_tree(preset, seed=seed)
                cloud = simulate_scan(truth, n_points=n, seed=seed, ground=True, **kw)
                run = skeletonize(cloud, method="graph")
                info = run.info.get("twig_offset", {})
                noise = max((v["noise"] for v in info.values()), default=0.0)
                offset = sum(v["offset"] for v in info.values())
                drop = np.zeros(cloud.n_points, bool)
                for name in ("is_leaf", "is_ground"):
                    if name in cloud.attributes:
                        drop |= np.asarray(cloud.attributes[name], bool)
                sd, rd, _ = surface_distance(truth, cloud.xyz[~drop])
                cells = []
                for a, b in bins:
                    sel = (np.abs(sd) <= rd) & (rd >= a) & (rd < b)
                    if sel.sum() < 30:
                        cells.append("–")
                        continue
                    read = 1e3 * float(np.median(sd[sel]))
                    cells.append(f"{read:+.2f} / {1e3 * _noise_median(rd[sel], noise):+.2f}")
                # what the model made of them: its radius over the truth's, per bin
                g = run.world_graph()
                tp, tch, tt = resample_graph(truth, 0.005)
                tr = (1 - tt) * truth.radius[truth.parent[tch]] + tt * truth.radius[tch]
                d, j = cKDTree(tp).query(g.position)
                ratios = []
                for a, b in bins:
                    m = (d < 0.03) & (tr[j] >= a) & (tr[j] < b)
                    ratios.append(f"{np.median(g.radius[m] / tr[j[m]]):.2f}" if m.any() else "–")
                print(
                    f"| {preset} | {cname} | {seed} | {1e3 * noise:.2f} | "
                    + " | ".join(cells)
                    + f" | {1e3 * offset:+.2f} | {' / '.join(ratios)} |"
                )
                sys.stdout.flush()


def single_scan_table(seeds: int, n: int, methods: tuple[str, ...]) -> None:
    """The presets scanned from one position (3 mm noise, occlusion; a single-scan plot
    protocol, or one side of a stem behind its neighbours): volume and classes against
    the truth, length, F1, and the DBH error of the taper model (``DBHqsm``) and of the
    stem's circles at 1.0-1.6 m (``DBHcyl``, :func:`biomorph.tree.radius.
    breast_height_fits`), median and worst over the seeds (session 30)."""
    from biomorph.tree.metrics import class_labels, compare_to_truth, dbh, volume_by_class
    from biomorph.tree.pipeline import skeletonize
    from biomorph.tree.synthetic import PRESETS, generate_tree, simulate_scan

    labs = class_labels()
    print(f"\n### Scanned from one position ({n:,} points, seeds 0..{seeds - 1}; % of the truth)\n")
    print(
        "| preset | method | volume (range) | "
        + " | ".join(labs)
        + " | length | F1 | DBH model: median (worst) | DBH circles: median (worst) |"
    )
    print("|---|---|---|" + "---|" * len(labs) + "---|---|---|---|")
    for preset in sorted(PRESETS):
        for method in methods:
            rows = []
            for seed in range(seeds):
                truth = generate_tree(preset, seed=seed)
                cloud = simulate_scan(
                    truth, n_points=n, seed=seed, noise=0.003, occlusion=True, scanners=1
                )
                vt = volume_by_class(truth)
                base, kw = method_options(method)
                skel = skeletonize(cloud, method=base, **kw)
                g = skel.world_graph()
                vc = volume_by_class(g)
                c = compare_to_truth(g, truth, cloud=cloud)
                d = dbh(truth)
                fit = skel.metrics["trees"][0].get("dbh_fit")
                rows.append(
                    [
                        sum(v["volume"] for v in vc.values())
                        / sum(v["volume"] for v in vt.values()),
                        *[
                            vc[k]["volume"] / vt[k]["volume"] if vt[k]["volume"] > 1e-6 else np.nan
                            for k in labs
                        ],
                        c["tbl_ratio"],
                        c["f1"],
                        dbh(g) / d - 1,
                        (fit if fit is not None else np.nan) / d - 1,
                    ]
                )
            a = np.array(rows, dtype=float)
            med = np.nanmedian(a, axis=0)

            def worst(col: NDArray) -> float:
                col = col[np.isfinite(col)]
                return float(col[np.argmax(np.abs(col))]) if col.size else np.nan

            cells = " | ".join(_fmt(100 * x, "{:.0f}") for x in med[1 : 1 + len(labs)])
            print(
                f"| {preset} | {method} | {100 * med[0]:.0f} ({100 * a[:, 0].min():.0f}-"
                f"{100 * a[:, 0].max():.0f}) | {cells} | {100 * med[-4]:.0f} | {med[-3]:.3f} | "
                f"{100 * med[-2]:+.1f} ({100 * worst(a[:, -2]):+.1f}) | "
                f"{100 * med[-1]:+.1f} ({100 * worst(a[:, -1]):+.1f}) |"
            )
            sys.stdout.flush()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="also time 1,000,000 points")
    ap.add_argument(
        "--only",
        choices=(
            "speed",
            "accuracy",
            "real",
            "peers",
            "truth",
            "sparse",
            "stand",
            "density",
            "seeds",
            "jitter",
            "runs",
            "models",
            "twignoise",
            "single",
        ),
    )
    ap.add_argument(
        "--clouds",
        nargs="*",
        default=list(PEER_CLOUDS),
        help="real clouds of the peer table (names in ../shared/data/trees)",
    )
    ap.add_argument("--no-pytlidar", action="store_true", help="peer table without pytlidar")
    ap.add_argument(
        "--variant",
        action="store_true",
        help="peers/sparse: also the graph variant VARIANT (adaptive level merge)",
    )
    ap.add_argument(
        "--fine",
        action="store_true",
        help=f"peers: also the graph method with --residual-threshold {FINE_RESIDUAL} "
        "(column graph+fine)",
    )
    ap.add_argument(
        "--coarse",
        action="store_true",
        help="peers: also the graph method with --residual-threshold 1, the fixed default "
        "before session 29 (column graph+coarse)",
    )
    ap.add_argument(
        "--runs",
        action="store_true",
        help="peers: also the graph method without run cylinders (column graph-runs)",
    )
    ap.add_argument(
        "--sizes",
        type=int,
        nargs="*",
        default=[60_000, 240_000],
        help="points per synthetic scan of the truth table",
    )
    ap.add_argument(
        "--methods",
        nargs="*",
        default=["graph", "voxel"],
        help="graph, voxel, graph+variant (truth), graph-runs / voxel-runs (--no-run-cylinders), "
        "graph-limbs / voxel-limbs (--no-reversed-limbs), graph+fine / voxel+fine "
        f"(--residual-threshold {FINE_RESIDUAL}), graph+coarse / voxel+coarse "
        "(--residual-threshold 1)",
    )
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument(
        "--models", type=int, default=5, help="models per cloud (--only models, --with-models)"
    )
    ap.add_argument(
        "--with-models",
        action="store_true",
        help="peers: also the graph method's chosen model of --models (column 'graph, N models')",
    )
    ap.add_argument("--points", type=int, default=60_000, help="points per synthetic scan")
    ap.add_argument(
        "--tip-support",
        type=float,
        default=None,
        help="graph method: prune weakly supported tip chains (e.g. 0.3)",
    )
    ap.add_argument(
        "--lof",
        action="store_true",
        help="outlier removal keeps points as sparse as their neighbours (cloud.LOCAL_RATIO=2)",
    )
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.lof:
        from biomorph.tree import cloud as tcloud

        tcloud.LOCAL_RATIO = 2.0
    if a.one:
        print(json.dumps(one_timing(a.one)))
        return
    print("## biomorph tree benchmark")
    if a.only in (None, "speed"):
        speed(a.full)
    if a.only in (None, "accuracy"):
        accuracy(a.seeds, a.points, a.tip_support)
    if a.only in (None, "real"):
        real()
    if a.only in (None, "peers"):
        peers(
            tuple(a.clouds),
            not a.no_pytlidar,
            a.variant,
            a.runs,
            a.models if a.with_models else 0,
            a.fine,
            a.coarse,
        )
    if a.only in (None, "truth"):
        truth_table(a.seeds, tuple(a.sizes), tuple(a.methods))
    if a.only in (None, "sparse"):
        sparse_twigs(a.seeds, variant=a.variant)
        sparse_volume_table(a.seeds)
    if a.only in (None, "stand"):
        stand_table(a.seeds, tuple(a.methods))
    if a.only in (None, "density"):
        density_table(tuple(a.clouds), tuple(a.methods))
    if a.only in (None, "seeds"):
        seed_table(tuple(a.clouds), tuple(a.methods), max(a.seeds, 4))
    if a.only == "jitter":
        seed_table(tuple(a.clouds), tuple(a.methods), max(a.seeds, 4), jitter=True)
    if a.only in (None, "runs"):
        run_cylinder_table()
        run_twig_table(tuple(a.clouds))
    if a.only in (None, "models"):
        models_table(a.seeds, tuple(a.sizes), a.models, tuple(a.clouds), tuple(a.methods))
    _opt_in_tables(a)


def _opt_in_tables(a: argparse.Namespace) -> None:
    """The tables only ``--only`` runs."""
    if a.only == "twignoise":
        twig_noise_table(a.seeds, a.points)
    if a.only == "single":
        single_scan_table(max(a.seeds, 4), a.points, tuple(a.methods))


if __name__ == "__main__":
    main()
