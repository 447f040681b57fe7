"""``biomorph creature …``: generate, batch, dataset, annotate."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from biomorph._cli import bounded
from biomorph.errors import ParameterError

app = typer.Typer(
    name="creature",
    no_args_is_help=True,
    add_completion=False,
    help="Procedural vertebrate skeletons (PCA over 44 species, seed 000).",
)


def parse_pc(items: list[str] | None, k: int | None = None) -> dict[int, float] | None:
    """``["1=1.5", "2=-0.8"]`` (1-based component numbers, scores in standard deviations)
    → ``{0: 1.5, 1: -0.8}`` for :attr:`Options.scores`; bad items raise ``ParameterError``."""
    from biomorph.creature import pca as pc
    from biomorph.creature.generator import MAX_SCORE

    if not items:
        return None
    n = pc.N_DIMS if k is None else int(k)
    out: dict[int, float] = {}
    for item in items:
        num, sep, val = str(item).partition("=")
        try:
            i = int(num.strip())
        except ValueError:
            i = None
        if not sep or i is None:
            raise ParameterError(
                f"--pc {item!r}: expected N=SCORE with a component number N "
                f"in 1..{n}, e.g. --pc 1=1.5"
            )
        if not 1 <= i <= n:
            raise ParameterError(f"--pc {item!r}: component number {i} outside 1..{n}")
        try:
            v = float(val)
        except ValueError:
            v = float("nan")
        if not (math.isfinite(v) and abs(v) <= MAX_SCORE):
            raise ParameterError(
                f"--pc {item!r}: score {val.strip()!r} is not a finite number "
                f"in -{MAX_SCORE:g}..{MAX_SCORE:g} standard deviations"
            )
        out[i - 1] = v
    return out


def _options(
    seed,
    legs,
    wings,
    arms,
    centaur,
    weight,
    neck_length,
    tail_length,
    cls,
    k,
    temperature,
    allow_unstable,
    dataset,
    pcs=None,
    allow_extrapolation=False,
    hoof_digits=None,
):
    from biomorph.creature.generator import Options

    if cls is not None:
        cls = cls.strip().lower()
    return Options(
        seed=seed,
        legs=legs,
        wings=wings,
        arms=arms,
        centaur=centaur,
        weight=weight,
        neck_length=neck_length,
        tail_length=tail_length,
        cls=cls,
        k=k,
        temperature=temperature,
        require_stable=not allow_unstable,
        dataset=None if dataset is None else str(dataset),
        scores=parse_pc(pcs, k),
        allow_extrapolation=allow_extrapolation,
        hoof_digits=hoof_digits,
    ).validate()


@app.command()
def generate(
    output: Annotated[
        Path, typer.Option("-o", "--output", help="Output file: .glb .bvh .obj .osim .xml .json")
    ] = Path("creature.glb"),
    seed: Annotated[
        int, typer.Option(help="Random seed (same seed → same creature).", callback=bounded(0))
    ] = 0,
    legs: Annotated[
        int | None,
        typer.Option(help="Legs with ground contact: 0, 2, 4 or 6.", callback=bounded(0, 6)),
    ] = None,
    wings: Annotated[
        bool | None, typer.Option("--wings/--no-wings", help="Force wings on or off.")
    ] = None,
    arms: Annotated[bool, typer.Option("--arms", help="Add a pair of arms.")] = False,
    centaur: Annotated[
        bool,
        typer.Option(
            "--centaur",
            help="Extra girdle with arms below the head (lengthens the neck if needed).",
        ),
    ] = False,
    weight: Annotated[
        float | None,
        typer.Option(
            help="Body weight in kg (the dataset spans 0.01..120000 kg; up to 10× beyond).",
            callback=bounded(0, lo_open=True),
        ),
    ] = None,
    allow_extrapolation: Annotated[
        bool,
        typer.Option(
            "--allow-extrapolation",
            help="Accept a weight more than 10× outside the dataset's range.",
        ),
    ] = False,
    neck_length: Annotated[
        float | None,
        typer.Option(
            help="Neck chord in frame units (1 = the skeleton's largest extent).",
            callback=bounded(0, 1.5),
        ),
    ] = None,
    tail_length: Annotated[
        float | None, typer.Option(help="Tail chord in frame units.", callback=bounded(0, 1.5))
    ] = None,
    cls: Annotated[
        str | None, typer.Option("--class", help="fish, amphibian, reptile, bird or mammal.")
    ] = None,
    hoof_digits: Annotated[
        int | None,
        typer.Option(
            "--hoof-digits",
            help="Hoofed mammal on 1 digit (perissodactyl: horse) or 2 (artiodactyl: cattle, "
            "deer); default: from the nearest species.",
            callback=bounded(1, 2),
        ),
    ] = None,
    k: Annotated[
        int | None,
        typer.Option(help="Sample from the top k PCA components.", callback=bounded(1, 29)),
    ] = None,
    temperature: Annotated[
        float, typer.Option(help="Variance scale of sampling.", callback=bounded(0))
    ] = 1.0,
    pc: Annotated[
        list[str] | None,
        typer.Option(
            "--pc",
            help="Fix a PCA component score: N=SCORE, N counted from 1 (PC1 = largest "
            "variance), SCORE in standard deviations, -4..4; repeatable.",
        ),
    ] = None,
    bone_shape: Annotated[
        str, typer.Option(help="bone (procedural bone models) or box (the seed's boxes) (glb/obj).")
    ] = "bone",
    lod: Annotated[int, typer.Option(help="Bone-model level of detail 0, 1 or 2.")] = 1,
    skin: Annotated[
        bool,
        typer.Option(
            "--skin",
            help="Add the body envelope (muscles + skin surface, smoothly skinned) (glb/obj).",
        ),
    ] = False,
    walk: Annotated[
        bool, typer.Option("--walk", help="Add a procedural walk cycle (glb/bvh).")
    ] = False,
    rigify: Annotated[
        bool,
        typer.Option(
            "--rigify",
            help="glb: a Rigify metarig (connected "
            "chains, heel/toe, rig types; finish it in Blender "
            "with `biomorph creature rigify-setup`); other "
            "formats: Rigify-style names only.",
        ),
    ] = False,
    settle: Annotated[
        bool,
        typer.Option(
            "--settle",
            help="Also let MuJoCo settle the creature for 2 s and report whether it tips.",
        ),
    ] = False,
    allow_unstable: Annotated[
        bool, typer.Option("--allow-unstable", help="Do not repair/resample.")
    ] = False,
    dataset: Annotated[Path | None, typer.Option(help="Species CSV (default: built-in).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Generate one creature and write it.

    Example: biomorph creature generate --seed 7 --legs 4 --no-wings -o horse.glb
    (``--pc 1=1.5 --pc 2=-0.8`` fixes the first two PCA component scores.)
    """
    from biomorph._cli import out_console, print_json
    from biomorph.creature.exporters import check_extension, export
    from biomorph.creature.generator import Generator
    from biomorph.creature.mesh import SHAPES

    check_extension(output)
    if rigify and legs == 0:
        raise ParameterError(
            "--rigify with --legs 0: a Rigify metarig needs legs (its leg "
            "chains carry the IK and the root); drop --rigify or ask for legs"
        )
    if bone_shape not in SHAPES:
        raise ParameterError(f"--bone-shape {bone_shape!r}; expected one of {', '.join(SHAPES)}")
    if lod not in (0, 1, 2):
        raise ParameterError(f"--lod {lod}; expected 0, 1 or 2")
    opts = _options(
        seed,
        legs,
        wings,
        arms,
        centaur,
        weight,
        neck_length,
        tail_length,
        cls,
        k,
        temperature,
        allow_unstable,
        dataset,
        pc,
        allow_extrapolation,
        hoof_digits,
    )
    creature = Generator(opts).run()
    summary = creature.summary()
    if settle:
        from biomorph.io.mjcf import settle as _settle

        summary["mujoco_settle"] = _settle(creature)
    path = export(
        creature, output, bone_shape=bone_shape, walk=walk, rigify=rigify, lod=lod, skin=skin
    )
    summary["output"] = str(path)
    if as_json:
        print_json(summary)
    else:
        out_console.print(
            f"wrote {path}: {summary['class']}, {summary['legs']} legs, "
            f"{summary['joints']} joints, {summary['mass_kg']} kg, "
            f"{summary['height_m']} m tall, stable={summary['stable']}"
        )


