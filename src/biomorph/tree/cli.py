"""``biomorph tree …``: skeletonise clouds, synthesise test trees, evaluate, batch-process.

Angles are degrees on the command line (radians inside). Every command computes first and
writes only at the end (each file atomically), so bad input exits with code 2 and one line
on stderr without leaving partial output.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from biomorph.errors import ParameterError

app = typer.Typer(name="tree", no_args_is_help=True, add_completion=False,
                  pretty_exceptions_enable=False,
                  help="Tree skeletons from LiDAR point clouds (graph and voxel methods).")

Method = Annotated[str, typer.Option("--method", "-m", help="graph (Livny) or voxel (Gorte).")]


def _print_table(title: str, rows: list[tuple[str, Any]]) -> None:
    from rich.table import Table

    from biomorph._cli import out_console

    table = Table(title=title, show_header=False)
    for k, v in rows:
        if isinstance(v, float):
            v = f"{v:.4g}"
        table.add_row(str(k), str(v))
    out_console.print(table)


def _parse_filter(spec: str | None) -> dict | None:
    if spec is None:
        return None
    parts = spec.split(":")
    if len(parts) not in (2, 3):
        raise ParameterError(f"--filter {spec!r}: expected NAME:MAX or NAME:MIN:MAX")
    try:
        if len(parts) == 2:
            return {"name": parts[0], "max_value": float(parts[1])}
        lo = float(parts[1]) if parts[1] else None
        hi = float(parts[2]) if parts[2] else None
        return {"name": parts[0], "min_value": lo, "max_value": hi}
    except ValueError:
        raise ParameterError(f"--filter {spec!r}: bounds must be numbers") from None


def _skeleton_kwargs(method: str, n_trees: int | None, node_spacing: float | None, k: int,
                     max_iter: int, cell_size: float | None, ground: bool, outliers: bool,
                     downsample: float | None, filter_spec: str | None, radius: str,
                     recentre: bool, order_angle: float, order_share: float, seed: int,
                     clutter: float | None = None, foliage: float | None = None,
                     edge_weights: str = "livny", tip_support: float | None = None,
                     ) -> dict[str, Any]:
    if order_angle <= 0 or order_angle > 180:
        raise ParameterError(f"--order-angle must lie in (0, 180] degrees, got {order_angle}")
    if downsample is not None and not 0 < downsample <= 1:
        raise ParameterError(f"--downsample must be a ratio in (0, 1], got {downsample}")
    if foliage is not None and foliage != 0 and not foliage > 1:
        raise ParameterError(f"--foliage must be 0 (off) or a factor > 1, got {foliage}")
    if tip_support is not None and not 0 < tip_support < 1:
        raise ParameterError(f"--tip-support must lie in (0, 1) (a share of the median points "
                             f"per node of the tip chains), got {tip_support}")
    kw: dict[str, Any] = dict(method=method, n_trees=n_trees, node_spacing=node_spacing, k=k,
                              max_iter=max_iter, ground="auto" if ground else None,
                              outliers=outliers, downsample=downsample,
                              filter=_parse_filter(filter_spec), radius=radius,
                              recentre=recentre, order_angle=float(np.radians(order_angle)),
                              order_share=order_share, seed=seed, sparse_filter=clutter,
                              foliage="auto" if foliage is None else (foliage or None),
                              edge_weights=edge_weights, tip_support=tip_support)
    if cell_size is not None:
        kw["voxel"] = {"cell_size": cell_size}
    return kw


@app.command()
def skeletonize(
    cloud: Annotated[Path, typer.Argument(help="Point cloud: .las .laz .ply .xyz .txt .csv .npy")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("tree-out"),
    method: Method = "graph",
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
    n_trees: Annotated[int | None, typer.Option(help="Number of trees (default: found "
                                                     "automatically).")] = None,
    node_spacing: Annotated[float | None, typer.Option(help="Skeleton node spacing, m "
                                                            "(default from the data).")] = None,
    k: Annotated[int, typer.Option(help="Neighbours per point (graph method).")] = 10,
    max_iter: Annotated[int, typer.Option(help="Re-weighting iterations cap.")] = 5,
    cell_size: Annotated[float | None, typer.Option(help="Voxel size, m (voxel method).")] = None,
    ground: Annotated[bool, typer.Option(help="Remove the ground when detected.")] = True,
    outliers: Annotated[bool, typer.Option(help="Statistical outlier removal.")] = True,
    downsample: Annotated[float | None, typer.Option(help="Random downsampling ratio.")] = None,
    filter_spec: Annotated[str | None, typer.Option("--filter", help="Keep points with "
                                                    "attribute NAME <= MAX (NAME:MAX).")] = None,
    radius: Annotated[str, typer.Option(help="fit (RANSAC circles) or allometric.")] = "fit",
    recentre: Annotated[bool, typer.Option(help="Move nodes to fitted stem centres.")] = True,
    order_angle: Annotated[float, typer.Option(help="Branch-order angle, degrees.")] = 45.0,
    order_share: Annotated[float, typer.Option(help="Branch-order weight share.")] = 0.5,
    world: Annotated[bool, typer.Option(help="Write original (e.g. georeferenced) "
                                             "coordinates.")] = True,
    clutter: Annotated[float | None, typer.Option(help="Drop sparse points (leaf clutter): "
                                                       "mean 16-NN distance > CLUTTER x "
                                                       "median, e.g. 4.")] = None,
    foliage: Annotated[float | None, typer.Option(help="Leaf/wood separation: drop points "
                                                       "whose neighbourhood is thicker than "
                                                       "FOLIAGE x the median; 0 = off "
                                                       "[default: 3 (graph), off (voxel)].")
                       ] = None,
    edge_weights: Annotated[str, typer.Option(help="Weights of Livny steps iv-v: livny (the "
                                                   "paper's) or branch.")] = "livny",
    tip_support: Annotated[float | None, typer.Option(help="Prune short tip chains with fewer "
                                                           "points per node than TIP_SUPPORT x "
                                                           "the median tip chain, e.g. 0.3 "
                                                           "for dense leafy scans (graph).")
                           ] = None,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """Skeletonise a tree cloud and write skeleton.ply/.mtg, tube.glb/.obj, cylinders.csv,
    summary.json and preview.png into OUT.

    Example: biomorph tree skeletonize scan.laz --method graph --out out/ --json
    """
    from biomorph.tree.export import export_skeleton
    from biomorph.tree.pipeline import skeletonize as run

    kw = _skeleton_kwargs(method, n_trees, node_spacing, k, max_iter, cell_size, ground,
                          outliers, downsample, filter_spec, radius, recentre, order_angle,
                          order_share, seed, clutter, foliage, edge_weights,
                          tip_support)
    skel = run(cloud, **kw)
    files = export_skeleton(skel, out, world=world, title=f"{cloud.name} ({method})")
    summary = skel.summary()
    summary["files"] = {k_: str(v) for k_, v in files.items()}
    if as_json:
        from biomorph._cli import print_json

        print_json(summary)
        return
    m = skel.metrics
    _print_table(f"{cloud.name}: {method} skeleton", [
        ("points", skel.info.get("points")), ("trees", m.get("n_trees")),
        ("nodes", m.get("n_nodes")), ("NOB (tips)", m.get("nob")), ("TBL (m)", m.get("tbl")),
        ("MSE (m²)", m.get("mse")), ("max order", m.get("max_order")),
        ("trunk radius (m)", ", ".join(f"{r:.3f}" for r in m.get("trunk_radius", []))),
        ("seconds", skel.timings.get("total")), ("output", str(out))])


@app.command()
def synth(
    preset: Annotated[str, typer.Option(help="maple, birch, aspen or conifer.")] = "maple",
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("synth-out"),
    points: Annotated[int, typer.Option(help="Number of scan points.")] = 50000,
    noise: Annotated[float, typer.Option(help="Range noise std, m.")] = 0.003,
    scanners: Annotated[int, typer.Option(help="Scanner positions.")] = 3,
    leaves: Annotated[float, typer.Option(help="Fraction of leaf clutter points.")] = 0.0,
    ground: Annotated[bool, typer.Option(help="Add a ground plane.")] = True,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Synthesise a tree with ground truth and a simulated scan: OUT/truth.ply, truth.mtg,
    cloud.ply (attributes is_ground, is_leaf, node) and preview.png.

    Example: biomorph tree synth --preset birch --points 100000 --noise 0.005 --out birch/
    """
    from biomorph.io import write_graph, write_points
    from biomorph.io.atomic import atomic_path
    from biomorph.render import render_graph
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    truth = generate_tree(preset, seed=seed)
    cloud = simulate_scan(truth, n_points=points, noise=noise, scanners=scanners,
                          leaves=leaves, ground=ground, seed=seed)
    out.mkdir(parents=True, exist_ok=True)
    files = {"truth": write_graph(out / "truth.ply", truth),
             "truth_mtg": write_graph(out / "truth.mtg", truth),
             "cloud": write_points(out / "cloud.ply", cloud)}
    with atomic_path(out / "preview.png") as tmp:
        render_graph(truth, tmp, cloud=cloud, title=f"synthetic {preset} (seed {seed})")
    files["preview"] = out / "preview.png"
    summary = {"preset": preset, "seed": seed, "points": cloud.n_points,
               "nob": int(truth.leaves.size), "tbl": truth.total_length,
               "base_radius": float(truth.radius[truth.roots[0]]),
               "files": {k_: str(v) for k_, v in files.items()}}
    if as_json:
        from biomorph._cli import print_json

        print_json(summary)
        return
    _print_table(f"synthetic {preset}", [(k_, v) for k_, v in summary.items() if k_ != "files"])


