"""``biomorph tree …``: skeletonise clouds, synthesise test trees, evaluate, batch-process.

Angles are degrees on the command line (radians inside). Every command computes first and
writes only at the end (each file atomically), so bad input exits with code 2 and one line
on stderr without leaving partial output.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from biomorph._cli import bounded
from biomorph.errors import ParameterError
from biomorph.tree.options import SkeletonizeOptions, cli_default, cli_fields, cli_type

app = typer.Typer(
    name="tree",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    help="Tree skeletons from LiDAR point clouds (graph and voxel methods).",
)

Method = Annotated[str, typer.Option("--method", "-m", help="graph (Livny) or voxel (Gorte).")]
Seed = Annotated[int, typer.Option(help="Random seed.")]


def _trees_line(m: dict) -> str:
    """``24 (16 measured stems, 8 fragments)``: fragments are no trees (understorey,
    stumps, crown pieces; :func:`biomorph.tree.metrics.tree_kinds`)."""
    n, frag = m.get("n_trees"), m.get("n_fragments")
    if not frag:
        return str(n)
    stems = m.get("n_stems")
    return (
        f"{n} ({stems} measured stem{'' if stems == 1 else 's'}, "
        f"{frag} fragment{'' if frag == 1 else 's'})"
    )


def _print_table(title: str, rows: list[tuple[str, Any]]) -> None:
    from rich.table import Table

    from biomorph._cli import out_console

    table = Table(title=title, show_header=False)
    for k, v in rows:
        if isinstance(v, float):
            v = f"{v:.4g}"
        table.add_row(str(k), str(v))
    out_console.print(table)


def _option_parameters() -> list[inspect.Parameter]:
    """One typer option per field of :mod:`biomorph.tree.options` that has a ``cli`` entry
    (generated: the API, ``skeletonize`` and ``batch`` share one list)."""
    params = []
    for stage, f, spec in cli_fields():
        typ = cli_type(f, spec)
        check = None
        if spec.lo is not None or spec.hi is not None:
            check = bounded(spec.lo, spec.hi, lo_open=spec.lo_open, hi_open=spec.hi_open)
        flag = typ is bool or typ == bool | None
        decls = [f"{spec.flag}/--no-{spec.flag[2:]}"] if flag else [spec.flag]
        opt = typer.Option(
            *decls, help=spec.help, callback=check, rich_help_panel=f"{stage.capitalize()} options"
        )
        params.append(
            inspect.Parameter(
                f"{stage}__{f.name}",
                inspect.Parameter.KEYWORD_ONLY,
                default=cli_default(f, spec),
                annotation=Annotated[typ, opt],
            )
        )
    return params


def with_skeleton_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """Give a command every pipeline option; it receives them as ``options``
    (a :class:`~biomorph.tree.options.SkeletonizeOptions`, built from its ``method`` and
    ``seed`` parameters and the generated options)."""
    sig = inspect.signature(func, eval_str=True)
    extra = _option_parameters()

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        values = {k.replace("__", ".", 1): kwargs.pop(k) for k in list(kwargs) if "__" in k}
        kwargs["options"] = SkeletonizeOptions.from_cli(
            values, method=kwargs["method"], seed=kwargs["seed"]
        )
        return func(*args, **kwargs)

    own = [p for p in sig.parameters.values() if p.name != "options"]
    wrapper.__signature__ = sig.replace(parameters=own + extra)  # type: ignore[attr-defined]
    wrapper.__annotations__ = {**func.__annotations__, **{p.name: p.annotation for p in extra}}
    wrapper.__annotations__.pop("options", None)
    return wrapper


@app.command()
@with_skeleton_options
def skeletonize(
    cloud: Annotated[Path, typer.Argument(help="Point cloud: .las .laz .ply .xyz .txt .csv .npy")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("tree-out"),
    method: Method = "graph",
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
    world: Annotated[
        bool, typer.Option(help="Write original (e.g. georeferenced) coordinates.")
    ] = True,
    seed: Seed = 0,
    models: Annotated[
        int,
        typer.Option(
            help="Reconstruct N models (seed + i, level width 0.85-1.15 x the derived one), "
            "keep the one nearest to the points and report the volume's spread over all "
            "(models.csv, summary.json 'models'; TreeQSM's practice).",
            callback=bounded(1, 64),
        ),
    ] = 1,
    options: SkeletonizeOptions | None = None,
) -> None:
    """Skeletonise a tree cloud and write skeleton.ply/.mtg, tube.glb/.obj, the TreeQSM
    tables (cylinders.csv, branches.csv, treedata.csv), points.laz (tree_id per point),
    one tree_<id>/ folder per tree of a plot, summary.json and preview.png into OUT; with
    --models N the model nearest to the points, models.csv (and models_trees.csv for a
    plot).

    Every option of the pipeline stages is listed below (biomorph.tree.options).

    Example: biomorph tree skeletonize scan.laz --method graph --out out/ --json
    """
    from biomorph.tree.metrics import scan_rows, summary_rows
    from biomorph.tree.models import summary_rows as models_summary_rows

    assert options is not None
    skel, files = _skeletonize_and_export(
        cloud, out, options, world, models, f"{cloud.name} ({method})", progress=True
    )
    summary = skel.summary()
    summary["files"] = {k_: str(v) for k_, v in files.items()}
    if as_json:
        from biomorph._cli import print_json

        print_json(summary)
        return
    m = skel.metrics
    _print_table(
        f"{cloud.name}: {method} skeleton",
        [
            ("points", skel.info.get("points")),
            ("trees", _trees_line(m)),
            ("nodes", m.get("n_nodes")),
            ("NOB (tips)", m.get("nob")),
            ("TBL (m)", m.get("tbl")),
            ("MSE (m²)", m.get("mse")),
            ("max order", m.get("max_order")),
            ("trunk radius (m)", ", ".join(f"{r:.3f}" for r in m.get("trunk_radius", []))),
            *summary_rows(m),
            *models_summary_rows(skel.info.get("models")),
            *scan_rows(skel.params, skel.info),
            ("seconds", skel.timings.get("total")),
            ("output", str(out)),
        ],
    )


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
    cloud = simulate_scan(
        truth,
        n_points=points,
        noise=noise,
        scanners=scanners,
        leaves=leaves,
        ground=ground,
        seed=seed,
    )
    out.mkdir(parents=True, exist_ok=True)
    files = {
        "truth": write_graph(out / "truth.ply", truth),
        "truth_mtg": write_graph(out / "truth.mtg", truth),
        "cloud": write_points(out / "cloud.ply", cloud),
    }
    with atomic_path(out / "preview.png") as tmp:
        render_graph(truth, tmp, cloud=cloud, title=f"synthetic {preset} (seed {seed})")
    files["preview"] = out / "preview.png"
    summary = {
        "preset": preset,
        "seed": seed,
        "points": cloud.n_points,
        "nob": int(truth.leaves.size),
        "tbl": truth.total_length,
        "base_radius": float(truth.radius[truth.roots[0]]),
        "files": {k_: str(v) for k_, v in files.items()},
    }
    if as_json:
        from biomorph._cli import print_json

        print_json(summary)
        return
    _print_table(f"synthetic {preset}", [(k_, v) for k_, v in summary.items() if k_ != "files"])


@app.command()
def evaluate(
    skeleton: Annotated[Path, typer.Argument(help="Skeleton .ply or .mtg.")],
    truth: Annotated[Path | None, typer.Option(help="Ground-truth skeleton .ply/.mtg.")] = None,
    cloud: Annotated[
        Path | None,
        typer.Option(
            help="Point cloud for the MSE (and, with --truth, the observed-truth measures)."
        ),
    ] = None,
    tolerance: Annotated[float | None, typer.Option(help="Match tolerance, m.")] = None,
    reference: Annotated[
        list[Path] | None,
        typer.Option(
            help="Reference QSM in the skeleton's frame (TreeQSM .mat, SimpleForest-style "
            ".csv, .ply, .mtg); repeatable. Reports the agreement with each: volume (all "
            "and per diameter class), length, trunk length, tips, F1 (5 cm unless "
            "--tolerance), radius profile."
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """NOB, TBL, MSE of a skeleton; with --truth also precision/recall/F1, NOB/TBL ratios,
    radius error, DBH and volume error; with --reference the agreement with each
    reference model.

    Example: biomorph tree evaluate out/skeleton.ply --reference tree_QSM.mat --json
    """
    from biomorph.core.jsonable import to_jsonable
    from biomorph.io import read_graph, read_points
    from biomorph.tree.metrics import compare_to_truth, skeleton_metrics

    g = read_graph(skeleton)
    pc = read_points(cloud) if cloud is not None else None
    res: dict[str, Any] = {"skeleton": str(skeleton), **skeleton_metrics(g, pc)}
    if truth is not None:
        res["truth"] = str(truth)
        res["comparison"] = compare_to_truth(g, read_graph(truth), tolerance, cloud=pc)
    if reference:
        from biomorph.tree.reference import compare_to_reference, read_reference

        refs = {str(p): read_reference(p) for p in reference}  # all read before reporting
        res["references"] = {
            k_: compare_to_reference(g, r, 0.05 if tolerance is None else tolerance)
            for k_, r in refs.items()
        }
    res = to_jsonable(res)
    if as_json:
        from biomorph._cli import print_json

        print_json(res)
        return
    rows = [(k_, v) for k_, v in res.items() if not isinstance(v, (dict, list))]
    rows += [(f"truth {k_}", v) for k_, v in res.get("comparison", {}).items()]
    for name, c in res.get("references", {}).items():
        rows += _reference_rows(Path(name).name, c)
    _print_table(f"{skeleton.name}", rows)


def _reference_rows(name: str, c: dict[str, Any]) -> list[tuple[str, str]]:
    """The summary rows of one :func:`~biomorph.tree.reference.compare_to_reference`."""

    def pair(key: str, unit: str, scale: float = 1.0, fmt: str = "{:.3g}") -> str:
        a, b = c.get(key), c.get(f"{key}_reference")
        if a is None or b is None:
            return "—"
        ratio = f" ({a / b:.2f}×)" if b else ""
        unit = f" {unit}" if unit else ""
        return f"{fmt.format(scale * a)} / {fmt.format(scale * b)}{unit}{ratio}"

    rows = [
        (f"{name}: volume ours / ref.", pair("volume", "L", 1e3, "{:.4g}")),
        (f"{name}: length", pair("length", "m")),
        (f"{name}: trunk length", pair("trunk_length", "m")),
        (f"{name}: tips", pair("tips", "", 1.0, "{:.0f}")),
        (f"{name}: F1 @ {100 * c['tolerance']:.0f} cm", f"{c['f1']:.3f}"),
    ]
    if c.get("classes"):
        cells = ", ".join(
            f"{k} {1e3 * a:.3g}/{1e3 * b:.3g}" for k, (a, b) in c["classes"].items() if a or b
        )
        rows.append((f"{name}: volume by diameter (L)", cells))
    if c.get("radius_profile_error") is not None:
        rows.append((f"{name}: radius profile error", f"{100 * c['radius_profile_error']:.0f} %"))
    return rows


def _skeletonize_and_export(
    cloud: Path | str,
    out: Path | str,
    options: SkeletonizeOptions,
    world: bool,
    models: int,
    title: str,
    *,
    progress: bool = False,
) -> tuple[Any, dict[str, Path]]:
    """One run, or ``models`` runs of which the nearest to the points is kept
    (:func:`biomorph.tree.models.reconstruct_models`; ``models.csv`` beside the outputs),
    exported into ``out``. ``progress``: a progress bar over the models' phases."""
    import contextlib

    from biomorph.progress import task
    from biomorph.tree.export import export_skeleton
    from biomorph.tree.pipeline import PHASES

    label = f"{models} models" if models > 1 else "skeleton"
    bar = task(label, total=models * len(PHASES)) if progress else contextlib.nullcontext(None)
    with bar as advance:  # a step per finished phase of each model
        if models <= 1:
            from biomorph.tree.pipeline import skeletonize as run

            skel = run(cloud, options=options, progress=advance)
            return skel, export_skeleton(skel, out, world=world, title=title)
        from biomorph.tree.models import reconstruct_models

        ensemble = reconstruct_models(cloud, models, options=options, progress=advance)
    from biomorph.io.atomic import write_text

    files = export_skeleton(ensemble.skeleton, out, world=world, title=title)
    files["models"] = write_text(Path(out) / "models.csv", ensemble.csv())
    if len(ensemble.runs[0].trees) > 1:
        files["models_trees"] = write_text(Path(out) / "models_trees.csv", ensemble.trees_csv())
    return ensemble.skeleton, files


