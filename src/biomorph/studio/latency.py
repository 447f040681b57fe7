"""Measure the studio's edit -> redraw latency on the server (no browser needed).

Each edit is made the way a slider change arrives (the GUI value is set, its callback runs
the pillar call and queues the new scene), timed from the callback's start until the scene
messages are queued — the part of the latency the studio controls (the websocket hop and
the browser's draw add a few milliseconds on loopback).

Run: ``python -m biomorph.studio.latency [--motion walk.bvh] [--cloud tree.xyz]
[--repeats 15]``; moves every slider of every tab and prints a markdown table (median /
95th percentile / max in ms).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def _motion_clip(path: Path, source: Path | None) -> Path:
    """A clip of about one minute: ``source`` repeated, or a synthetic 120 fps walk."""
    from biomorph import io
    from biomorph.motion import concatenate

    if source is not None:
        clip = io.read_motion(source)
        reps = int(np.ceil(60.0 / max(clip.duration, 1e-3)))
        clip = concatenate([clip] * max(reps, 1))
    else:
        from biomorph.motion.synthetic import walk

        clip = walk(n_frames=7200, fps=120.0)
    io.write_bvh(path, clip)
    return path


def _sweep(tab: Any, handle: Any, values: Any) -> None:
    """Set ``handle`` to each of ``values`` the way a page's edit arrives (its callbacks
    run the pillar call and queue the scene)."""
    for v in values:
        handle.value = v


def measure(
    repeats: int = 15, motion: Path | None = None, cloud: Path | None = None
) -> tuple[dict[str, Any], str]:
    """Move every slider of every tab ``repeats`` times; return (latency summary, notes)."""
    from biomorph.studio.server import StudioApp

    with tempfile.TemporaryDirectory() as tmp:
        app = StudioApp(tmp, port=0, shared=True)
        app.start()
        try:
            notes = []
            rng = np.random.default_rng(0)
            tabs = app.tabs
            if "creature" in tabs:
                t = tabs["creature"]
                _sweep(t, t.seed, range(100, 100 + repeats))
                for h in (t.neck, t.tail):
                    _sweep(t, h, np.round(np.linspace(0.1, 1.2, repeats), 2))
                _sweep(t, t.k, rng.integers(2, 28, repeats))
                _sweep(t, t.temperature, np.round(np.linspace(0.2, 1.8, repeats), 2))
                _sweep(t, t.pcs[0], np.round(np.linspace(-2.0, 2.0, repeats), 1))
                notes.append(
                    "creature: seed, neck, tail, k, temperature, PC1 (each a full regeneration)"
                )
            if "leaf" in tabs:
                t = tabs["leaf"]
                _sweep(t, t.lod, rng.integers(10, 390, repeats))
                _sweep(t, t.age, np.round(np.linspace(0.2, 1.0, repeats), 3))
                _sweep(t, t.length, np.round(np.linspace(0.3, 1.2, repeats), 2))
                _sweep(t, t.width, np.round(np.linspace(2.0, 12.0, repeats), 1))
                _sweep(t, t.twist, np.round(np.linspace(-90.0, 90.0, repeats)))
                _sweep(t, t.undulation, np.round(np.linspace(0.0, 10.0, repeats), 1))
                t.op_kind.value = "bend"
                _sweep(t, t.op_value, np.round(np.linspace(0.2, 2.0, repeats), 2))
                notes.append(
                    "leaf: maize; LOD 10-390 triangles, age, length, width, twist, undulation, bend"
                )
            if "motion" in tabs:
                t = tabs["motion"]
                clip = _motion_clip(Path(tmp) / "clip.bvh", motion)
                t.run("load", lambda: t.load(clip), timed=False)
                mo = t.source
                _sweep(t, t.gains[2], np.round(np.linspace(0.0, 2.0, repeats), 2))
                if t.speed is not None:
                    _sweep(t, t.speed, np.round(np.linspace(0.5, 2.0, repeats), 2))
                    t.speed.value = 1.0
                if t.cycle_on is not None:
                    t.cycle_on.value = True
                    _sweep(t, t.cycle_transition, rng.integers(5, 60, repeats))
                    t.cycle_on.value = False
                for f in rng.integers(0, mo.n_frames, repeats):
                    t.run("scrub", lambda f=f: t.draw_frame(int(f)))
                notes.append(
                    f"motion: {mo.n_frames} frames at {mo.fps:.0f} fps "
                    f"({mo.duration:.0f} s), {mo.n_joints} joints; equalizer band "
                    "3, speed, cycle transition, scrub"
                )
            if "tree" in tabs:
                t = tabs["tree"]
                if cloud is not None:
                    import shutil

                    local = Path(shutil.copy(cloud, tmp))  # the tab reads the data folder only
                    t.run("load", lambda: t.load(local), timed=False)
                else:
                    t.run("synthesise", t.synthesise, timed=False)
                _sweep(t, t.max_display, [int(v) * 5000 for v in rng.integers(1, 40, repeats)])
                notes.append(f"tree: {t.cloud.n_points} points, cloud display subsampling")
            return app.latency.summary(), "; ".join(notes)
        finally:
            app.stop()


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument(
        "--motion",
        type=Path,
        default=None,
        help="BVH/HTR clip repeated to about one minute (default: synthetic)",
    )
    ap.add_argument(
        "--cloud",
        type=Path,
        default=None,
        help="point cloud for the tree tab (default: a synthetic scan)",
    )
    args = ap.parse_args(argv)
    summary, notes = measure(args.repeats, args.motion, args.cloud)
    print(f"Data: {notes}\n")
    print("| tab/action | n | median ms | p95 ms | max ms |\n|---|---|---|---|---|")
    for k, s in summary.items():
        print(f"| {k} | {s['n']} | {s['median_ms']:.1f} | {s['p95_ms']:.1f} | {s['max_ms']:.1f} |")


if __name__ == "__main__":
    main()
