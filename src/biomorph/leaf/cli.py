"""``biomorph leaf``: mesh, grow, canopy, reduce-curve (thin layer over the API).

Angles are degrees at the command line, lengths metres. Bad input exits with code 2 and
one line; nothing is written.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from biomorph._cli import bounded
from biomorph.errors import ParameterError

app = typer.Typer(
    no_args_is_help=True,
    add_completion=False,
    help="Grass leaves: mesh, grow, canopies, reduction curves.",
)

MESH_EXT = (".obj", ".ply", ".glb", ".can")

Preset = Annotated[str, typer.Option("--preset", help="Leaf preset: maize, wheat or grass.")]
Json = Annotated[bool, typer.Option("--json", help="Print a machine-readable summary.")]


def _check_ext(path: Path, allowed: tuple[str, ...]) -> None:
    if path.suffix.lower() not in allowed:
        raise ParameterError(
            f"output {path}: extension {path.suffix or '(none)'!r} is not "
            f"supported; expected one of {' '.join(allowed)}"
        )


def _shape(
    preset: str,
    length: float | None,
    width: float | None,
    twist: float | None,
    undulation: float | None,
    midrib: Path | None = None,
    widths: Path | None = None,
    rank_class: str | None = None,
):
    import numpy as np

    from biomorph.leaf.files import read_points_csv
    from biomorph.leaf.shape import LeafShape

    base = LeafShape.from_preset(preset, rank_class=rank_class)
    if midrib is not None:
        x, y = read_points_csv(midrib, ("x", "y"))
        if widths is not None:
            s, r = read_points_csv(widths, ("s", "r"))
        else:
            s, r = base.s_r, base.r
        fitted = LeafShape.from_points(
            x, y, s, r, width=None if widths else base.width, name=midrib.stem
        )
        base = base.with_(
            s=fitted.s,
            phi=fitted.phi,
            s_r=fitted.s_r,
            r=fitted.r,
            length=fitted.length,
            width=fitted.width,
            collection=None,
            name=fitted.name,
        )
    changes: dict = {}
    if length is not None:
        changes["length"] = length
    if width is not None:
        changes["width"] = width
    if twist is not None:
        changes["twist"] = float(np.radians(twist))
    if undulation is not None:
        changes["undulation"] = undulation
    return base.with_(**changes) if changes else base


POS = bounded(0, lo_open=True)
NONNEG = bounded(0)
AGE = bounded(0, 1)


@app.command()
def mesh(
    output: Annotated[Path, typer.Option("-o", "--output", help="leaf.obj|.ply|.glb|.can")],
    preset: Preset = "maize",
    rank_class: Annotated[
        str | None,
        typer.Option(
            "--class",
            help="Class of the preset (wheat So99 1..6, 1 = flag leaf; maize rank 1..16 of "
            "the mature plant, or shape group e.g. g8-10).",
        ),
    ] = None,
    length: Annotated[float | None, typer.Option(help="Leaf length L (m).", callback=POS)] = None,
    width: Annotated[float | None, typer.Option(help="Maximal width (m).", callback=POS)] = None,
    age: Annotated[
        float | None, typer.Option(help="Normalised age in [0, 1].", callback=AGE)
    ] = None,
    triangles: Annotated[
        int | None, typer.Option(help="Exact triangle budget.", callback=bounded(1))
    ] = None,
    twist: Annotated[
        float | None,
        typer.Option(help="Twist at the tip (degrees).", callback=bounded(-3600, 3600)),
    ] = None,
    undulation: Annotated[
        float | None, typer.Option(help="Margin undulation amplitude (m).", callback=NONNEG)
    ] = None,
    n_s: Annotated[
        int, typer.Option("--n-s", help="Samples along the midrib.", callback=bounded(2))
    ] = 60,
    midrib: Annotated[
        Path | None, typer.Option(help="Fit to a digitised midrib: CSV with columns x,y (cm).")
    ] = None,
    widths: Annotated[
        Path | None, typer.Option(help="Width profile for --midrib: CSV with columns s,r (cm).")
    ] = None,
    as_json: Json = False,
) -> None:
    """Mesh one leaf (a preset or one of its shape classes, or fitted to your midrib).

    Example: biomorph leaf mesh --preset wheat --class 5 --age 0.7 --triangles 50 -o leaf.obj
    """
    from biomorph._cli import emit
    from biomorph.leaf.files import write_leaf_mesh

    _check_ext(output, MESH_EXT)
    if widths is not None and midrib is None:
        raise ParameterError("--widths needs --midrib (the width profile of your leaf)")
    shape = _shape(preset, length, width, twist, undulation, midrib, widths, rank_class)
    m = shape.mesh(age=age, triangles=triangles, n_s=n_s)
    write_leaf_mesh(output, m)
    summary = {
        "file": str(output),
        "preset": preset,
        "class": rank_class,
        "triangles": m.n_faces,
        "vertices": m.n_vertices,
        "area_m2": m.area(),
        "analytic_area_m2": shape.area(),
        "length_m": shape.length,
        "width_m": shape.width,
        "age": age,
    }
    emit(summary, as_json, title="leaf mesh")


@app.command()
def grow(
    output: Annotated[Path, typer.Option("-o", "--output", help="DIR or FILE.glb")],
    preset: Preset = "wheat",
    frames: Annotated[int, typer.Option(help="Number of frames.", callback=bounded(1, 10000))] = 24,
    duration: Annotated[float, typer.Option(help="Duration (s).", callback=POS)] = 2.0,
    age_start: Annotated[float, typer.Option(help="Age at t=0.", callback=AGE)] = 0.0,
    age_end: Annotated[float, typer.Option(help="Age at the end.", callback=AGE)] = 1.0,
    width_rate: Annotated[
        float, typer.Option(help="d(width factor)/d(age).", callback=bounded(-100, 100))
    ] = 0.0,
    bend_rate: Annotated[
        float, typer.Option(help="dθ/d(age) (degrees).", callback=bounded(-3600, 3600))
    ] = 0.0,
    hidden: Annotated[
        float,
        typer.Option(
            help="Length hidden in the sheath (m); the visible part is l − hidden.", callback=NONNEG
        ),
    ] = 0.0,
    fmt: Annotated[str, typer.Option("--format", help="Frame format in a DIR.")] = "obj",
    plant: Annotated[bool, typer.Option("--plant", help="Grow a whole plant.")] = False,
    leaves: Annotated[
        int, typer.Option(help="Leaves of the --plant.", callback=bounded(1, 100))
    ] = 8,
    seed: Annotated[int, typer.Option(help="Random seed of the --plant.")] = 0,
    as_json: Json = False,
) -> None:
    """Grow a leaf (or a plant): a glTF with one morph target per frame, or a folder.

    Example: biomorph leaf grow --preset wheat --frames 24 -o grow.glb
    """
    import numpy as np

    from biomorph._cli import emit
    from biomorph.leaf.files import write_leaf_mesh
    from biomorph.leaf.growth import GrowthRates, LeafTimeline, state_at_age
    from biomorph.leaf.shape import LeafShape

    if age_end < age_start:
        raise ParameterError(f"--age-end {age_end} is before --age-start {age_start}")
    is_glb = output.suffix.lower() == ".glb"
    if output.suffix and not is_glb:
        raise ParameterError(f"output {output}: expected a .glb file or a folder (no suffix)")
    if not is_glb:
        _check_ext(Path("x." + fmt), MESH_EXT)
    shape = LeafShape.from_preset(preset)
    if plant:
        from biomorph.leaf.canopy import PlantSpec, plant_growth_frames

        meshes = plant_growth_frames(
            PlantSpec(preset=preset, leaves=leaves),
            frames,
            seed=seed,
            age_start=max(age_start, 0.01),
            age_end=age_end,
        )
    else:
        rates = GrowthRates(
            age_rate=(age_end - age_start) / duration,
            width_rate=width_rate,
            bend_rate=float(np.radians(bend_rate)),
        )
        tl = LeafTimeline(
            shape,
            rates,
            duration,
            hidden=hidden,
            initial=state_at_age(shape, age_start, hidden=hidden),
        )
        meshes = tl.frames(frames)
    areas = [m.area() for m in meshes]
    if is_glb:
        from biomorph.io.gltf import write_gltf

        write_gltf(
            output,
            None,
            frames=meshes,
            frame_time=duration / max(frames - 1, 1),
            y_up=False,
            name=f"{preset} leaf growth",
        )
        files = [str(output)]
    else:
        files = [
            str(write_leaf_mesh(output / f"frame_{i:04d}.{fmt}", m)) for i, m in enumerate(meshes)
        ]
    summary = {
        "output": str(output),
        "frames": frames,
        "files": len(files),
        "area_m2": areas,
        "triangles": meshes[0].n_faces,
    }
    emit(summary, as_json, title="leaf grow")


@app.command()
def canopy(
    output: Annotated[Path, typer.Option("-o", "--output", help="field.glb|.obj|.ply|.can")],
    plants: Annotated[
        int, typer.Option(help="Number of plants.", callback=bounded(1, 10_000_000))
    ] = 20,
    rows: Annotated[int, typer.Option(help="Number of rows.", callback=bounded(1))] = 4,
    spacing: Annotated[
        float | None,
        typer.Option(help="Row spacing (m) [default: maize 0.75, else 0.15].", callback=POS),
    ] = None,
    density: Annotated[
        float | None,
        typer.Option(
            help="Plants per m² (sets the spacing within rows) [default: maize 8, else "
            "spacing / 3 within rows].",
            callback=POS,
        ),
    ] = None,
    preset: Preset = "wheat",
    leaves: Annotated[
        int | None,
        typer.Option(
            help="Leaves per plant [default: maize 16, else 6].", callback=bounded(1, 100)
        ),
    ] = None,
    triangles: Annotated[
        int, typer.Option(help="Triangles per leaf (about).", callback=bounded(1))
    ] = 20,
    age: Annotated[
        float | None,
        typer.Option(
            help="Plant age in [0, 1] [default: 0.8; maize: the mature plant, last leaf "
            "ligulated].",
            callback=AGE,
        ),
    ] = None,
    thermal_time: Annotated[
        float | None,
        typer.Option(
            help="Thermal time since emergence (°Cd): leaf ages from phyllochrons "
            "instead of --age.",
            callback=NONNEG,
        ),
    ] = None,
    phyllochron: Annotated[
        float | None, typer.Option(help="Phyllochron (°Cd; default per preset).", callback=POS)
    ] = None,
    classes: Annotated[
        bool, typer.Option(help="Per-rank shape classes fitted to the data.")
    ] = True,
    draw: Annotated[
        bool, typer.Option(help="Draw each leaf from its class database (ADEL-like).")
    ] = False,
    soil: Annotated[bool, typer.Option(help="Bend leaves at the soil.")] = True,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    as_json: Json = False,
) -> None:
    """Build a field of plants in rows; report its leaf area index and ground tile.

    Example: biomorph leaf canopy --plants 200 --rows 10 --spacing 0.15 --seed 1 -o field.glb
    """
    import warnings

    from biomorph._cli import emit, err_console
    from biomorph.leaf.canopy import (
        FieldSpec,
        LeafCountWarning,
        PlantSpec,
        build_field,
        field_mesh,
        leaf_area_index,
    )

    _check_ext(output, MESH_EXT)
    from biomorph.leaf.plant import DEFAULT_LEAVES, mature_thermal_time

    if leaves is None:
        leaves = DEFAULT_LEAVES.get(preset, 6)
    mature = preset in DEFAULT_LEAVES  # maize: a mature field at a usual row spacing/density
    if spacing is None:
        spacing = 0.75 if mature else 0.15
    if density is None and mature:
        density = 8.0
    if age is None and thermal_time is None and mature:
        thermal_time = mature_thermal_time(preset, leaves, phyllochron)
    spec = FieldSpec(
        plants=plants,
        rows=rows,
        row_spacing=spacing,
        density=density,
        plant=PlantSpec(
            preset=preset,
            leaves=leaves,
            age=0.8 if age is None else age,
            thermal_time=thermal_time,
            phyllochron=phyllochron,
            shape_classes=classes,
            draw_members=draw,
            soil=soil,
        ),
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LeafCountWarning)
        fld = build_field(spec, seed=seed)
    for w in caught:
        err_console.print(f"warning: {w.message}")
    m = field_mesh(fld, triangles_per_leaf=triangles)
    _write_with_tile(output, m, fld.tile)
    lai = leaf_area_index(fld, m)
    summary = {
        "file": str(output),
        "plants": plants,
        "leaves": fld.n_leaves,
        "missing_leaves_per_plant": fld.missing_leaves(),
        "triangles": m.n_faces,
        "leaf_area_m2": lai * fld.ground_area,
        "ground_area_m2": fld.ground_area,
        "lai": lai,
        "ground": ",".join(f"{v:.6g}" for v in fld.tile) if fld.tile else None,
        "below_ground_vertices": int((m.vertices[:, 2] < 0).sum()),
        "seed": seed,
    }
    emit(summary, as_json, title="leaf canopy")


def _write_with_tile(output: Path, mesh, tile) -> None:
    """Write a field's mesh; a GLB also carries the ground tile in its scene extras, so
    `leaf light` uses the field's tile by default (not the leaves' overhanging extent)."""
    from biomorph.leaf.files import GROUND_TILE_KEY, write_leaf_mesh

    if tile and Path(output).suffix.lower() == ".glb":
        write_leaf_mesh(output, mesh, extras={GROUND_TILE_KEY: [float(v) for v in tile]})
    else:
        write_leaf_mesh(output, mesh)


@app.command("reduce-curve")
def reduce_curve(
    output: Annotated[Path, typer.Option("-o", "--output", help="curve.png")],
    preset: Preset = "wheat",
    points: Annotated[
        int, typer.Option(help="Discretisation points.", callback=bounded(3, 100_000))
    ] = 200,
    leaves: Annotated[
        int,
        typer.Option(
            help="Leaves in the field timed for the time curve.", callback=bounded(1, 1_000_000)
        ),
    ] = 500,
    as_json: Json = False,
) -> None:
    """Plot error vs triangles and time vs triangles of the reduction (paper's figure 6).

    Example: biomorph leaf reduce-curve --preset wheat -o curve.png
    """
    from biomorph._cli import out_console, print_json
    from biomorph.leaf.plots import reduction_curves

    _check_ext(output, (".png",))
    if points < 3:
        raise ParameterError(f"--points {points}: expected at least 3")
    if leaves < 1:
        raise ParameterError(f"--leaves {leaves}: expected at least 1")
    from biomorph.leaf.shape import LeafShape

    table = reduction_curves(LeafShape.from_preset(preset), output, n_points=points, leaves=leaves)
    if as_json:
        print_json({"file": str(output), **table})
    else:
        out_console.print(f"wrote {output}")


@app.command()
def light(
    canopy_file: Annotated[
        Path,
        typer.Argument(metavar="CANOPY", help="Canopy mesh .glb|.obj|.ply|.can (Z-up, metres)."),
    ],
    sun: Annotated[
        str | None,
        typer.Option(help="Sun time, ISO 8601 UTC (e.g. 2026-06-21T12:00). Omit: sky only."),
    ] = None,
    latitude: Annotated[
        float, typer.Option(help="Latitude (degrees north).", callback=bounded(-90, 90))
    ] = 48.8,
    longitude: Annotated[
        float, typer.Option(help="Longitude (degrees east).", callback=bounded(-180, 360))
    ] = 2.3,
    sky: Annotated[
        int, typer.Option(help="Diffuse sky directions: 46, 16 or 0.", callback=bounded(0, 46))
    ] = 46,
    par: Annotated[
        float,
        typer.Option(
            help="Global horizontal PAR (µmol m-2 s-1).", callback=bounded(0, lo_open=True)
        ),
    ] = 1500.0,
    diffuse_fraction: Annotated[
        float, typer.Option(help="Diffuse part of the PAR.", callback=bounded(0, 1))
    ] = 0.3,
    absorptance: Annotated[
        float, typer.Option(help="Leaf PAR absorptance.", callback=bounded(0, 1, lo_open=True))
    ] = 0.85,
    ray_spacing: Annotated[
        float | None,
        typer.Option(
            help="Metres between rays (default: from the triangle size).",
            callback=bounded(0, lo_open=True),
        ),
    ] = None,
    max_rays: Annotated[
        int, typer.Option(help="Most rays per direction.", callback=bounded(1))
    ] = 300_000,
    ground: Annotated[
        str | None,
        typer.Option(
            help="Ground tile xmin,ymin,xmax,ymax (m); default: the tile a `leaf canopy` GLB "
            "stores, else the canopy's extent."
        ),
    ] = None,
    periodic: Annotated[
        bool, typer.Option(help="Treat the ground tile as one tile of an infinite field.")
    ] = True,
    plot: Annotated[
        Path | None,
        typer.Option("--plot", "--png", help="False-colour PNG of absorbed PAR (top view)."),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option("-o", "--output", help="Canopy .glb with absorbed PAR per vertex."),
    ] = None,
    table: Annotated[str | None, typer.Option(help="Per-leaf results as CSV.")] = None,
    seed: Annotated[int, typer.Option(help="Random seed of the ray jitter.")] = 0,
    engine: Annotated[
        str,
        typer.Option(help="First hits: zbuffer (numba, all cores), embree or trimesh."),
    ] = "zbuffer",
    as_json: Json = False,
) -> None:
    """Light intercepted by a canopy: sun + standard overcast sky by ray casting.

    Example: biomorph leaf light field.glb --sun 2026-06-21T12:00 --latitude 48.8 --json
    """
    from dataclasses import replace
    from datetime import datetime

    from biomorph._cli import check_suffix, emit
    from biomorph.leaf.files import read_canopy_scene
    from biomorph.leaf.light import ENGINES, LightOptions

    if engine not in ENGINES:
        raise ParameterError(f"--engine {engine!r}: expected one of {', '.join(ENGINES)}")
    if sky not in (0, 16, 46):
        raise ParameterError(f"--sky {sky}: expected 0, 16 or 46 directions")
    when = None
    if sun is not None:
        try:
            when = datetime.fromisoformat(sun)
        except ValueError:
            raise ParameterError(
                f"--sun {sun!r}: expected an ISO 8601 date and time such as 2026-06-21T12:00 (UTC)"
            ) from None
    rect = _parse_ground(ground)
    table_path = None if table is None else Path(table)
    for path, allowed, opt in (
        (plot, (".png",), "--plot"),
        (output, (".glb",), "--output"),
        (table_path, (".csv",), "--table"),
    ):
        if path is not None:
            check_suffix(path, allowed, opt)
    opts = LightOptions(
        when=when,
        latitude=latitude,
        longitude=longitude,
        sky=sky,
        par=par,
        diffuse_fraction=diffuse_fraction,
        absorptance=absorptance,
        ray_spacing=ray_spacing,
        max_rays=max_rays,
        periodic=periodic,
        ground=rect,
        seed=seed,
        engine=engine,
    )
    opts.validate()
    mesh, stored = read_canopy_scene(canopy_file)
    ground_from = "--ground" if rect is not None else "file" if stored else "canopy extent"
    if rect is None and stored is not None:  # the tile `leaf canopy` stored in the GLB
        opts = replace(opts, ground=stored)
    result = _run_light(mesh, opts)
    summary = {"file": str(canopy_file), **result.summary(), "ground_from": ground_from}
    if table_path is not None and table_path.resolve() == canopy_file.resolve():
        raise ParameterError(f"--table {table}: is the input canopy; choose another file")
    summary.update(_light_outputs(mesh, result, plot, output, table_path))
    emit(summary, as_json, title="leaf light")


def _parse_ground(text: str | None):
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 4 or not (vals[2] > vals[0] and vals[3] > vals[1]):
        raise ParameterError(
            f"--ground {text!r}: expected xmin,ymin,xmax,ymax with "
            "xmax > xmin and ymax > ymin (metres)"
        )
    return vals


def _run_light(mesh, opts):
    from biomorph.leaf.light import intercept
    from biomorph.progress import task

    with task("casting rays", total=None) as advance:

        def progress(done: int, total: int) -> None:
            advance(1, description=f"casting rays: direction {done}/{total}")

        return intercept(mesh, opts, progress=progress)


def _light_outputs(mesh, result, png, output, table) -> dict:
    out: dict = {}
    if png is not None:
        from biomorph.leaf.plots import light_map

        el = result.sun[0] if result.sun else None
        title = f"absorbed PAR, gap fraction {result.gap_fraction:.3f}" + (
            f", sun elevation {el:.1f}°" if el is not None else ""
        )
        out["png"] = str(light_map(mesh, result.absorbed, png, title))
    if output is not None:
        from biomorph.leaf.files import write_leaf_mesh

        per_vertex = result.vertex_values(mesh)
        out["output"] = str(
            write_leaf_mesh(
                output, _coloured(mesh, per_vertex), vertex_attributes={"par_absorbed": per_vertex}
            )
        )
    if table is not None:
        from biomorph.io.atomic import write_text

        lv = result.leaves
        cols = ("plant", "leaf", "area", "intercepted", "absorbed", "fraction", "absorbed_par")
        lines = [
            "plant,leaf,area_m2,intercepted_umol_s,absorbed_umol_s,fraction,absorbed_par_umol_m2_s"
        ]
        lines += [
            ",".join(
                f"{lv[c][i]:.8g}" if c not in ("plant", "leaf") else str(int(lv[c][i]))
                for c in cols
            )
            for i in range(lv["leaf"].size)
        ]
        out["table"] = str(write_text(table, "\n".join(lines) + "\n"))
    return out


def _coloured(mesh, values):
    """The mesh with false-colour vertex colours (inferno-like ramp) of ``values``."""
    import numpy as np

    from biomorph.core.mesh import Mesh

    top = float(np.percentile(values, 99.5)) or 1.0
    x = np.clip(values / top, 0, 1)[:, None]
    ramp = np.array(
        [[0, 0, 4], [87, 16, 110], [188, 55, 84], [249, 142, 9], [252, 255, 164]], float
    )
    pos = x[:, 0] * (len(ramp) - 1)
    i = np.minimum(pos.astype(int), len(ramp) - 2)
    f = (pos - i)[:, None]
    rgb = ramp[i] * (1 - f) + ramp[i + 1] * f
    rgba = np.concatenate([rgb, np.full((len(values), 1), 255.0)], axis=1).astype(np.uint8)
    return Mesh(
        mesh.vertices,
        mesh.faces,
        normals=mesh.normals,
        uv=mesh.uv,
        vertex_colors=rgba,
        face_ids=mesh.face_ids,
    )


@app.command()
def plant(
    output: Annotated[Path, typer.Option("-o", "--output", help="plant.glb|.obj|.ply|.can")],
    preset: Preset = "wheat",
    leaves: Annotated[
        int | None,
        typer.Option(
            help="Main-stem leaves (default tables) [default: maize 16, else 11].",
            callback=bounded(1, 60),
        ),
    ] = None,
    thermal_time: Annotated[
        float | None,
        typer.Option(
            help="Thermal time since emergence (°Cd) [default: the last leaf just ligulated].",
            callback=NONNEG,
        ),
    ] = None,
    phyllochron: Annotated[
        float | None, typer.Option(help="Phyllochron (°Cd; default per preset).", callback=POS)
    ] = None,
    tillers: Annotated[int, typer.Option(help="Tillers.", callback=bounded(0, 20))] = 0,
    dims: Annotated[
        str | None, typer.Option("--dims", help="Dimension table CSV (dimT-like, metres).")
    ] = None,
    phen: Annotated[
        str | None, typer.Option("--phen", help="Phenology table CSV (phenT-like, Haun stages).")
    ] = None,
    mtg: Annotated[str | None, typer.Option(help="Also write the plant as MTG.")] = None,
    plants: Annotated[
        int, typer.Option(help="Plants in the stand.", callback=bounded(1, 100_000))
    ] = 1,
    rows: Annotated[int, typer.Option(help="Rows of the stand.", callback=bounded(1))] = 1,
    spacing: Annotated[float, typer.Option(help="Row spacing (m).", callback=POS)] = 0.15,
    density: Annotated[
        float | None, typer.Option(help="Plants per m² (sets the spacing in rows).", callback=POS)
    ] = None,
    triangles: Annotated[
        int, typer.Option(help="Triangles per leaf (about).", callback=bounded(1))
    ] = 20,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    as_json: Json = False,
) -> None:
    """One plant as ADEL describes it: tables, thermal time, tubes, tillers, senescence.

    Example: biomorph leaf plant --preset wheat --thermal-time 1100 --tillers 2 -o plant.glb
    """
    import warnings

    from biomorph._cli import check_suffix, emit, err_console
    from biomorph.io.plant_tables import read_dimensions, read_phenology
    from biomorph.leaf.canopy import LeafCountWarning
    from biomorph.leaf.plant import (
        PlantOptions,
        build_plant_architecture,
        build_plant_stand,
        write_plant_mtg,
    )

    _check_ext(output, MESH_EXT)
    if mtg is not None:
        check_suffix(mtg, (".mtg",), "--mtg")
    d = read_dimensions(dims) if dims else None
    p = read_phenology(phen) if phen else None
    opts = PlantOptions(
        preset=preset,
        leaves=leaves if d is None else int(d["rank"].size),
        thermal_time=thermal_time,
        phyllochron=phyllochron,
        tillers=tillers,
        dimensions=d,
        phenology=p,
        triangles_per_leaf=triangles,
    )
    if rows > plants:
        raise ParameterError(f"--rows {rows} exceeds --plants {plants}")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LeafCountWarning)
        if plants == 1:
            built = build_plant_architecture(opts, seed=seed)
            stand, mesh, tile = [built], built.mesh, None
        else:
            mesh, stand, tile = build_plant_stand(opts, plants, rows, spacing, density, seed)
            built = stand[0]
    for w in caught[:1]:
        err_console.print(f"warning: {w.message}")
    _write_with_tile(output, mesh, tile)
    summary = {
        "file": str(output),
        "preset": preset,
        "plants": plants,
        **built.summary(),
        "triangles": mesh.n_faces,
        "below_ground_vertices": int((mesh.vertices[:, 2] < 0).sum()),
    }
    sums = [p.summary() for p in stand]
    for key in ("leaves", "leaf_area_m2", "green_area_m2", "senescent_area_m2"):
        summary[key] = sum(s[key] for s in sums)  # whole stand
    summary["height_m"] = max(s["height_m"] for s in sums)
    if tile is not None:
        ground = (tile[2] - tile[0]) * (tile[3] - tile[1])
        summary["ground"] = ",".join(f"{v:.6g}" for v in tile)
        summary["lai"] = sum(float(p.leaves["area"].sum()) for p in stand) / ground
    if mtg is not None:
        summary["mtg"] = str(write_plant_mtg(mtg, stand))
    summary["per_leaf"] = (
        [
            {
                "plant": k,
                "axis": int(lv["axis"][i]),
                "rank": int(lv["rank"][i]),
                "length_m": lv["length"][i],
                "green_length_m": lv["green_length"][i],
                "area_m2": lv["area"][i],
                "green_area_m2": lv["green_area"][i],
                "insertion_deg": lv["insertion_deg"][i],
            }
            for k, lv in enumerate(p.leaves for p in stand)
            for i in range(lv["rank"].size)
        ]
        if as_json
        else summary["leaves"]
    )
    emit(summary, as_json, title="leaf plant")


@app.command()
def tables(
    dims: Annotated[str, typer.Option("--dims", help="Write the dimension table here.")],
    phen: Annotated[str, typer.Option("--phen", help="Write the phenology table here.")],
    preset: Preset = "wheat",
    leaves: Annotated[
        int | None,
        typer.Option(
            help="Main-stem leaves [default: maize 16, else 11].", callback=bounded(1, 60)
        ),
    ] = None,
    as_json: Json = False,
) -> None:
    """Write the default dimension and phenology tables of a preset (to edit and pass to
    ``biomorph leaf plant --dims --phen``).

    Example: biomorph leaf tables --preset maize --leaves 16 --dims dimT.csv --phen phenT.csv
    """
    from biomorph._cli import check_suffix, emit
    from biomorph.io.plant_tables import DIM_COLUMNS, PHEN_COLUMNS, write_table
    from biomorph.leaf.plant import default_leaves, default_tables

    check_suffix(dims, (".csv",), "--dims")
    check_suffix(phen, (".csv",), "--phen")
    leaves = default_leaves(preset) if leaves is None else leaves
    d, p = default_tables(preset, leaves)
    emit(
        {
            "dims": str(write_table(dims, d, DIM_COLUMNS)),
            "phen": str(write_table(phen, p, PHEN_COLUMNS)),
            "ranks": leaves,
        },
        as_json,
        title="leaf tables",
    )
