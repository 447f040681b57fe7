"""Measure the studio's edit -> redraw latency on the server (no browser needed).

Each edit is made the way a slider change arrives (the GUI value is set, its callback runs
the pillar call and queues the new scene), timed from the callback's start until the scene
messages are queued — the part of the latency the studio controls (the websocket hop and
the browser's draw add a few milliseconds on loopback).

Run: ``python -m biomorph.studio.latency [--motion walk.bvh] [--repeats 15]``; prints a
markdown table (median / 95th percentile / max in ms).
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


def measure(repeats: int = 15, motion: Path | None = None) -> tuple[dict[str, Any], str]:
    """Run typical edits in every tab; return (latency summary, description of the data)."""
    from biomorph.studio.server import StudioApp

    with tempfile.TemporaryDirectory() as tmp:
        app = StudioApp(tmp, port=0)
        app.start()
        try:
            notes = []
            rng = np.random.default_rng(0)
            if "creature" in app.tabs:
                t = app.tabs["creature"]
                for i in range(repeats):
                    t.seed.value = 100 + i
                notes.append("creature: new seed each edit (full regeneration)")
            if "leaf" in app.tabs:
                t = app.tabs["leaf"]
                for v in rng.integers(10, 390, repeats):
                    t.lod.value = int(v)
                for v in np.linspace(0.2, 1.0, repeats):
                    t.age.value = round(float(v), 3)
                for v in np.linspace(0.2, 2.0, repeats):
                    t.op_kind.value = "bend"
                    t.op_value.value = round(float(v), 2)
                notes.append("leaf: maize, LOD 10-390 triangles, age, bend operator")
            if "motion" in app.tabs:
                t = app.tabs["motion"]
                clip = _motion_clip(Path(tmp) / "clip.bvh", motion)
                t.run("load", lambda: t.load(clip), timed=False)
                mo = t.source
                for v in np.linspace(0.0, 2.0, repeats):
                    t.gains[2].value = round(float(v), 2)
                for f in rng.integers(0, mo.n_frames, repeats):
                    t.run("scrub", lambda f=f: t.draw_frame(int(f)))
                notes.append(f"motion: {mo.n_frames} frames at {mo.fps:.0f} fps "
                             f"({mo.duration:.0f} s), {mo.n_joints} joints; equalizer band 3")
            if "tree" in app.tabs:
                t = app.tabs["tree"]
                t.run("synthesise", t.synthesise, timed=False)
                for v in rng.integers(1, 40, repeats):
                    t.max_display.value = int(v) * 5000
                notes.append(f"tree: {t.cloud.n_points} points, cloud display subsampling")
            return app.latency.summary(), "; ".join(notes)
        finally:
            app.stop()


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--motion", type=Path, default=None,
                    help="BVH/HTR clip repeated to about one minute (default: synthetic)")
    args = ap.parse_args(argv)
    summary, notes = measure(args.repeats, args.motion)
    print(f"Data: {notes}\n")
    print("| tab/action | n | median ms | p95 ms | max ms |\n|---|---|---|---|---|")
    for k, s in summary.items():
        print(f"| {k} | {s['n']} | {s['median_ms']:.1f} | {s['p95_ms']:.1f} | "
              f"{s['max_ms']:.1f} |")


if __name__ == "__main__":
    main()
