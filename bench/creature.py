"""Creature benchmark: quality over seeded creatures, speed, diversity, PCA spectrum, batch.

    .venv/bin/python bench/creature.py                    # 1,000 creatures + 10,000 GLB batch
    .venv/bin/python bench/creature.py --count 200 --batch 0   # quick

Prints markdown tables. Timings are wall-clock on this machine (2 shared cores).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from biomorph.creature.generator import Generator, Options, generate
from biomorph.creature.model import species_model
from biomorph.creature.pca import SEED_SPECTRUM, spectrum_summary
from biomorph.creature.quality import CHECKS, check, vendi_score


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--batch", type=int, default=10000, help="GLB batch size (0 = skip)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--settle", type=int, default=100, help="MuJoCo settle checks")
    args = ap.parse_args()

    generate(0)  # JIT compile / load caches outside the timing
    times, cpu, creatures = [], [], []
    for seed in range(args.count):
        t0, c0 = time.perf_counter(), time.process_time()
        c = Generator(Options(seed=seed)).run()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        creatures.append(c)
    t = np.array(times) * 1e3
    tc = np.array(cpu) * 1e3
    res = {k: 0 for k in CHECKS}
    for c in creatures:
        for k, v in check(c).items():
            res[k] += v
    legs = np.array([c.params["legs"] for c in creatures])
    applicable = sum(c.balance.applicable for c in creatures)
    resampled = sum(c.balance.resamples > 0 for c in creatures)
    repaired = sum(c.balance.repairs > 0 for c in creatures)
    print(f"## Quality over {args.count} seeded creatures (seeds 0..{args.count - 1})\n")
    print("| check | pass |\n|---|---|")
    for k in CHECKS:
        print(f"| {k} | {res[k]}/{args.count} ({res[k] / args.count:.1%}) |")
    print(f"\nlegs 0/2/4: {(legs == 0).sum()}/{(legs == 2).sum()}/{(legs == 4).sum()}; "
          f"with ground contact {applicable}; balance-repaired {repaired}; "
          f"resampled {resampled}\n")
    print("## Speed (no export)\n")
    print("| clock | median ms | p90 ms | mean ms | seed's Java |\n|---|---|---|---|---|")
    print(f"| wall | {np.median(t):.2f} | {np.percentile(t, 90):.2f} | {t.mean():.2f} | 3.05 ms |")
    print(f"| CPU (process) | {np.median(tc):.2f} | {np.percentile(tc, 90):.2f} | "
          f"{tc.mean():.2f} | |\n")
    with open("/proc/loadavg") as fh:
        print(f"load average during the run: {fh.read().split()[0]}\n")
    feats = np.array([c.features() for c in creatures])
    from biomorph.creature.dataset import load_species
    from biomorph.creature.pca import encode
    tab = load_species()
    ds = encode(tab.points, tab.lengths, tab.wings, tab.legs, tab.weight)
    n = min(len(feats), 1000)
    print("## Diversity (Vendi score, RBF on standardised features)\n")
    print("| set | n | Vendi |\n|---|---|---|")
    print(f"| generated creatures | {n} | {vendi_score(feats[:n]):.1f} |")
    print(f"| generated (44-subset) | 44 | {vendi_score(feats[:44]):.1f} |")
    print(f"| dataset species (29 PCA dims) | 44 | {vendi_score(ds):.1f} |\n")
    ours = spectrum_summary(species_model(None).pca)
    print("## PCA spectrum (the model the generator samples from)\n")
    print("| | first eigenvalue | total | 6 components | eigenvalues > 0.01 |")
    print("|---|---|---|---|---|")
    print(f"| seed | {SEED_SPECTRUM['first']} | {SEED_SPECTRUM['total']} | "
          f"{SEED_SPECTRUM['six_components']:.1%} | {SEED_SPECTRUM['above_0.01']} |")
    print(f"| ours | {ours['first']:.3f} | {ours['total']:.3f} | {ours['six_components']:.1%} | "
          f"{ours['above_0.01']} |\n")
    if args.settle:
        from biomorph.io.mjcf import settle
        legged = [c for c in creatures if c.balance.applicable][: args.settle]
        up = sum(settle(c)["upright"] for c in legged)
        print(f"MuJoCo settle (rigid, 2 s): {up}/{len(legged)} upright\n")
    if args.batch:
        from biomorph.cli import run
        out = Path(tempfile.mkdtemp(prefix="creature_batch_"))
        t0 = time.perf_counter()
        code = run(["creature", "batch", "--count", str(args.batch), "--out", str(out),
                    "--workers", str(args.workers), "--format", "glb", "--json"])
        dt = time.perf_counter() - t0
        files = len(list(out.glob("*.glb")))
        print("## Batch with GLB export\n")
        print("| creatures | workers | seconds | per creature | exit |\n|---|---|---|---|---|")
        print(f"| {files} | {args.workers} | {dt:.1f} | {dt / max(files, 1) * 1e3:.1f} ms | "
              f"{code} |")
        shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
