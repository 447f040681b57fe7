"""PNG figures: error-vs-triangles and time-vs-triangles of the reduction (the paper's
figure 6), and leaf/canopy previews. Headless matplotlib (Agg); files written atomically."""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from biomorph.core.mesh import Mesh
from biomorph.core.types import PathLike
from biomorph.io.atomic import atomic_path


def _plt():
    """Figure-API stand-in for pyplot (no global backend or state): subplots/figure/close."""
    from biomorph import render

    return render


def _save(fig, path: PathLike) -> Path:
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    _plt().close(fig)
    return Path(path)


def time_vs_triangles(
    shape, budgets: Sequence[int], leaves: int = 500, repeat: int = 3, seed: int = 0
) -> np.ndarray:
    """Seconds to mesh a ``leaves``-leaf field at each per-leaf triangle budget and compute
    its per-triangle light interception proxy (projected area × cos of the sun angle)."""
    from biomorph.leaf.canopy import (
        FieldSpec,
        PlantSpec,
        build_field,
        field_mesh,
        lod_samples,
    )

    spec = FieldSpec(
        plants=max(leaves // 6, 1),
        rows=max(leaves // 60, 1),
        plant=PlantSpec(
            preset=shape.name if shape.name in ("wheat", "maize", "grass") else "wheat",
            leaves=6,
            age=1.0,
        ),
    )
    fld = build_field(spec, seed=seed)
    red = None
    out = []
    for b in budgets:
        best = np.inf
        s = lod_samples(fld.shape, int(b), reduction=red)
        for _ in range(repeat):
            t0 = time.perf_counter()
            m = field_mesh(fld, triangles_per_leaf=int(b), stems=False, s=s)
            n = m.face_normals_unnormalised()
            _ = np.abs(n[:, 2]).sum() * 0.5  # horizontal projected area
            best = min(best, time.perf_counter() - t0)
        out.append(best)
    return np.array(out)


def reduction_curves(
    shape,
    path: PathLike,
    n_points: int = 200,
    budgets: Sequence[int] | None = None,
    leaves: int = 500,
    repeat: int = 3,
) -> dict:
    """Write the two-panel reduction figure; return its numbers as a dict of lists."""
    from biomorph.leaf.reduction import reduce_leaf

    red = reduce_leaf(shape, n_points)
    tri, exy, bound = red.curve()
    if budgets is None:
        budgets = [b for b in (3, 5, 9, 15, 21, 31, 51, 101, 201) if b <= red.full_triangles]
    times = time_vs_triangles(shape, budgets, leaves=leaves, repeat=repeat)
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].loglog(tri, np.maximum(exy, 1e-6), label="midrib error (max distance)")
    ax[0].loglog(tri, np.maximum(bound, 1e-6), "--", label="ε bound (largest removed)")
    ax[0].set_xlabel("triangles per leaf")
    ax[0].set_ylabel("error / leaf length")
    ax[0].set_title(f"{shape.name}: error vs triangles")
    ax[0].legend()
    ax[1].plot(budgets, np.asarray(times) * 1e3, "D-", label=f"mesh + light proxy, {leaves} leaves")
    ax[1].set_xlabel("triangles per leaf")
    ax[1].set_ylabel("time (ms)")
    ax[1].set_title("computation time falls with triangle count")
    ax[1].legend()
    _save(fig, path)
    return {
        "triangles": tri.tolist(),
        "midrib_error": exy.tolist(),
        "bound": bound.tolist(),
        "budgets": list(map(int, budgets)),
        "time_s": np.asarray(times).tolist(),
    }


def mesh_preview(
    meshes: Sequence[Mesh],
    path: PathLike,
    titles: Sequence[str] | None = None,
    elev: float = 20.0,
    azim: float = -60.0,
    same_scale: bool = False,
) -> Path:
    """Render meshes side by side (3-D, flat shading by normal·light), Z-up.

    ``same_scale`` uses one scale for all panels (e.g. a leaf at several ages)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    plt = _plt()
    n = len(meshes)
    fig = plt.figure(figsize=(3.2 * n, 3.6))
    light = np.array([0.3, -0.4, 0.85])
    light /= np.linalg.norm(light)
    common = max(float((m.bounds()[1] - m.bounds()[0]).max()) / 2 for m in meshes)
    for i, m in enumerate(meshes):
        ax = fig.add_subplot(1, n, i + 1, projection="3d")
        tri = np.asarray(m.vertices)[np.asarray(m.faces)]
        shade = 0.35 + 0.65 * np.abs(m.face_normals() @ light)
        col = np.stack([0.15 * shade, 0.55 * shade, 0.12 * shade, np.ones_like(shade)], 1)
        ax.add_collection3d(
            Poly3DCollection(tri, facecolors=col, edgecolors=(0, 0.2, 0, 0.25), linewidths=0.2)
        )
        lo, hi = m.bounds()
        c, r = (lo + hi) / 2, max((hi - lo).max() / 2, 1e-6)
        if same_scale:
            r = max(common, 1e-6)
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[1] - r, c[1] + r)
        ax.set_zlim(c[2] - r, c[2] + r)
        ax.view_init(elev=elev, azim=azim)
        ax.set_axis_off()
        if titles:
            ax.set_title(titles[i], fontsize=9)
    return _save(fig, path)


def light_map(
    mesh: Mesh,
    values: np.ndarray,
    path: PathLike,
    title: str = "",
    label: str = "absorbed PAR (µmol m⁻² s⁻¹)",
) -> Path:
    """False-colour top view of per-triangle ``values`` (painter's order: higher triangles
    drawn last), with a colour bar. Uses matplotlib's ``Figure`` API only (no global
    backend switch)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    tri = mesh.vertices[mesh.faces]
    order = np.argsort(tri[:, :, 2].mean(axis=1))
    vals = np.asarray(values, float)[order]
    fig = Figure(figsize=(7, 6))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    coll = PolyCollection(
        tri[order, :, :2], array=vals, cmap="inferno", edgecolors="none", linewidths=0
    )
    coll.set_clim(0.0, float(np.percentile(vals, 99.5)) if vals.size else 1.0)
    ax.add_collection(coll)
    lo, hi = mesh.vertices[:, :2].min(axis=0), mesh.vertices[:, :2].max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_facecolor((0.35, 0.27, 0.2))  # soil
    ax.set_xlabel("x (m, east)")
    ax.set_ylabel("y (m, north)")
    ax.set_title(title)
    fig.colorbar(coll, ax=ax, label=label)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    return Path(path)


__all__ = ["light_map", "mesh_preview", "reduction_curves", "time_vs_triangles"]
