"""Start-up time of the command line (issue 12 item 5), beside Python's own floor.

Each command is run ``--repeat`` times as a fresh process (warm OS and numba caches: one
untimed run first); the table gives the median wall time and its ratio to two floors measured
in the same run: a bare ``python -c pass`` and ``python -c "import numpy"``.

    .venv/bin/python bench/cli.py [--repeat 7]

Targets: ``biomorph --help`` and ``biomorph <pillar> --help`` ≤ 0.5 s,
``biomorph motion info FILE`` ≤ 1 s.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent / "biomorph"


def _bvh(path: Path) -> Path:
    """A small BVH written by biomorph itself (built-in data: no shared files needed)."""
    subprocess.run(
        [
            sys.executable,
            "-c",
            "import biomorph.motion.synthetic as s, biomorph.io as bio, sys;"
            "bio.write_bvh(sys.argv[1], s.walk())",
            str(path),
        ],
        check=True,
        capture_output=True,
    )
    return path


def timed(cmd: list[str], repeat: int) -> float:
    subprocess.run(cmd, check=False, capture_output=True)  # warm caches
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=False, capture_output=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        try:
            bvh = _bvh(Path(tmp) / "walk.bvh")
        except subprocess.CalledProcessError:
            bvh = None
        floor = timed([sys.executable, "-c", "pass"], args.repeat)
        numpy_floor = timed([sys.executable, "-c", "import numpy"], args.repeat)
        rows = [("python -c pass", floor, None), ("python -c 'import numpy'", numpy_floor, None)]
        cmds = [["--help"]] + [
            [p, "--help"] for p in ("creature", "tree", "motion", "leaf", "studio")
        ]
        targets = {tuple(c): 0.5 for c in cmds}
        if bvh is not None:
            cmds.append(["motion", "info", str(bvh)])
            targets[tuple(cmds[-1])] = 1.0
        for c in cmds:
            rows.append(
                (
                    "biomorph " + " ".join(c).replace(str(bvh), "walk.bvh"),
                    timed([str(BIN), *c], args.repeat),
                    targets[tuple(c)],
                )
            )
    print("| command | median wall s | × python | × python+numpy | target s |")
    print("|---|---:|---:|---:|---:|")
    for name, t, target in rows:
        tgt = "" if target is None else f"{target:g} ({'met' if t <= target else 'MISSED'})"
        print(f"| {name} | {t:.3f} | {t / floor:.1f} | {t / numpy_floor:.2f} | {tgt} |")


if __name__ == "__main__":
    main()
