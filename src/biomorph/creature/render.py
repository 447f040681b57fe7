"""Shaded 3-D pictures of creatures: skeleton (bone models) and body envelope.

A small software renderer over matplotlib's 2-D :class:`~matplotlib.collections.
PolyCollection`: orthographic camera, back faces culled, triangles drawn far to near
(painter's algorithm), Lambert shading ``ambient + diffuse · max(0, n · l)`` with a key
light over the camera's shoulder. The envelope is drawn translucent over the bones
(an x-ray look) or on its own. Views: ``side`` (the creature's right side, head to the
right) and ``three_quarter`` (35° round to the front, 20° from above). Drawn through the
``Figure`` API only (no pyplot state, no global backend).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from biomorph.creature.creature import Creature
from biomorph.errors import ParameterError

#: (azimuth about +Y from the side view towards the head, elevation) in degrees
VIEWS = {
    "side": (0.0, 0.0),
    "three_quarter": (35.0, 20.0),
    "front": (90.0, 10.0),
    "top": (0.0, 89.0),
}
BONE_RGB = np.array([0.90, 0.86, 0.78])
SKIN_RGB = np.array([0.80, 0.56, 0.46])
MUSCLE_RGB = np.array([0.72, 0.26, 0.24])
AMBIENT = 0.28


@dataclass(frozen=True)
class Layer:
    """One mesh to draw: world vertices ``(n, 3)``, faces ``(m, 3)``, colour and opacity."""

    vertices: NDArray
    faces: NDArray
    rgb: NDArray
    alpha: float = 1.0
    cull: bool = True
    #: optional vertex normals ``(n, 3)``: a face is shaded by the mean of its corners'
    #: normals (smooth surfaces read smooth, not as their triangles)
    normals: NDArray | None = None


def _camera(view: str) -> tuple[NDArray, NDArray, NDArray]:
    if view not in VIEWS:
        raise ParameterError(f"view {view!r} unknown; expected one of {', '.join(VIEWS)}")
    az, el = np.radians(VIEWS[view])
    back = np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])
    right = np.cross([0.0, 1.0, 0.0], back)
    if np.linalg.norm(right) < 1e-6:
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    return right, up, back


def _shade(layer: Layer, right: NDArray, up: NDArray, back: NDArray):
    v, f = np.asarray(layer.vertices, float), np.asarray(layer.faces, np.int64)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 0
    n = n[ok] / norm[ok, None]
    tri = tri[ok]
    if layer.normals is not None:  # smooth shading: the corners' normals averaged
        vn = np.asarray(layer.normals, float)[f[ok]].sum(axis=1)
        vl = np.linalg.norm(vn, axis=1)
        smooth = np.where((vl > 1e-12)[:, None], vn / np.maximum(vl, 1e-12)[:, None], n)
    else:
        smooth = n
    facing = n @ back
    if layer.cull:
        keep = facing > 0
        tri, n, smooth, facing = tri[keep], n[keep], smooth[keep], facing[keep]
    else:
        smooth = np.where(facing[:, None] < 0, -smooth, smooth)
    n = smooth
    light = back + 0.9 * up + 0.4 * right
    light /= np.linalg.norm(light)
    lam = AMBIENT + (1 - AMBIENT) * np.clip(n @ light, 0.0, 1.0)
    rgb = np.clip(layer.rgb[None, :] * lam[:, None], 0, 1)
    rgba = np.concatenate([rgb, np.full((len(rgb), 1), layer.alpha)], axis=1)
    xy = np.stack([tri @ right, tri @ up], axis=-1)
    depth = (tri @ back).mean(axis=1)
    return xy, rgba, depth


def draw(ax, layers: Sequence[Layer], view: str, ground: bool = True) -> None:
    """Draw ``layers`` on a matplotlib axes in ``view`` (all layers depth-sorted together)."""
    from matplotlib.collections import LineCollection, PolyCollection

    right, up, back = _camera(view)
    parts = [_shade(layer, right, up, back) for layer in layers]
    xy = np.concatenate([p[0] for p in parts]) if parts else np.zeros((0, 3, 2))
    rgba = np.concatenate([p[1] for p in parts]) if parts else np.zeros((0, 4))
    depth = np.concatenate([p[2] for p in parts]) if parts else np.zeros(0)
    order = np.argsort(depth, kind="stable")  # far first
    ax.add_collection(
        PolyCollection(xy[order], facecolors=rgba[order], edgecolors=rgba[order], linewidths=0.15)
    )
    if len(xy):
        lo, hi = xy.reshape(-1, 2).min(axis=0), xy.reshape(-1, 2).max(axis=0)
        pad = 0.05 * max(hi - lo)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        if ground and VIEWS[view][1] < 60:
            allv = np.concatenate([np.asarray(layer.vertices) for layer in layers])
            a, b = allv.min(axis=0), allv.max(axis=0)
            ext = 0.6 * (b - a)
            c = 0.5 * (a + b)
            ring = np.array(
                [
                    [c[0] - ext[0], 0, c[2] - ext[2]],
                    [c[0] + ext[0], 0, c[2] - ext[2]],
                    [c[0] + ext[0], 0, c[2] + ext[2]],
                    [c[0] - ext[0], 0, c[2] + ext[2]],
                    [c[0] - ext[0], 0, c[2] - ext[2]],
                ]
            )
            seg = np.stack([ring @ right, ring @ up], axis=-1)
            ax.add_collection(
                LineCollection([seg], colors=[(0.5, 0.5, 0.5, 0.6)], linewidths=0.8, zorder=0)
            )
    ax.set_aspect("equal")
    ax.set_axis_off()


def creature_layers(
    c: Creature,
    *,
    shape: str = "bone",
    lod: int = 1,
    skin: bool = False,
    muscles: bool = False,
    skeleton: bool = True,
) -> list[Layer]:
    """Layers for ``c``: bone models, optionally muscles and the body envelope."""
    layers = []
    if skeleton:
        from biomorph.creature.bones import world_mesh

        m = world_mesh(c, shape, lod)
        layers.append(Layer(m.vertices, m.faces, BONE_RGB))
    if muscles or skin:
        from biomorph.creature.skin import body

        b = body(c, lod=lod)
        if muscles and b.muscles is not None:
            layers.append(
                Layer(
                    b.muscles.vertices,
                    b.muscles.faces,
                    MUSCLE_RGB,
                    0.85 if skeleton else 1.0,
                    normals=b.muscles.normals,
                )
            )
        if skin:
            env = b.envelope
            layers.append(
                Layer(
                    env.vertices,
                    env.faces,
                    SKIN_RGB,
                    0.38 if skeleton else 1.0,
                    normals=env.normals,
                )
            )
    return layers


def render_creature(
    c: Creature,
    path: str | os.PathLike[str],
    *,
    views: Sequence[str] = ("side", "three_quarter"),
    shape: str = "bone",
    lod: int = 1,
    skin: bool = True,
    title: str | None = None,
    width_in: float = 5.0,
) -> Path:
    """PNG with one row per picture (skeleton; skeleton + muscles under a translucent
    envelope; the envelope alone when ``skin``) and one column per view."""
    from biomorph.creature.plots import _figure, _save

    rows = [creature_layers(c, shape=shape, lod=lod)]
    labels = ["skeleton"]
    if skin:
        rows.append(creature_layers(c, shape=shape, lod=lod, skin=True, muscles=True))
        rows.append(creature_layers(c, shape=shape, lod=lod, skin=True, skeleton=False))
        labels += ["skeleton, muscles, skin", "skin"]
    fig, axes = _figure(
        len(rows), len(views), (width_in * len(views), 3.6 * len(rows)), squeeze=False
    )
    for r, layers in enumerate(rows):
        for k, view in enumerate(views):
            draw(axes[r][k], layers, view)
            axes[r][k].set_title(f"{labels[r]} — {view.replace('_', '-')}", fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def render_set(
    creatures: Sequence[Creature],
    titles: Sequence[str],
    path: str | os.PathLike[str],
    *,
    view: str = "three_quarter",
    shape: str = "bone",
    skin: bool = False,
    width_in: float = 4.0,
    lod: int = 0,
) -> Path:
    """PNG grid: one shaded picture per creature (skeleton, optionally under its skin)."""
    from biomorph.creature.plots import _figure, _save

    n = len(creatures)
    cols = min(3, max(n, 1))
    rows = (n + cols - 1) // cols
    fig, axes = _figure(rows, cols, (width_in * cols, 3.2 * rows), squeeze=False)
    for i in range(rows * cols):
        ax = axes[i // cols][i % cols]
        if i >= n:
            ax.set_axis_off()
            continue
        draw(ax, creature_layers(creatures[i], shape=shape, lod=lod, skin=skin, muscles=skin), view)
        ax.set_title(titles[i], fontsize=9)
    return _save(fig, path)
