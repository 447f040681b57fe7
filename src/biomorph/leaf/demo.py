"""``biomorph demo`` section for leaves: ages, plastic bending, LOD levels, a small field.

Uses the built-in presets only (no ``../shared`` data) and runs in a few seconds.
"""

from __future__ import annotations

import time
from pathlib import Path

from biomorph.report import Section, Table


def run_demo(out_dir: str | Path) -> list[Section]:
    """Write leaf pictures and meshes into ``out_dir``; return report sections."""
    from biomorph.leaf.canopy import (
        FieldSpec,
        PlantSpec,
        build_field,
        field_mesh,
        leaf_area_index,
        plant_growth_frames,
    )
    from biomorph.leaf.files import write_leaf_mesh
    from biomorph.leaf.plastic import apply_ops, bend, scale_width
    from biomorph.leaf.plots import mesh_preview, reduction_curves
    from biomorph.leaf.reduction import reduce_leaf, reduced_mesh
    from biomorph.leaf.shape import LeafShape

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sections: list[Section] = []

    # 1. a wheat leaf at several ages (midrib collection interpolated by age)
    wheat = LeafShape.from_preset("wheat")
    ages = [0.1, 0.3, 0.5, 0.75, 1.0]
    meshes = [wheat.mesh(age=a, n_s=40) for a in ages]
    img = mesh_preview(
        meshes,
        out / "leaf_ages.png",
        [f"age {a}" for a in ages],
        elev=15,
        azim=-70,
        same_scale=True,
    )
    rows = [[a, m.n_faces, f"{m.area() * 1e4:.2f}"] for a, m in zip(ages, meshes, strict=True)]
    sections.append(
        Section(
            "Leaf: a growing wheat leaf",
            "Wheat preset (450 digitised So99 midribs, SRSo widths) with the Tremie12 midrib "
            "collection N(age, s) interpolated by age; the visible midrib keeps length l.",
            images=[img],
            tables=[Table(["age", "triangles", "area (cm²)"], rows)],
        )
    )

    # 2. plastic transformation: wind bend + damaged margin, same length
    maize = LeafShape.from_preset("maize")
    bent = apply_ops(maize, [bend(0.25, 0.55, 0.9), scale_width(0.7, 0.8, 0.4)])
    img = mesh_preview(
        [maize.mesh(), bent.mesh()],
        out / "leaf_plastic.png",
        ["maize preset", "bent 0.9 rad on [0.25,0.55], damaged"],
        elev=8,
        azim=-80,
    )
    sections.append(
        Section(
            "Leaf: plastic transformation",
            f"Bending operates on the angle form: midrib length stays {maize.length:.3f} m; "
            f"area {maize.area() * 1e4:.1f} → {bent.area() * 1e4:.1f} cm² (damaged margin).",
            images=[img],
        )
    )

    # 3. LOD levels by the reduction algorithm
    lod_leaf = apply_ops(maize, [bend(0.2, 0.8, 1.6)])
    red = reduce_leaf(lod_leaf, 200)
    budgets = [3, 9, 21, 51, 201]
    lods = [reduced_mesh(lod_leaf, b, reduction=red, n_points=200) for b in budgets]
    img = mesh_preview(lods, out / "leaf_lod.png", [f"{m.n_faces} triangles" for m in lods])
    rows = []
    for b, m in zip(budgets, lods, strict=True):
        k = red.kept(red.removed_for_budget(b))
        exy, er = red.error(k)
        rows.append(
            [b, m.n_faces, k.size, f"{exy:.2e}", f"{er:.2e}", f"{m.area() / lod_leaf.area():.6f}"]
        )
    curve = reduction_curves(lod_leaf, out / "leaf_reduction_curve.png")
    sections.append(
        Section(
            "Leaf: levels of detail (reduction with a correct heap)",
            "Maize leaf bent by 1.6 rad (plastic operator). Points removed in order of "
            "ε = √(ε_xy² + ε_r²) with a lazy-deletion heap; the triangle count equals the budget. "
            "Area column: mesh area over the flat analytic area L·∫r ds; the flat part is kept "
            "exactly, the excess is what twist and undulation add, which coarse levels sample "
            "less.",
            images=[img, out / "leaf_reduction_curve.png"],
            tables=[
                Table(
                    [
                        "budget",
                        "triangles",
                        "points",
                        "midrib err / L",
                        "width err / L",
                        "area / analytic",
                    ],
                    rows,
                ),
                Table(
                    ["triangles per leaf", "time (ms), 500 leaves"],
                    [
                        [b, f"{t * 1e3:.1f}"]
                        for b, t in zip(curve["budgets"], curve["time_s"], strict=True)
                    ],
                    "time vs triangles (paper's figure 6)",
                ),
            ],
        )
    )

    # 4. a small field + growth animation of one plant
    t0 = time.perf_counter()
    spec = FieldSpec(
        plants=36, rows=6, row_spacing=0.18, plant=PlantSpec(preset="wheat", leaves=6, age=0.9)
    )
    fld = build_field(spec, seed=7)
    fm = field_mesh(fld, triangles_per_leaf=21)
    glb = write_leaf_mesh(out / "field.glb", fm)
    can = write_leaf_mesh(out / "field.can", fm)
    lai = leaf_area_index(fld, fm)
    img = mesh_preview([fm], out / "field.png", [f"36 plants, LAI {lai:.2f}"], elev=25)
    frames = plant_growth_frames(PlantSpec(preset="maize", leaves=8), frames=24, seed=1)
    from biomorph.io.gltf import write_gltf

    grow = write_gltf(
        out / "plant_growth.glb",
        None,
        frames=frames,
        frame_time=1 / 12,
        y_up=False,
        name="maize plant growth",
    )
    img2 = mesh_preview(
        [frames[i] for i in (4, 10, 16, 23)],
        out / "plant_growth.png",
        ["frame 4", "frame 10", "frame 16", "frame 23"],
        elev=10,
        same_scale=True,
    )
    sections.append(
        Section(
            "Leaf: a small wheat field and a growing maize plant",
            f"{fld.n_leaves} leaves in distichous phyllotaxy, {fm.n_faces} triangles, LAI "
            f"{lai:.2f}, built and written in {time.perf_counter() - t0:.2f} s. The CARIBU scene "
            "labels every triangle with plant and leaf ids.",
            images=[img, img2],
            files=[glb, can, grow],
        )
    )
    sections.append(_light_section(out))
    return sections