def _write_inventory(out: Path, done: list[Path]) -> Path | None:
    """``OUT/inventory.csv``: every tree of every finished input, one row each — the
    input's file name, then its ``treedata.csv`` row (TreeQSM's attributes, the tree's
    location) — written atomically; None when no input has a tree table."""
    import csv
    import io

    from biomorph.io.atomic import write_text

    header: list[str] = []
    rows: list[dict[str, str]] = []
    for p in done:
        table = out / p.stem / "treedata.csv"
        if not table.is_file():
            continue
        with table.open(newline="", encoding="utf-8") as f:
            for row in csv.DictReader(f):
                header += [c for c in row if c not in header]
                rows.append({"input": p.name, **row})
    if not rows:
        return None
    buf = io.StringIO()
    writer = csv.DictWriter(buf, ["input", *header], restval="", lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return write_text(out / "inventory.csv", buf.getvalue())


def batch_item(item: tuple[str, str, SkeletonizeOptions, bool, int]) -> dict[str, Any]:
    """Skeletonise one cloud (``models`` models, the nearest kept) into ``out/<stem>/``
    (module level: picklable for dask)."""
    path, out, options, world, models = item
    skel, _ = _skeletonize_and_export(path, out, options, world, models, Path(path).name)
    m = skel.metrics
    res = {
        "nob": m.get("nob"),
        "tbl": m.get("tbl"),
        "trees": m.get("n_trees"),
        "stems": m.get("n_stems"),
        "fragments": m.get("n_fragments"),
        "seconds": skel.timings.get("total"),
    }
    st = skel.info.get("models")
    if st:
        res["volume_L"] = st["volume_L"]
        res["chosen_model"] = st["best"]
    return res


@app.command()
@with_skeleton_options
def batch(
    inputs: Annotated[list[Path], typer.Argument(help="Point cloud files.")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output folder (one sub-folder per input).")
    ] = Path("batch-out"),
    method: Method = "graph",
    workers: Annotated[int | None, typer.Option(help="Worker processes (0 = serial).")] = None,
    scheduler: Annotated[
        str | None, typer.Option(help="Address of a running dask scheduler.")
    ] = None,
    world: Annotated[bool, typer.Option(help="Write original coordinates.")] = True,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the batch report as JSON.")
    ] = False,
    seed: Seed = 0,
    models: Annotated[
        int,
        typer.Option(
            help="Models per cloud, the one nearest to the points kept (as skeletonize).",
            callback=bounded(1, 64),
        ),
    ] = 1,
    options: SkeletonizeOptions | None = None,
) -> None:
    """Skeletonise many clouds in parallel on dask.distributed (LocalCluster by default),
    with every option of ``skeletonize``.

    Failed inputs are reported without stopping the others; an input counts as done once
    all its files are written (a completion marker keyed by the options), so a re-run
    resumes exactly. Exit code 1 if any input failed. OUT/inventory.csv lists every tree
    of every finished input (its treedata row: volumes, height, DBH, crown, location).

    Example: biomorph tree batch plots/*.laz --out results/ --workers 4
    """
    from biomorph.scale.batch import run_batch

    if not inputs:
        raise ParameterError("no input files given")
    stems = [p.stem for p in inputs]
    if len(set(stems)) != len(stems):
        raise ParameterError("input file names must be unique (outputs go to OUT/<name>/)")
    assert options is not None
    items = [(str(p), str(out / p.stem), options, world, models) for p in inputs]
    report = run_batch(
        items,
        batch_item,
        out_dir=out,
        key=lambda it: Path(it[0]).stem,
        workers=workers,
        scheduler=scheduler,
        description="trees",
    )
    _write_inventory(out, [p for p in inputs if p.stem in {*report.ok, *report.skipped}])
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
