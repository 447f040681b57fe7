"""Pictures: the dataset on PC1/PC2 (the seed's figures 4.5/4.6) and creatures side by side.

Drawn through matplotlib's object API (:class:`matplotlib.figure.Figure`), so no global
backend is chosen for the process and no pyplot state is left behind.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from biomorph.io.atomic import atomic_path

CLASS_COLOURS = {
    "fish": "#1f77b4",
    "amphibian": "#2ca02c",
    "reptile": "#8c564b",
    "bird": "#d62728",
    "mammal": "#9467bd",
}
KIND_COLOURS = {
    "spine": "#555555",
    "skull": "#222222",
    "girdle": "#999999",
    "leg": "#8c564b",
    "arm": "#1f77b4",
    "wing": "#d62728",
    "fin": "#17becf",
}


def _figure(nrows: int, ncols: int, figsize: tuple[float, float], **kwargs):
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def _save(fig, path: str | os.PathLike[str]) -> Path:
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    return Path(path)


def pca_plot(path: str | os.PathLike[str], table=None) -> Path:
    """PNG of the species projected on PC1/PC2, marked by class, wings and legs."""
    from biomorph.creature.dataset import load_species
    from biomorph.creature.pca import fit_dataset

    t = load_species() if table is None else table
    p = fit_dataset(t, reparam=True)  # the PCA the generator samples from
    z = p.scores[:, :2]
    fig, axes = _figure(1, 3, figsize=(15, 4.6))
    cls = np.array(t.cls)
    for c, col in CLASS_COLOURS.items():
        sel = cls == c
        axes[0].scatter(z[sel, 0], z[sel, 1], c=col, label=c, s=28)
    axes[0].set_title("class")
    for w, col, lab in ((0, "#d62728", "no wings"), (1, "#1f77b4", "wings")):
        sel = t.wings == w
        axes[1].scatter(z[sel, 0], z[sel, 1], c=col, label=lab, s=28)
    axes[1].set_title("wings")
    for lg, col in ((0, "#d62728"), (2, "#1f77b4"), (4, "#2ca02c")):
        sel = t.legs == lg
        axes[2].scatter(z[sel, 0], z[sel, 1], c=col, label=f"{lg} legs", s=28)
    axes[2].set_title("legs with ground contact")
    for ax in axes:
        ax.set_xlabel("PC1")
        ax.set_ylabel("PC2")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    for i in range(len(t)):
        axes[0].annotate(t.name[i], z[i], fontsize=5, alpha=0.7)
    return _save(fig, path)


def draw_creature(ax, creature, title: str = "") -> None:
    """Side view (x forward to the right, y up) of the bones with the ground and the COM."""
    start = creature.joint_positions
    end = creature.bone_ends
    for j in range(len(creature)):
        if creature.bone_length[j] <= 0:
            continue
        near = creature.side[j] >= 0
        ax.plot(
            [start[j, 0], end[j, 0]],
            [start[j, 1], end[j, 1]],
            color=KIND_COLOURS.get(creature.kind[j], "k"),
            lw=1.0 + 1.8 * near,
            alpha=1.0 if near else 0.35,
            solid_capstyle="round",
        )
    com = creature.center_of_mass
    ax.plot(com[0], com[1], "o", color="orange", ms=5)
    ax.axhline(0.0, color="#6b8e23", lw=1)
    if len(creature.contacts):
        ax.plot(creature.contacts[:, 0], creature.contacts[:, 1], "v", color="#6b8e23", ms=4)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.tick_params(labelsize=6)


def side_by_side(path: str | os.PathLike[str], creatures: Sequence, titles: Sequence[str]) -> Path:
    """PNG with one side view per creature."""
    n = len(creatures)
    cols = min(n, 3)
    rows = int(np.ceil(n / cols))
    fig, axes = _figure(rows, cols, figsize=(5 * cols, 3.6 * rows), squeeze=False)
    for ax, c, t in zip(axes.ravel(), creatures, titles, strict=False):
        draw_creature(ax, c, t)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    return _save(fig, path)