@app.command()
def evaluate(
    skeleton: Annotated[Path, typer.Argument(help="Skeleton .ply or .mtg.")],
    truth: Annotated[Path | None, typer.Option(help="Ground-truth skeleton .ply/.mtg.")] = None,
    cloud: Annotated[Path | None, typer.Option(help="Point cloud for the MSE (and, with "
                                                    "--truth, the observed-truth "
                                                    "measures).")] = None,
    tolerance: Annotated[float | None, typer.Option(help="Match tolerance, m.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """NOB, TBL, MSE of a skeleton; with --truth also precision/recall/F1, NOB/TBL ratios,
    radius error, DBH and volume error.

    Example: biomorph tree evaluate out/skeleton.ply --truth synth/truth.ply --json
    """
    from biomorph.io import read_graph, read_points
    from biomorph.tree.metrics import compare_to_truth, skeleton_metrics
    from biomorph.tree.pipeline import _jsonable

    g = read_graph(skeleton)
    pc = read_points(cloud) if cloud is not None else None
    res: dict[str, Any] = {"skeleton": str(skeleton), **skeleton_metrics(g, pc)}
    if truth is not None:
        res["truth"] = str(truth)
        res["comparison"] = compare_to_truth(g, read_graph(truth), tolerance, cloud=pc)
    res = _jsonable(res)
    if as_json:
        from biomorph._cli import print_json

        print_json(res)
        return
    rows = [(k_, v) for k_, v in res.items() if not isinstance(v, (dict, list))]
    rows += [(f"truth {k_}", v) for k_, v in res.get("comparison", {}).items()]
    _print_table(f"{skeleton.name}", rows)


def batch_item(item: tuple[str, str, dict[str, Any], bool]) -> dict[str, Any]:
    """Skeletonise one cloud into ``out/<stem>/`` (module level: picklable for dask)."""
    from biomorph.tree.export import export_skeleton
    from biomorph.tree.pipeline import skeletonize as run

    path, out, kw, world = item
    skel = run(path, **kw)
    export_skeleton(skel, out, world=world, title=Path(path).name)
    m = skel.metrics
    return {"nob": m.get("nob"), "tbl": m.get("tbl"), "trees": m.get("n_trees"),
            "seconds": skel.timings.get("total")}


@app.command()
def batch(
    inputs: Annotated[list[Path], typer.Argument(help="Point cloud files.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder (one sub-folder "
                                                          "per input).")] = Path("batch-out"),
    method: Method = "graph",
    workers: Annotated[int | None, typer.Option(help="Worker processes (0 = serial).")] = None,
    scheduler: Annotated[str | None, typer.Option(help="Address of a running dask "
                                                       "scheduler.")] = None,
    ground: Annotated[bool, typer.Option(help="Remove the ground when detected.")] = True,
    node_spacing: Annotated[float | None, typer.Option(help="Node spacing, m.")] = None,
    world: Annotated[bool, typer.Option(help="Write original coordinates.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print the batch report as JSON.")
                       ] = False,
) -> None:
    """Skeletonise many clouds in parallel on dask.distributed (LocalCluster by default).

    Failed inputs are reported without stopping the others; inputs whose summary.json
    exists are skipped, so a re-run resumes. Exit code 1 if any input failed.

    Example: biomorph tree batch plots/*.laz --out results/ --workers 4
    """
    from biomorph.scale.batch import run_batch

    if not inputs:
        raise ParameterError("no input files given")
    stems = [p.stem for p in inputs]
    if len(set(stems)) != len(stems):
        raise ParameterError("input file names must be unique (outputs go to OUT/<name>/)")
    kw = {"method": method, "ground": "auto" if ground else None,
          "node_spacing": node_spacing}
    items = [(str(p), str(out / p.stem), kw, world) for p in inputs]
    report = run_batch(items, batch_item, out_dir=out, key=lambda it: Path(it[0]).stem,
                       done=lambda it: (Path(it[1]) / "summary.json").exists(),
                       workers=workers, scheduler=scheduler, description="trees")
    if as_json:
        from biomorph._cli import print_json

        data = report.to_dict()
        data["results"] = report.results
        print_json(data)
    else:
        from biomorph._cli import err_console, out_console

        out_console.print(report.summary())
        for key, msg in report.failed:
            err_console.print(f"failed: {key}: {msg}")
    if report.exit_code:
        raise typer.Exit(report.exit_code)
