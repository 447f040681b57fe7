"""``biomorph leaf``: mesh, grow, canopy, reduce-curve (thin layer over the API).

Angles are degrees at the command line, lengths metres. Bad input exits with code 2 and
one line; nothing is written.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from biomorph.errors import ParameterError

app = typer.Typer(no_args_is_help=True, add_completion=False,
                  help="Grass leaves: mesh, grow, canopies, reduction curves.")

MESH_EXT = (".obj", ".ply", ".glb", ".can")

Preset = Annotated[str, typer.Option("--preset", help="Leaf preset: maize, wheat or grass.")]
Json = Annotated[bool, typer.Option("--json", help="Print a machine-readable summary.")]


def _check_ext(path: Path, allowed: tuple[str, ...]) -> None:
    if path.suffix.lower() not in allowed:
        raise ParameterError(f"output {path}: extension {path.suffix or '(none)'!r} is not "
                             f"supported; expected one of {' '.join(allowed)}")


def _shape(preset: str, length: float | None, width: float | None, twist: float | None,
           undulation: float | None, midrib: Path | None = None, widths: Path | None = None):
    import numpy as np

    from biomorph.leaf.files import read_points_csv
    from biomorph.leaf.shape import LeafShape

    base = LeafShape.from_preset(preset)
    if midrib is not None:
        x, y = read_points_csv(midrib, ("x", "y"))
        if widths is not None:
            s, r = read_points_csv(widths, ("s", "r"))
        else:
            s, r = base.s_r, base.r
        fitted = LeafShape.from_points(x, y, s, r, width=None if widths else base.width,
                                       name=midrib.stem)
        base = base.with_(s=fitted.s, phi=fitted.phi, s_r=fitted.s_r, r=fitted.r,
                          length=fitted.length, width=fitted.width, collection=None,
                          name=fitted.name)
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


@app.command()
def mesh(output: Annotated[Path, typer.Option("-o", "--output", help="leaf.obj|.ply|.glb|.can")],
         preset: Preset = "maize",
         length: Annotated[float | None, typer.Option(help="Leaf length L (m).")] = None,
         width: Annotated[float | None, typer.Option(help="Maximal width (m).")] = None,
         age: Annotated[float | None, typer.Option(help="Normalised age in [0, 1].")] = None,
         triangles: Annotated[int | None, typer.Option(help="Exact triangle budget.")] = None,
         twist: Annotated[float | None, typer.Option(help="Twist at the tip (degrees).")] = None,
         undulation: Annotated[float | None, typer.Option(
             help="Margin undulation amplitude (m).")] = None,
         n_s: Annotated[int, typer.Option("--n-s", help="Samples along the midrib.")] = 60,
         midrib: Annotated[Path | None, typer.Option(
             help="Fit to a digitised midrib: CSV with columns x,y (cm).")] = None,
         widths: Annotated[Path | None, typer.Option(
             help="Width profile for --midrib: CSV with columns s,r (cm).")] = None,
         as_json: Json = False) -> None:
    """Mesh one leaf (a preset, or fitted to your digitised midrib with --midrib).

    Example: biomorph leaf mesh --preset wheat --age 0.7 --triangles 50 -o leaf.obj
    """
    from biomorph._cli import out_console, print_json
    from biomorph.leaf.files import write_leaf_mesh
    from biomorph.leaf.shape import check_age

    _check_ext(output, MESH_EXT)
    if age is not None:
        check_age(age)
    if widths is not None and midrib is None:
        raise ParameterError("--widths needs --midrib (the width profile of your leaf)")
    shape = _shape(preset, length, width, twist, undulation, midrib, widths)
    m = shape.mesh(age=age, triangles=triangles, n_s=n_s)
    write_leaf_mesh(output, m)
    summary = {"file": str(output), "preset": preset, "triangles": m.n_faces,
               "vertices": m.n_vertices, "area_m2": m.area(), "analytic_area_m2": shape.area(),
               "length_m": shape.length, "width_m": shape.width, "age": age}
    if as_json:
        print_json(summary)
    else:
        out_console.print(f"wrote {output}: {m.n_faces} triangles, area {m.area():.5g} m²")


@app.command()
def grow(output: Annotated[Path, typer.Option("-o", "--output", help="DIR or FILE.glb")],
         preset: Preset = "wheat",
         frames: Annotated[int, typer.Option(help="Number of frames.")] = 24,
         duration: Annotated[float, typer.Option(help="Duration (s).")] = 2.0,
         age_start: Annotated[float, typer.Option(help="Age at t=0.")] = 0.0,
         age_end: Annotated[float, typer.Option(help="Age at the end.")] = 1.0,
         width_rate: Annotated[float, typer.Option(help="d(width factor)/d(age).")] = 0.0,
         bend_rate: Annotated[float, typer.Option(help="dθ/d(age) (degrees).")] = 0.0,
         hidden: Annotated[float, typer.Option(
             help="Length hidden in the sheath (m); the visible part is l − hidden.")] = 0.0,
         fmt: Annotated[str, typer.Option("--format", help="Frame format in a DIR.")] = "obj",
         plant: Annotated[bool, typer.Option("--plant", help="Grow a whole plant.")] = False,
         leaves: Annotated[int, typer.Option(help="Leaves of the --plant.")] = 8,
         seed: Annotated[int, typer.Option(help="Random seed of the --plant.")] = 0,
         as_json: Json = False) -> None:
    """Grow a leaf (or a plant): a glTF with one morph target per frame, or a folder.

    Example: biomorph leaf grow --preset wheat --frames 24 -o grow.glb
    """
    import numpy as np

    from biomorph._cli import out_console, print_json
    from biomorph.leaf.files import write_leaf_mesh
    from biomorph.leaf.growth import GrowthRates, LeafTimeline, state_at_age
    from biomorph.leaf.shape import LeafShape, check_age

    if frames < 1:
        raise ParameterError(f"--frames {frames}: expected at least 1")
    check_age(age_start)
    check_age(age_end)
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

        meshes = plant_growth_frames(PlantSpec(preset=preset, leaves=leaves), frames, seed=seed,
                                     age_start=max(age_start, 0.01), age_end=age_end)
    else:
        rates = GrowthRates(age_rate=(age_end - age_start) / duration, width_rate=width_rate,
                            bend_rate=float(np.radians(bend_rate)))
        if hidden < 0:
            raise ParameterError(f"--hidden {hidden}: expected a length >= 0 m")
        tl = LeafTimeline(shape, rates, duration, hidden=hidden,
                          initial=state_at_age(shape, age_start, hidden=hidden))
        meshes = tl.frames(frames)
    areas = [m.area() for m in meshes]
    if is_glb:
        from biomorph.io.gltf import write_gltf

        write_gltf(output, None, frames=meshes, frame_time=duration / max(frames - 1, 1),
                   y_up=False, name=f"{preset} leaf growth")
        files = [str(output)]
    else:
        files = [str(write_leaf_mesh(output / f"frame_{i:04d}.{fmt}", m))
                 for i, m in enumerate(meshes)]
    summary = {"output": str(output), "frames": frames, "files": len(files),
               "area_m2": areas, "triangles": meshes[0].n_faces}
    if as_json:
        print_json(summary)
    else:
        out_console.print(f"wrote {output}: {frames} frames, area {areas[0]:.3g} → "
                          f"{areas[-1]:.3g} m²")


@app.command()
def canopy(output: Annotated[Path, typer.Option("-o", "--output",
                                                help="field.glb|.obj|.ply|.can")],
           plants: Annotated[int, typer.Option(help="Number of plants.")] = 20,
           rows: Annotated[int, typer.Option(help="Number of rows.")] = 4,
           spacing: Annotated[float, typer.Option(help="Row spacing (m).")] = 0.15,
           density: Annotated[float | None, typer.Option(
               help="Plants per m² (sets the spacing within rows).")] = None,
           preset: Preset = "wheat",
           leaves: Annotated[int, typer.Option(help="Leaves per plant.")] = 6,
           triangles: Annotated[int, typer.Option(help="Triangles per leaf (about).")] = 20,
           age: Annotated[float, typer.Option(help="Plant age in [0, 1].")] = 0.8,
           seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
           as_json: Json = False) -> None:
    """Build a field of plants in rows; report its leaf area index.

    Example: biomorph leaf canopy --plants 200 --rows 10 --spacing 0.15 --seed 1 -o field.glb
    """
    from biomorph._cli import out_console, print_json
    from biomorph.leaf.canopy import (
        FieldSpec,
        PlantSpec,
        build_field,
        field_mesh,
        leaf_area_index,
    )
    from biomorph.leaf.files import write_leaf_mesh
    from biomorph.leaf.shape import check_age

    _check_ext(output, MESH_EXT)
    check_age(age)
    spec = FieldSpec(plants=plants, rows=rows, row_spacing=spacing, density=density,
                     plant=PlantSpec(preset=preset, leaves=leaves, age=age))
    fld = build_field(spec, seed=seed)
    m = field_mesh(fld, triangles_per_leaf=triangles)
    write_leaf_mesh(output, m)
    lai = leaf_area_index(fld, m)
    summary = {"file": str(output), "plants": plants, "leaves": fld.n_leaves,
               "triangles": m.n_faces, "leaf_area_m2": lai * fld.ground_area,
               "ground_area_m2": fld.ground_area, "lai": lai, "seed": seed}
    if as_json:
        print_json(summary)
    else:
        out_console.print(f"wrote {output}: {fld.n_leaves} leaves, {m.n_faces} triangles, "
                          f"LAI {summary['lai']:.3f}")


@app.command("reduce-curve")
def reduce_curve(output: Annotated[Path, typer.Option("-o", "--output", help="curve.png")],
                 preset: Preset = "wheat",
                 points: Annotated[int, typer.Option(help="Discretisation points.")] = 200,
                 leaves: Annotated[int, typer.Option(
                     help="Leaves in the field timed for the time curve.")] = 500,
                 as_json: Json = False) -> None:
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

    table = reduction_curves(LeafShape.from_preset(preset), output, n_points=points,
                             leaves=leaves)
    if as_json:
        print_json({"file": str(output), **table})
    else:
        out_console.print(f"wrote {output}")
