"""Start-up time of the command line (issue 12 item 5), beside Python's own floor.

Each command is run ``--repeat`` times as a fresh process (warm OS and numba caches: one
untimed run first); the table gives the median wall time and its ratio to two floors measured
in the same run: a bare ``python -c pass`` and ``python -c "import numpy"``.

    .venv/bin/python bench/cli.py [--repeat 7]
    .venv/bin/python bench/cli.py --crossover    (where the compiled motion kernels pay off)

The table also gives the median CPU time of the child processes (user + system), which the
machine's load disturbs less than wall time, and the load average.

``--crossover`` measures what the size thresholds of the small-file NumPy paths
(``core.motion.COMPILED_MIN_WORK``, ``io.bvh._COMPILED_MIN_VALUES``) trade: the one-off CPU
cost of importing numba and loading the cached FK/slerp/BVH kernels in a fresh process, and
the extra CPU time per joint-frame (per value for the BVH read) of the NumPy paths; their
ratio is the break-even size.

Targets: ``biomorph --help`` and ``biomorph <pillar> --help`` ≤ 0.5 s,
``biomorph motion info FILE`` ≤ 1 s.
"""

from __future__ import annotations

import argparse
import os
import resource
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


CPU: dict[str, float] = {}


def _child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(cmd: list[str], repeat: int) -> float:
    """Median wall s of ``repeat`` fresh runs; their median CPU s goes to ``CPU``."""
    subprocess.run(cmd, check=False, capture_output=True)  # warm caches
    times, cpus = [], []
    for _ in range(repeat):
        c0 = _child_cpu()
        t0 = time.perf_counter()
        subprocess.run(cmd, check=False, capture_output=True)
        times.append(time.perf_counter() - t0)
        cpus.append(_child_cpu() - c0)
    CPU[" ".join(cmd)] = statistics.median(cpus)
    return statistics.median(times)


LOAD_PROBE = """
import time
import numpy as np
c0 = time.process_time()
from biomorph.core._motion_kernels import fk_positions, sample_slerp
from biomorph.io import _bvh_kernels as k
rot = np.zeros((2, 3, 4)); rot[..., 3] = 1; rot.setflags(write=False)
tr = np.zeros((2, 3, 3)); tr.setflags(write=False)
par = np.array([-1, 0, 1]); par.setflags(write=False)
rest = rot[0].copy(); rest.setflags(write=False)
fk_positions(rest, rot, tr, par, np.empty((2, 3, 3)), np.empty((2, 3, 4)))
i0 = np.zeros(2, dtype=np.int64); i0.setflags(write=False)
fr = np.zeros(2); fr.setflags(write=False)
sample_slerp(rot, i0, fr, np.empty((2, 3, 4)))
buf = np.frombuffer(b"1 2 3\\n4 5 6\\n", dtype=np.uint8)
k._scan_floats(buf, 0, np.empty(6), 3)
v = np.zeros((2, 6))
cols = np.array([[3, 4, 5], [-1, -1, -1]])
axes = np.array([[2, 0, 1], [0, 0, 0]])
k._euler_kernel(v, cols, axes, np.empty((2, 2, 4)))
k._count_wraps(v, np.array([3, 4, 5]))
print(time.process_time() - c0)
"""


def _cpu_of(fn, repeat: int = 5) -> float:
    fn()
    out = []
    for _ in range(repeat):
        c0 = time.process_time()
        fn()
        out.append(time.process_time() - c0)
    return statistics.median(out)