def _batch_item(item: dict) -> dict:
    """Generate and write one chunk of seeds (module level so dask can pickle it)."""
    from biomorph.creature.exporters import export
    from biomorph.creature.generator import Generator, Options

    out = Path(item["out"])
    stats = {"n": 0, "stable": 0, "joints": 0}
    for seed in item["seeds"]:
        c = Generator(Options(seed=seed)).run()
        # batch keeps the seed's boxes (its 10,000-creature throughput figure); bone models
        # cost ~25 ms more per creature (bench/gltf.py --creatures)
        export(c, out / f"creature_{seed:06d}{item['ext']}", bone_shape="box")
        stats["n"] += 1
        stats["stable"] += int(c.balance is None or not c.balance.applicable or c.balance.stable)
        stats["joints"] += len(c)
    return stats


@app.command()
def batch(
    count: Annotated[int, typer.Option(help="Number of creatures.", callback=bounded(1))] = 100,
    out: Annotated[Path, typer.Option(help="Output folder.")] = Path("creatures"),
    fmt: Annotated[str, typer.Option("--format", help="glb, bvh, obj, osim, xml or json.")] = "glb",
    seed_start: Annotated[int, typer.Option(help="First seed.", callback=bounded(0))] = 0,
    chunk: Annotated[int, typer.Option(help="Creatures per task.", callback=bounded(1))] = 100,
    workers: Annotated[
        int | None, typer.Option(help="Worker processes (0 = serial).", callback=bounded(0))
    ] = None,
    scheduler: Annotated[str | None, typer.Option(help="Dask scheduler address.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Generate many creatures in parallel on dask.distributed (resumable).

    Example: biomorph creature batch --count 10000 --out creatures --workers 2
    """
    from biomorph._cli import out_console, print_json
    from biomorph.creature.exporters import check_extension
    from biomorph.scale.batch import run_batch

    ext = check_extension(f"x.{fmt.lstrip('.')}")
    if count < 1:
        raise ParameterError(f"--count {count}; expected at least 1")
    if chunk < 1:
        raise ParameterError(f"--chunk {chunk}; expected at least 1")
    seeds = list(range(seed_start, seed_start + count))
    items = [
        {"seeds": seeds[i : i + chunk], "out": str(out), "ext": ext} for i in range(0, count, chunk)
    ]
    out.mkdir(parents=True, exist_ok=True)
    report = run_batch(
        items,
        _batch_item,
        out_dir=out,
        key=lambda it: f"{it['seeds'][0]:06d}-{it['seeds'][-1]:06d}",
        workers=workers,
        scheduler=scheduler,
        description="creatures",
    )
    made = sum(r["n"] for r in report.results.values())
    stable = sum(r["stable"] for r in report.results.values())
    summary = {
        "count": made,
        "stable": stable,
        "failed_chunks": len(report.failed),
        "skipped_chunks": len(report.skipped),
        "seconds": round(report.seconds, 2),
        "out": str(out),
        "format": ext,
    }
    if as_json:
        print_json(summary)
    else:
        out_console.print(
            f"{made} creatures in {report.seconds:.1f} s → {out} "
            f"({len(report.failed)} failed chunks)"
        )
    if report.failed:
        raise typer.Exit(1)


@app.command()
def dataset(
    plot: Annotated[Path | None, typer.Option(help="Write the PC1/PC2 plot (PNG).")] = None,
    path: Annotated[Path | None, typer.Option("--dataset", help="Species CSV.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """List the species dataset and the PCA spectrum beside the seed's.

    Example: biomorph creature dataset --plot pca.png
    """
    from biomorph._cli import check_suffix, out_console, print_json
    from biomorph.creature.model import species_model
    from biomorph.creature.pca import SEED_SPECTRUM, spectrum_summary

    if plot is not None:
        check_suffix(plot, (".png",), "--plot")
    model = species_model(None if path is None else str(path))
    table = model.table
    ours = spectrum_summary(model.pca)  # the PCA the generator samples from
    if plot is not None:
        from biomorph.creature.plots import pca_plot

        pca_plot(plot, table)
    rows = [
        {
            "name": table.name[i],
            "class": table.cls[i],
            "weight_kg": float(table.weight[i]),
            "wings": int(table.wings[i]),
            "legs": int(table.legs[i]),
            "vertebrae": table.counts[i].tolist(),
        }
        for i in range(len(table))
    ]
    if as_json:
        print_json(
            {
                "species": rows,
                "spectrum": ours,
                "seed_spectrum": SEED_SPECTRUM,
                "plot": None if plot is None else str(plot),
            }
        )
        return
    from rich.table import Table

    t = Table(title=f"{len(table)} species")
    for h in ("name", "class", "kg", "wings", "legs", "C/T/Ca"):
        t.add_column(h)
    for r in rows:
        t.add_row(
            r["name"],
            r["class"],
            f"{r['weight_kg']:g}",
            str(r["wings"]),
            str(r["legs"]),
            "/".join(map(str, r["vertebrae"])),
        )
    out_console.print(t)
    out_console.print(
        f"PCA sampled by the generator (neck/tail as offsets, seed §4.5): first "
        f"eigenvalue {ours['first']:.3f} of {ours['total']:.3f} (seed 0.349 of "
        f"0.583); six components {ours['six_components']:.1%} (seed 92.2%)"
    )


@app.command()
def annotate(
    svg: Annotated[Path, typer.Argument(help="Inkscape SVG with named paths.")],
    name: Annotated[str | None, typer.Option(help="Species name (default: file stem).")] = None,
    cls: Annotated[str, typer.Option("--class", help="Animal class.")] = "mammal",
    weight: Annotated[
        float, typer.Option(help="Weight in kg.", callback=bounded(0, lo_open=True))
    ] = 1.0,
    wings: Annotated[bool, typer.Option("--wings/--no-wings")] = False,
    legs: Annotated[
        int, typer.Option(help="Legs with ground contact: 0, 2 or 4.", callback=bounded(0, 4))
    ] = 4,
    out: Annotated[
        Path,
        typer.Option(
            "--dataset", help="Species CSV to append to (created from the built-in 44 if absent)."
        ),
    ] = Path("species.csv"),
    as_json: Annotated[bool, typer.Option("--json", help="Print the parsed row.")] = False,
) -> None:
    """Read an annotated side view (paths neck, back, tail, upper_arm, …) and append it.

    Example: biomorph creature annotate okapi.svg --class mammal --weight 250 --dataset my.csv
    """
    from biomorph._cli import out_console, print_json
    from biomorph.creature.dataset import append_species
    from biomorph.creature.dataset.annotations import species_row

    row = species_row(svg, name=name or svg.stem, cls=cls, weight=weight, wings=wings, legs=legs)
    path = append_species(out, row)
    if as_json:
        print_json({"row": row, "dataset": str(path)})
    else:
        out_console.print(f"appended {row['name']} to {path}")


@app.command()
def render(
    output: Annotated[Path, typer.Option("-o", "--output", help="PNG to write.")] = Path(
        "creature.png"
    ),
    seed: Annotated[int, typer.Option(help="Random seed (same seed → same creature).")] = 0,
    legs: Annotated[
        int | None, typer.Option(help="Legs with ground contact: 0, 2, 4 or 6.")
    ] = None,
    wings: Annotated[
        bool | None, typer.Option("--wings/--no-wings", help="Force wings on or off.")
    ] = None,
    weight: Annotated[float | None, typer.Option(help="Body weight in kg.")] = None,
    cls: Annotated[
        str | None, typer.Option("--class", help="fish, amphibian, reptile, bird or mammal.")
    ] = None,
    view: Annotated[
        list[str] | None,
        typer.Option(
            "--view",
            help="side, three_quarter, front or top; repeatable (default: side and three_quarter).",
        ),
    ] = None,
    bone_shape: Annotated[str, typer.Option(help="bone or box.")] = "bone",
    lod: Annotated[int, typer.Option(help="Bone-model level of detail 0, 1 or 2.")] = 1,
    skin: Annotated[
        bool, typer.Option("--skin/--no-skin", help="Also draw muscles and the body envelope.")
    ] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Shaded 3-D pictures (side and three-quarter) of a creature's skeleton and skin.

    Example: biomorph creature render --seed 7 --legs 4 -o horse.png
    """
    from biomorph._cli import check_suffix, out_console, print_json
    from biomorph.creature.generator import Generator
    from biomorph.creature.mesh import SHAPES
    from biomorph.creature.render import VIEWS, render_creature

    check_suffix(output, (".png",), "--output")
    views = tuple(view or ("side", "three_quarter"))
    for v in views:
        if v not in VIEWS:
            raise ParameterError(f"--view {v!r}; expected one of {', '.join(VIEWS)}")
    if bone_shape not in SHAPES:
        raise ParameterError(f"--bone-shape {bone_shape!r}; expected one of {', '.join(SHAPES)}")
    if lod not in (0, 1, 2):
        raise ParameterError(f"--lod {lod}; expected 0, 1 or 2")
    opts = _options(
        seed, legs, wings, False, False, weight, None, None, cls, None, 1.0, False, None, None
    )
    creature = Generator(opts).run()
    s = creature.summary()
    path = render_creature(
        creature,
        output,
        views=views,
        shape=bone_shape,
        lod=lod,
        skin=skin,
        title=f"seed {seed}: {s['class']}, {s['legs']} legs, {s['mass_kg']:.3g} kg",
    )
    summary = {**s, "output": str(path), "views": list(views)}
    if as_json:
        print_json(summary)
    else:
        out_console.print(f"wrote {path}: {s['class']}, {len(views)} views, skin={skin}")


@app.command("rigify-setup")
def rigify_setup(
    output: Annotated[
        Path | None,
        typer.Option("-o", "--output", help="Write the script here (.py) instead of printing it."),
    ] = None,
) -> None:
    """Print (or write) the Blender script that turns a ``--rigify`` GLB into a Rigify metarig.

    Example: biomorph creature rigify-setup -o setup.py && blender -b --python setup.py --
    horse.glb --generate --save horse_rig.blend
    """
    from biomorph._cli import check_suffix, out_console
    from biomorph.creature.rigify_setup import script

    if output is None:
        print(script(), end="")
        return
    from biomorph.io.atomic import write_text

    check_suffix(output, (".py",), "--output")
    out_console.print(f"wrote {write_text(output, script())}")
