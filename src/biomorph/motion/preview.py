"""Animated previews of a clip: ``.gif`` (Pillow writer, always available) or ``.mp4``
(ffmpeg, only when the ``ffmpeg`` executable is on PATH — Debian: ``apt-get install ffmpeg``).

The skeleton is drawn as bone segments in a side view that turns slowly about the vertical
(a turntable: one full turn over the clip), following the root horizontally so a walk stays
in frame. At most ``max_frames`` frames are drawn (every k-th frame, the playback rate
lowered to match, so the preview lasts as long as the clip). Drawn through matplotlib's
``Figure`` API only (no global backend); written atomically.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from biomorph.core.motion import Motion
from biomorph.errors import ParameterError, UnsupportedFormatError
from biomorph.io.atomic import atomic_path

FORMATS = (".gif", ".mp4")


def render_preview(
    motion: Motion,
    path: str | os.PathLike[str],
    max_frames: int = 120,
    turns: float = 1.0,
    size_px: int = 320,
    up: str | None = None,
) -> Path:
    """Write an animated preview of ``motion`` to ``path`` (.gif or .mp4)."""
    from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    p = Path(path)
    ext = p.suffix.lower()
    if ext not in FORMATS:
        raise UnsupportedFormatError(
            f"--preview {p}: extension {ext or '(none)'!r}; expected .gif or .mp4"
        )
    if ext == ".mp4" and shutil.which("ffmpeg") is None:
        raise UnsupportedFormatError(
            f"--preview {p}: MP4 needs ffmpeg (apt-get install ffmpeg); write a .gif instead"
        )
    if not (isinstance(max_frames, int) and 1 <= max_frames <= 100000):
        raise ParameterError(f"max_frames {max_frames!r}; expected an integer 1..100000")
    step = max(1, int(np.ceil(motion.n_frames / max_frames)))
    frames = np.arange(0, motion.n_frames, step)
    w = motion.world_positions(frames)
    ui = "xyz".index((up or motion.meta.get("up_guess") or "y").lower())
    h1, h2 = (ui + 1) % 3, (ui + 2) % 3
    par = motion.skeleton.parent
    bones = np.flatnonzero(par >= 0)
    centre = w[:, 0].copy()
    theta = 2 * np.pi * turns * np.arange(frames.size) / max(frames.size, 1)
    height = float(np.ptp(w[..., ui])) or 1.0
    fig = Figure(figsize=(size_px / 80, size_px / 80), dpi=80)
    ax = fig.add_subplot(1, 1, 1)
    ax.set_aspect("equal")
    ax.set_axis_off()
    lo = float(w[..., ui].min())
    ax.set_xlim(-0.75 * height, 0.75 * height)
    ax.set_ylim(lo - 0.05 * height, lo + 1.1 * height)
    ax.axhline(lo, color="0.7", lw=1)
    lines = LineCollection([], colors="tab:blue", linewidths=2)
    ax.add_collection(lines)
    title = ax.set_title("", fontsize=8)

    def draw(k: int):
        c, s = np.cos(theta[k]), np.sin(theta[k])
        x = (w[k, :, h1] - centre[k, h1]) * c + (w[k, :, h2] - centre[k, h2]) * s
        y = w[k, :, ui]
        segs = np.stack(
            [
                np.column_stack([x[par[bones]], y[par[bones]]]),
                np.column_stack([x[bones], y[bones]]),
            ],
            axis=1,
        )
        lines.set_segments(segs)
        title.set_text(f"frame {frames[k]} / {motion.n_frames - 1}")
        return lines, title

    fps = max(1.0, motion.fps / step)
    anim = FuncAnimation(fig, draw, frames=frames.size, blit=False)
    writer = PillowWriter(fps=fps) if ext == ".gif" else FFMpegWriter(fps=fps)
    with atomic_path(p) as tmp:
        anim.save(os.fspath(tmp), writer=writer)
    return p


__all__ = ["render_preview", "FORMATS"]