def crossover() -> None:
    """One-off kernel load cost against the NumPy paths' extra cost per unit of work."""
    import warnings

    import numpy as np

    warnings.simplefilter("ignore")
    loads = []
    for _ in range(5):
        out = subprocess.run(
            [sys.executable, "-c", LOAD_PROBE], capture_output=True, text=True, check=True
        )
        loads.append(float(out.stdout.split()[-1]))
    load_s = statistics.median(loads)
    import biomorph.io.bvh as bvh
    from biomorph.core import motion as cm
    from biomorph.core._motion_kernels import fk_positions, sample_slerp
    from biomorph.motion.synthetic import walk

    m = walk(7200, 120, n_joints=60, noise_deg=0.5)
    sk = m.skeleton
    rot, tr = m.rotation, np.ascontiguousarray(m.local_translations())
    pos, quat = np.empty(tr.shape), np.empty(rot.shape)
    work = rot.shape[0] * rot.shape[1]
    fk_c = _cpu_of(
        lambda: fk_positions(
            cm.ro(sk.rest_rotation), cm.ro(rot), cm.ro(tr), cm.ro_int(sk.parent), pos, quat
        )
    )
    fk_n = _cpu_of(lambda: cm.fk_numpy(sk.rest_rotation, rot, tr, sk.parent, pos, quat))
    t = np.arange(0, m.n_frames - 1, 0.9)
    i0, frac, _, _ = cm.sample_linear(m, t)
    out = np.empty((t.size,) + rot.shape[1:])
    sl_c = _cpu_of(lambda: sample_slerp(cm.ro(rot), cm.ro_int(i0), cm.ro(frac), out))
    sl_n = _cpu_of(lambda: cm.slerp_numpy(rot, i0, frac, out))
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "minute.bvh"
        bvh.write_bvh(p, m)
        real = bvh._compiled
        try:
            bvh._compiled = lambda n: True
            rd_c = _cpu_of(lambda: bvh.read_bvh(p), 3)
            wr_c = _cpu_of(lambda: bvh.write_bvh(p, m), 3)
            bvh._compiled = lambda n: False
            rd_n = _cpu_of(lambda: bvh.read_bvh(p), 3)
            wr_n = _cpu_of(lambda: bvh.write_bvh(p, m), 3)
        finally:
            bvh._compiled = real
    values = m.n_frames * (6 + 3 * (sk.n_joints - 1))
    print(
        f"Crossover (load average {os.getloadavg()[0]:.1f}; CPU s): importing numba and "
        f"loading the cached FK, slerp and BVH kernels in a fresh process: {load_s:.2f} s\n"
    )
    print("| path | compiled s | NumPy s | extra µs per unit | break-even units |")
    print("|---|---:|---:|---:|---:|")
    for name, unit, c, n in (
        ("FK, 7,200 f × 60 j", work, fk_c, fk_n),
        ("slerp sampling, 8,000 f × 60 j", t.size * 60, sl_c, sl_n),
        ("BVH read (values)", values, rd_c, rd_n),
        ("BVH write (values)", values, wr_c, wr_n),
    ):
        extra = (n - c) / unit
        even = f"{load_s / extra:,.0f}" if extra > 0 else "never"
        print(f"| {name} | {c:.4f} | {n:.4f} | {1e6 * extra:.3f} | {even} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--crossover", action="store_true", help="kernel load vs NumPy paths")
    args = ap.parse_args()
    if args.crossover:
        crossover()
        return
    with tempfile.TemporaryDirectory() as tmp:
        try:
            bvh = _bvh(Path(tmp) / "walk.bvh")
        except subprocess.CalledProcessError:
            bvh = None
        floor = timed([sys.executable, "-c", "pass"], args.repeat)
        numpy_floor = timed([sys.executable, "-c", "import numpy"], args.repeat)
        py = sys.executable
        rows = [
            ("python -c pass", floor, None, CPU[f"{py} -c pass"]),
            ("python -c 'import numpy'", numpy_floor, None, CPU[f"{py} -c import numpy"]),
        ]
        cmds = [["--help"]] + [
            [p, "--help"] for p in ("creature", "tree", "motion", "leaf", "studio")
        ]
        targets = {tuple(c): 0.5 for c in cmds}
        if bvh is not None:
            cmds.append(["motion", "info", str(bvh)])
            targets[tuple(cmds[-1])] = 1.0
        real = ROOT.parent / "shared" / "data" / "motion" / "cmu_01_01.bvh"  # 2 MB capture
        if real.exists():
            cmds.append(["motion", "info", str(real)])
            targets[tuple(cmds[-1])] = 1.0
        for c in cmds:
            wall = timed([str(BIN), *c], args.repeat)
            name = "biomorph " + " ".join(c).replace(str(bvh), "walk.bvh")
            cpu = CPU[" ".join([str(BIN), *c])]
            rows.append((name.replace(str(real), "cmu_01_01.bvh"), wall, targets[tuple(c)], cpu))
    print(f"Load average {os.getloadavg()[0]:.1f} at the end, {os.cpu_count()} cores\n")
    print("| command | median wall s | CPU s | × python | × python+numpy | target s |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, t, target, cpu in rows:
        tgt = "" if target is None else f"{target:g} ({'met' if t <= target else 'MISSED'})"
        print(f"| {name} | {t:.3f} | {cpu:.3f} | {t / floor:.1f} | {t / numpy_floor:.2f} | {tgt} |")


if __name__ == "__main__":
    main()