def _light_section(out: Path) -> Section:
    """5. an ADEL-like wheat stand (tables, tillers, senescence) and the light it absorbs."""
    import warnings
    from datetime import datetime

    from biomorph.leaf.light import LightOptions, intercept
    from biomorph.leaf.plant import PlantOptions, build_plant_stand, write_plant_mtg
    from biomorph.leaf.plots import light_map

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh, plants, tile = build_plant_stand(
            PlantOptions(preset="wheat", thermal_time=1000.0, tillers=1),
            plants=12,
            rows=3,
            row_spacing=0.15,
            density=250.0,
            seed=3,
        )
    mtg = write_plant_mtg(out / "stand.mtg", plants)
    res = intercept(mesh, LightOptions(when=datetime(2026, 6, 21, 11, 0), sky=16, ground=tile))
    img = light_map(
        mesh,
        res.absorbed,
        out / "stand_light.png",
        f"absorbed PAR, gap fraction {res.gap_fraction:.2f}",
    )
    s = res.summary()
    rows = [
        [k, f"{v:.4g}" if isinstance(v, float) else v]
        for k, v in s.items()
        if k
        in (
            "triangles",
            "leaves",
            "rays",
            "sun_elevation_deg",
            "gap_fraction",
            "intercepted_fraction",
            "absorbed_par_umol_s",
        )
    ]
    green = sum(p.summary()["green_area_m2"] for p in plants)
    total = sum(p.summary()["leaf_area_m2"] for p in plants)
    return Section(
        "Leaf: an ADEL-like wheat stand and the light it intercepts",
        f"12 plants from the default dimension/phenology tables at 1000 °Cd with one tiller "
        f"each: sheath and internode tubes, leaves at their collars, {100 * green / total:.0f}"
        " % of the blade area green (senescence runs from the tip). Sun on 21 June 11:00 UTC "
        f"at 48.8° N plus a 16-direction overcast sky, periodic ground tile, "
        f"{time.perf_counter() - t0:.1f} s with the MTG written.",
        images=[img],
        tables=[Table(["quantity", "value"], rows)],
        files=[mtg],
    )


__all__ = ["run_demo"]
