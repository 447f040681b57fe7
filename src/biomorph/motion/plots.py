"""PNG figures for MotionLab (matplotlib, headless, written atomically).

* :func:`plot_bands` – a channel and its frequency bands (the seed's figures 7–12), with the
  equalized result on top.
* :func:`plot_blend` – blend weights per clip over the output timeline and a channel of
  each clip and of the result.
* :func:`plot_speed` – speed curve and the resulting time warp.
* :func:`plot_cycle` – a channel of the looped clip over several cycles with seams marked.
* :func:`plot_poses` – stick-figure strip of poses (side view) for one or more motions.
* :func:`plot_contacts` – per foot point, height and horizontal speed (body scales) with the
  detected contacts and the foot-skate metric's band, before and after locking.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from biomorph.core.motion import Motion
from biomorph.io.atomic import atomic_path


def _plt():
    """Figure-API stand-in for pyplot (no global backend or state): subplots/figure/close."""
    from biomorph import render

    return render


def _save(fig, path: str | os.PathLike[str]) -> Path:
    plt = _plt()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
    return Path(path)


def plot_bands(
    signal: ArrayLike,
    path: str | os.PathLike[str],
    levels: int = 4,
    fps: float = 1.0,
    gains: ArrayLike | None = None,
    title: str = "channel",
    unit: str = "deg",
) -> Path:
    """Channel ``signal`` (f,) and its ``levels`` band-pass bands plus the low-pass rest;
    with ``gains`` the equalized signal is drawn over the original."""
    from biomorph.motion.equalizer import bands, equalize_signal

    plt = _plt()
    x = np.asarray(signal, dtype=float).reshape(-1)
    b = bands(x, levels)
    t = np.arange(x.size) / fps
    fig, axes = plt.subplots(levels + 2, 1, figsize=(9, 1.4 * (levels + 2)), sharex=True)
    axes[0].plot(t, x, color="0.3", lw=1.2, label="original")
    if gains is not None:
        axes[0].plot(
            t,
            equalize_signal(x, gains),
            color="C3",
            lw=1.0,
            label="equalized, gains " + ", ".join(f"{g:g}" for g in np.asarray(gains, float)),
        )
    axes[0].legend(loc="upper right", fontsize=7)
    axes[0].set_title(title, fontsize=9)
    names = [f"band {k + 1} (L{k}{', noise' if k == 0 else ''})" for k in range(levels)]
    names.append(f"band {levels + 1} (G{levels}, main motion)")
    for k in range(levels + 1):
        axes[k + 1].plot(t, b[k], color=f"C{k}", lw=0.9)
        axes[k + 1].set_ylabel(names[k], fontsize=7, rotation=0, ha="right", va="center")
        axes[k + 1].tick_params(labelsize=7)
    axes[-1].set_xlabel("seconds" if fps != 1.0 else "frame", fontsize=8)
    fig.supylabel(unit, fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def plot_blend(
    weights: ArrayLike,
    channels: Sequence[ArrayLike],
    result: ArrayLike,
    path: str | os.PathLike[str],
    labels: Sequence[str] | None = None,
    title: str = "blend",
) -> Path:
    """Blend weights ``(f, N)`` and a channel of every clip (on the output timeline) and of
    the result."""
    plt = _plt()
    w = np.asarray(weights, float)
    labels = list(labels or [f"clip {i}" for i in range(w.shape[1])])
    fig, (a0, a1) = plt.subplots(2, 1, figsize=(9, 4.5), sharex=True)
    for i in range(w.shape[1]):
        a0.plot(w[:, i], label=f"weight {labels[i]}")
        a1.plot(np.asarray(channels[i], float), lw=0.8, alpha=0.7, label=labels[i])
    a1.plot(np.asarray(result, float), color="k", lw=1.4, label="result")
    a0.set_ylabel("weight")
    a0.set_title(title, fontsize=9)
    a0.legend(fontsize=7)
    a1.legend(fontsize=7)
    a1.set_xlabel("output frame")
    fig.tight_layout()
    return _save(fig, path)


def plot_speed(
    speed: ArrayLike,
    t_src: ArrayLike,
    path: str | os.PathLike[str],
    title: str = "speed curve",
    original: ArrayLike | None = None,
    result: ArrayLike | None = None,
) -> Path:
    """Speed curve over original frames and the resulting time warp (output frame → source
    frame); with ``original``/``result`` channels a third panel shows the retimed signal."""
    plt = _plt()
    s = np.asarray(speed, float)
    panels = 3 if original is not None and result is not None else 2
    fig, axes = plt.subplots(1, panels, figsize=(4.5 * panels, 3.2))
    a0, a1 = axes[0], axes[1]
    if panels == 3:
        axes[2].plot(np.asarray(original, float), color="0.6", lw=1.0, label="original")
        axes[2].plot(np.asarray(result, float), color="C3", lw=1.2, label="retimed")
        axes[2].set_xlabel("frame")
        axes[2].legend(fontsize=7)
    a0.plot(s, color="C1")
    a0.axhline(1.0, color="0.7", lw=0.8)
    a0.set_xlabel("original frame")
    a0.set_ylabel("speed (1 = original)")
    a0.set_title(title, fontsize=9)
    ts = np.asarray(t_src, float)
    a1.plot(ts, color="C0", label="time warp")
    a1.plot(np.arange(ts.size), color="0.7", lw=0.8, ls="--", label="identity")
    a1.set_xlabel("output frame")
    a1.set_ylabel("source frame")
    a1.legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path)


def plot_cycle(
    original: ArrayLike,
    looped: ArrayLike,
    period: int,
    path: str | os.PathLike[str],
    title: str = "cycle",
) -> Path:
    """A channel of the source range and of the looped result; seams marked."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(9, 3.2))
    ax.plot(np.asarray(original, float), color="0.6", lw=1.0, label="source range")
    y = np.asarray(looped, float)
    ax.plot(y, color="C2", lw=1.3, label="loop (several cycles)")
    for s in range(period, y.size, period):
        ax.axvline(s - 0.5, color="C3", lw=0.8, ls=":")
    ax.set_xlabel("frame")
    ax.set_title(title + " (dotted: seams)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path)


def plot_poses(
    motions: Sequence[tuple[str, Motion]],
    frames: Sequence[int],
    path: str | os.PathLike[str],
    up: str = "y",
    title: str = "poses",
) -> Path:
    """Stick figures (side view: forward axis horizontal, up vertical) of ``frames`` for
    each ``(label, motion)`` — one row per motion, poses side by side."""
    plt = _plt()
    ui = "xyz".index(up)
    rows = len(motions)
    fig, axes = plt.subplots(
        rows, 1, figsize=(min(2.0 + 1.3 * len(frames), 14), 2.4 * rows), squeeze=False
    )
    for r, (label, m) in enumerate(motions):
        ax = axes[r, 0]
        fr = [min(max(int(f), 0), m.n_frames - 1) for f in frames]
        w = m.world_positions(np.asarray(fr))
        # horizontal axis: the one the root moves along most (or z)
        travel = np.ptp(m.root_position, axis=0)
        travel[ui] = -1
        hi = int(np.argmax(travel)) if travel.max() > 1e-9 else (2 if ui != 2 else 0)
        span = float(np.ptp(w[..., ui]) or 1.0)
        for k, p in enumerate(w):
            shift = k * 0.9 * span - p[0, hi]
            for j in range(1, m.n_joints):
                par = m.skeleton.parent[j]
                if par < 0:
                    continue
                ax.plot(
                    [p[par, hi] + shift, p[j, hi] + shift],
                    [p[par, ui], p[j, ui]],
                    color=f"C{r}",
                    lw=1.2,
                )
            ax.text(
                p[0, hi] + shift,
                float(w[..., ui].min()) - 0.08 * span,
                str(fr[k]),
                fontsize=6,
                ha="center",
            )
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(label, fontsize=8, loc="left")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


__all__ = ["plot_bands", "plot_blend", "plot_speed", "plot_cycle", "plot_poses"]


def plot_contacts(
    motion: Motion,
    path: str | os.PathLike[str],
    locked: Motion | None = None,
    title: str = "",
) -> Path:
    """For every contact point (ankles and toes): height above the floor and horizontal
    speed, both in body scales (hip heights; per second for speed), the frames
    :func:`~biomorph.motion.contact.detect_contacts` plants (green) and the frames the
    foot-skate metric counts (red, below 8 % of hip height); ``locked`` (the same clip after
    :func:`~biomorph.motion.contact.lock_feet`) is drawn dashed."""
    from biomorph.motion.contact import detect_contacts, find_legs
    from biomorph.motion.quality import foot_skate

    plt = _plt()
    fs = foot_skate(motion)
    ui = "xyz".index(fs["up"].lower())
    horiz = [a for a in range(3) if a != ui]
    g, scale = fs["ground_height"], fs["body_scale"]
    pts = sorted({p for lg in find_legs(motion) for p in (lg.ankle, lg.toe) if p >= 0})
    contacts = detect_contacts(motion)
    t = np.arange(motion.n_frames) / motion.fps
    fig, axes = plt.subplots(max(len(pts), 1), 1, figsize=(10, 1.9 * max(len(pts), 1)), sharex=True)
    axes = np.atleast_1d(axes)
    runs = [(motion, "-", "clip")] + ([(locked, "--", "locked")] if locked is not None else [])
    for ax, j in zip(axes, pts, strict=False):
        for mo, ls, label in runs:
            w = mo.world_positions()[:, j]
            h = (w[:, ui] - g) / scale
            v = np.hypot(*np.gradient(w[:, horiz], axis=0).T) * mo.fps / scale
            ax.plot(t, 10 * h, ls, color="tab:blue", lw=1.1, label=f"height ×10 ({label})")
            ax.plot(t, v, ls, color="tab:orange", lw=1.1, label=f"speed ({label})")
            if mo is motion:
                ax.fill_between(t, -0.4, 0, where=h < 0.08, color="tab:red", alpha=0.3, lw=0)
        on = contacts.get(j)
        if on is not None:
            top = ax.get_ylim()[1]
            ax.fill_between(t, 0, top, where=on, color="tab:green", alpha=0.15, lw=0)
        ax.axhline(0.8, color="0.5", ls=":", lw=0.8)
        ax.set_ylabel(motion.names[j], fontsize=8)
    axes[0].legend(fontsize=7, ncol=4, loc="upper right")
    axes[0].set_title(
        title
        or "foot points: height ×10 and speed (hip heights, /s); green planted, "
        + (
            f"red counted by the skate metric (skate {fs['skate_per_body_scale']:.3f})"
            if fs["feet"]
            else "no feet: no skate metric"
        ),
        fontsize=9,
    )
    axes[-1].set_xlabel("s")
    fig.tight_layout()
    return _save(fig, path)
