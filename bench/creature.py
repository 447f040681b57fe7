"""Creature benchmark: quality over seeded creatures, speed, diversity, PCA spectrum, batch.

    .venv/bin/python bench/creature.py                    # 1,000 creatures + 10,000 GLB batch
    .venv/bin/python bench/creature.py --count 200 --batch 0   # quick
    .venv/bin/python bench/creature.py --compare HEAD~3 --speed-only --count 300
        # speed before/after: REF's src/ (git archive) and this tree's src/ timed in two
        # worker processes, alternating blocks of seeds in the same window

``--compare`` interleaves the two codes block by block (25 seeds of one condition in one
worker, then the same seeds in the other, the order swapped every block), so both see the
same machine load; each worker reports ``time.process_time`` per creature.

Prints markdown tables. Timings: CPU time (``time.process_time``) beside the wall clock, and
the ratio to a baseline measured in the same run — the seed's plain pipeline (its descent
without the anatomical preferences, no balance repair: ``DescentParams(plausible=False,
restarts=1)``, ``require_stable=False``), the closest thing to the thesis's Java (3.05 ms,
not runnable here) — because the machine is shared and its load moves every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from biomorph.creature.generator import Generator, Options, generate
from biomorph.creature.limbs import DescentParams
from biomorph.creature.model import species_model
from biomorph.creature.pca import SEED_SPECTRUM, spectrum_summary
from biomorph.creature.quality import (
    ANATOMY_CHECKS,
    CHECKS,
    anatomy_check,
    anatomy_measures,
    check,
    vendi_score,
)
from biomorph.creature.stance import RANGES
from biomorph.creature.walk import plan_walk, walk_cycle, walk_quality

#: The seed's plain pipeline (see the module docstring), the same-run timing baseline.
SEED_PLAIN = {"descent": DescentParams(plausible=False, restarts=1), "require_stable": False}

CONDITIONS = {
    "--legs 4": {"legs": 4},
    "--legs 2": {"legs": 2},
    "--class bird": {"cls": "bird"},
    "--weight 600": {"weight": 600.0},
    "--legs 6": {"legs": 6},
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--batch", type=int, default=10000, help="GLB batch size (0 = skip)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--settle", type=int, default=100, help="MuJoCo settle checks")
    ap.add_argument("--walk", type=int, default=300, help="walk cycles checked")
    ap.add_argument(
        "--compare",
        metavar="REF",
        help="time REF's src/ against this tree's, interleaved (before/after table)",
    )
    ap.add_argument("--speed-only", action="store_true", help="only the speed table(s)")
    ap.add_argument(
        "--conditions",
        help="with --compare: comma-separated labels of SPEED_CONDITIONS (default: all), "
        "e.g. 'defaults,--legs 2,--class bird'",
    )
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        return _worker()
    if args.compare:
        labels = args.conditions.split(",") if args.conditions else None
        compare_table(args.compare, args.count, labels=labels)
        if args.speed_only:
            return

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
    print(
        f"\nlegs 0/2/4: {(legs == 0).sum()}/{(legs == 2).sum()}/{(legs == 4).sum()}; "
        f"with ground contact {applicable}; balance-repaired {repaired}; "
        f"resampled {resampled}\n"
    )
    tip = [
        np.degrees(np.arctan2(c.balance.margin, c.balance.com[1]))
        for c in creatures
        if c.balance.applicable
    ]
    if tip:
        print(
            f"least tipping angle atan(margin / centre-of-mass height): {min(tip):.2f}° "
            f"(every stable creature ≥ atan(0.02) = 1.15°)\n"
        )
    anatomy_table(creatures)
    bird_table(args.count)
    fish_table(args.count)
    walk_table(creatures, args.walk)
    speed_table(t, tc, max(args.count // 5, 1))
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
    print(
        f"| seed | {SEED_SPECTRUM['first']} | {SEED_SPECTRUM['total']} | "
        f"{SEED_SPECTRUM['six_components']:.1%} | {SEED_SPECTRUM['above_0.01']} |"
    )
    print(
        f"| ours | {ours['first']:.3f} | {ours['total']:.3f} | {ours['six_components']:.1%} | "
        f"{ours['above_0.01']} |\n"
    )
    if args.settle:
        from biomorph.io.mjcf import settle

        legged = [c for c in creatures if c.balance.applicable][: args.settle]
        up = sum(settle(c)["upright"] for c in legged)
        print(f"MuJoCo settle (rigid, 2 s): {up}/{len(legged)} upright\n")
    if args.batch:
        from biomorph.cli import run

        out = Path(tempfile.mkdtemp(prefix="creature_batch_"))
        t0 = time.perf_counter()
        code = run(
            [
                "creature",
                "batch",
                "--count",
                str(args.batch),
                "--out",
                str(out),
                "--workers",
                str(args.workers),
                "--format",
                "glb",
                "--json",
            ]
        )
        dt = time.perf_counter() - t0
        files = len(list(out.glob("*.glb")))
        print("## Batch with GLB export\n")
        print("| creatures | workers | seconds | per creature | exit |\n|---|---|---|---|---|")
        print(
            f"| {files} | {args.workers} | {dt:.1f} | {dt / max(files, 1) * 1e3:.1f} ms | {code} |"
        )
        shutil.rmtree(out, ignore_errors=True)


#: The conditions of the issue-14 speed target (defaults first).
SPEED_CONDITIONS = {"defaults": {}, **CONDITIONS}


def _worker() -> None:
    """Compare worker: read ``{"kw": {...}, "seeds": [...]}`` lines, answer each with the CPU
    ms per creature (``time.process_time``)."""
    generate(0)  # JIT compile / load caches outside the timing
    for kw in SPEED_CONDITIONS.values():
        generate(0, **kw)
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        job = json.loads(line)
        out = []
        for seed in job["seeds"]:
            c0 = time.process_time()
            generate(seed, **job["kw"])
            out.append((time.process_time() - c0) * 1e3)
        print(json.dumps(out), flush=True)


def _spawn(src: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(src))
    p = subprocess.Popen(
        [sys.executable, __file__, "--worker"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        cwd=str(src.parent),
    )
    assert p.stdin and p.stdout
    json.loads(p.stdout.readline())
    return p


def _ask(p: subprocess.Popen, kw: dict, seeds: list[int]) -> list[float]:
    assert p.stdin and p.stdout
    p.stdin.write(json.dumps({"kw": kw, "seeds": seeds}) + "\n")
    p.stdin.flush()
    return json.loads(p.stdout.readline())


def compare_table(ref: str, n: int, block: int = 25, labels: list[str] | None = None) -> None:
    """Median CPU ms per creature, REF's code against this tree's, per speed condition,
    interleaved in blocks of seeds in the same run (``--compare``)."""
    root = Path(__file__).resolve().parents[1]
    tmp = Path(tempfile.mkdtemp(prefix="creature_ref_"))
    arch = subprocess.run(
        ["git", "-C", str(root), "archive", ref, "src"], check=True, capture_output=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(tmp)], input=arch, check=True)
    sha = subprocess.run(
        ["git", "-C", str(root), "rev-parse", "--short", ref],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    with open("/proc/loadavg") as fh:
        load0 = fh.read().split()[0]
    before, after = _spawn(tmp / "src"), _spawn(root / "src")
    res: dict[str, tuple[list[float], list[float]]] = {}
    try:
        for label, kw in SPEED_CONDITIONS.items():
            if labels is not None and label not in labels:
                continue
            b_, a_ = [], []
            for i, start in enumerate(range(0, n, block)):
                seeds = list(range(start, min(start + block, n)))
                if i % 2 == 0:
                    b_ += _ask(before, kw, seeds)
                    a_ += _ask(after, kw, seeds)
                else:
                    a_ += _ask(after, kw, seeds)
                    b_ += _ask(before, kw, seeds)
            res[label] = (b_, a_)
    finally:
        for p in (before, after):
            p.kill()
            p.wait()
        shutil.rmtree(tmp, ignore_errors=True)
    with open("/proc/loadavg") as fh:
        load1 = fh.read().split()[0]
    print(f"## Speed before/after (`--compare {ref}` = {sha}; seeds 0..{n - 1} per condition)\n")
    print(
        "| condition | n | before CPU median ms | after CPU median ms | after ÷ before | "
        "before p90 | after p90 | after ≤ 5 ms |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for label, (b_, a_) in res.items():
        mb, ma = float(np.median(b_)), float(np.median(a_))
        print(
            f"| {label} | {len(a_)} | {mb:.2f} | {ma:.2f} | {ma / mb:.2f} | "
            f"{np.percentile(b_, 90):.2f} | {np.percentile(a_, 90):.2f} | "
            f"{'yes' if ma <= 5.0 else 'no'} |"
        )
    print(
        f"\nload average {load0} before, {load1} after (2 cores); blocks of {block} seeds "
        "alternate between the two worker processes\n"
    )


def _timed(n: int, **kw) -> tuple[np.ndarray, np.ndarray]:
    w, c = [], []
    for seed in range(n):
        t0, c0 = time.perf_counter(), time.process_time()
        Generator(Options(seed=seed, **kw)).run()
        w.append(time.perf_counter() - t0)
        c.append(time.process_time() - c0)
    return np.array(w) * 1e3, np.array(c) * 1e3


def speed_table(t: np.ndarray, tc: np.ndarray, n: int) -> None:
    """CPU per creature per condition beside the seed's plain pipeline in the same run."""
    with open("/proc/loadavg") as fh:
        load0 = fh.read().split()[0]
    _, base = _timed(n, **SEED_PLAIN)
    b = float(np.median(base))
    print("## Speed (no export; balance repair included)\n")
    print(
        "| condition | n | wall median ms | CPU median ms | CPU p90 ms | ÷ seed's plain "
        "pipeline (same run) |"
    )
    print("|---|---|---|---|---|---|")
    print(f"| seed's plain pipeline | {n} | – | {b:.2f} | {np.percentile(base, 90):.2f} | 1.00 |")
    print(
        f"| none | {len(t)} | {np.median(t):.2f} | {np.median(tc):.2f} | "
        f"{np.percentile(tc, 90):.2f} | {np.median(tc) / b:.2f} |"
    )
    for label, kw in CONDITIONS.items():
        w_, c_ = _timed(n, **kw)
        print(
            f"| {label} | {len(w_)} | {np.median(w_):.2f} | {np.median(c_):.2f} | "
            f"{np.percentile(c_, 90):.2f} | {np.median(c_) / b:.2f} |"
        )
    with open("/proc/loadavg") as fh:
        load1 = fh.read().split()[0]
    print(f"\nload average: {load0} before, {load1} after the timing (2 cores); the thesis's")
    print("Java: 3.05 ms per creature (its own machine, not re-measured)\n")


def anatomy_table(creatures) -> None:
    """Issue 14's anatomical rules: passes over the creatures, the measured spread beside the
    real ranges (biomorph.creature.stance)."""
    n = len(creatures)
    res = {k: 0 for k in ANATOMY_CHECKS}
    meas = []
    for c in creatures:
        m = anatomy_measures(c)
        meas.append((c, m))
        for k, v in anatomy_check(c, m).items():
            res[k] += v
    print(f"## Anatomy over {n} seeded creatures (ranges: biomorph/creature/stance.py)\n")
    print("| rule | pass | measured (min / median / max) | real range |\n|---|---|---|---|")

    def spread(vals):
        v = np.array([x for x in vals if x is not None], float)
        return "–" if not len(v) else f"{v.min():.2f} / {np.median(v):.2f} / {v.max():.2f}"

    quad = [m["trunk_pitch_deg"] for c, m in meas if c.params["legs"] >= 4]
    bip = [
        m["trunk_pitch_deg"]
        for c, m in meas
        if c.params["legs"] == 2 and c.params["class"] != "bird"
    ]
    birds = [
        m["trunk_pitch_deg"]
        for c, m in meas
        if c.params["legs"] == 2 and c.params["class"] == "bird"
    ]
    fem = [a for c, m in meas if c.params["class"] != "bird" for a in m["femur_deg"]]
    femb = [a for c, m in meas if c.params["class"] == "bird" for a in m["femur_deg"]]
    rows = {
        "trunk_pitch": (
            f"quadrupeds {spread(quad)}°; bipeds {spread(bip)}°; birds {spread(birds)}°",
            f"quadrupeds {RANGES['trunk_pitch_quadruped']}° (horse 0–5°, giraffe ≈ 25°) / "
            f"bipeds {RANGES['trunk_pitch_biped']}° (theropods 0–15°, kangaroo ≈ 45°) / "
            f"birds {RANGES['trunk_pitch_bird']}° (pronograde, not level)",
        ),
        "head_pitch": (
            spread([m["head_pitch_deg"] for _, m in meas]) + "°",
            f"{RANGES['head_pitch']}°",
        ),
        "femur_angle": (
            f"{spread(fem)}°; birds {spread(femb)}°",
            f"{RANGES['femur_from_vertical']}° / birds {RANGES['femur_from_vertical_bird']}°",
        ),
        "withers_height": (
            spread([m["withers_ratio"] for _, m in meas]),
            f"{RANGES['withers_ratio']} × a·M^(1/3)",
        ),
        "knee_behind_elbow": ("", "hind knee behind front elbow"),
        "class_legs": ("", "birds 2 legs, fish 0 (unless asked)"),
        "weight_in_range": (
            spread([c.total_mass for c in creatures]) + " kg",
            "0.01..120000 kg (dataset)",
        ),
        "feet_have_digits": ("", "contacts are digit joints / flat feet"),
    }
    for k in ANATOMY_CHECKS:
        got, real = rows[k]
        print(f"| {k} | {res[k]}/{n} ({res[k] / n:.1%}) | {got} | {real} |")
    from biomorph.creature.quality import standing_height

    ung = [
        standing_height(Generator(Options(seed=s, legs=4, weight=600.0, cls="mammal")).run())
        for s in range(10)
    ]
    print(
        f"\n600-kg quadruped mammals (10 seeds): withers {min(ung):.2f}..{max(ung):.2f} m "
        "(a horse: ≈ 1.1-1.3 m)\n"
    )
    hooves: dict[int, int] = {}
    for c in creatures:
        if c.params.get("stance") == "unguligrade" and c.params.get("legs", 0) > 0:
            hooves[c.params["hoof_digits"]] = hooves.get(c.params["hoof_digits"], 0) + 1
    print(
        "hoofed (unguligrade) creatures by hoofed digits per foot: "
        + ", ".join(f"{k}: {v}" for k, v in sorted(hooves.items()))
        + " (1 = perissodactyl, inherited from the horse; 2 = artiodactyl)\n"
    )


def bird_table(n: int) -> None:
    """Birds asked for (``--class bird``, seeds 0..n-1): trunk pitch against the birds' real
    20-50° (stance.RANGES['trunk_pitch_bird']), every anatomy rule, balance on the feet."""
    from biomorph.creature.quality import trunk_pitch_deg

    lo, hi = RANGES["trunk_pitch_bird"]
    pitch, rules, stable = [], 0, 0
    for seed in range(n):
        c = generate(seed, cls="bird")
        pitch.append(trunk_pitch_deg(c))
        rules += all(anatomy_check(c).values())
        stable += all(check(c).values())
    t = np.array(pitch)
    inside = int(((t >= lo) & (t <= hi)).sum())
    print(f"## Birds (`--class bird`, seeds 0..{n - 1})\n")
    print(
        "| trunk pitch in 20–50° | min / p10 / median / p90 / max | every anatomy rule | "
        "every quality check (stable on the foot contacts) |\n|---|---|---|---|"
    )
    q = np.percentile(t, [10, 50, 90])
    print(
        f"| {inside}/{n} | {t.min():.1f} / {q[0]:.1f} / {q[1]:.1f} / {q[2]:.1f} / "
        f"{t.max():.1f}° | {rules}/{n} | {stable}/{n} |\n"
    )


def fish_table(n: int) -> None:
    """Fish asked for (``--class fish``, seeds 0..n-1): the median fins
    (:func:`biomorph.creature.fins.build_median`) — all three present and finite, the dorsal
    rays' tips above where they leave the skin, the anal tips below, the caudal tips behind
    the last vertebra's end."""
    from biomorph.creature import fins as fn

    have = placed = 0
    for seed in range(n):
        c = generate(seed, cls="fish")
        ms = fn.build_median(c, *fn.MEDIAN_DETAIL[1])
        if [m.name for m in ms] != list(fn.MEDIAN) or not all(
            np.isfinite(m.rays).all() for m in ms
        ):
            continue
        have += 1
        dorsal, anal, caudal = ms
        end = min(c.bone_ends[j][0] for j in range(len(c)) if c.kind[j] == "spine")
        placed += bool(
            (dorsal.rays[:, -1, 1] > dorsal.surface[:, 1]).all()
            and (anal.rays[:, -1, 1] < anal.surface[:, 1]).all()
            and (caudal.rays[:, -1, 0] < end).all()
        )
    print(f"## Fish median fins (`--class fish`, seeds 0..{n - 1})\n")
    print(
        "| dorsal, anal and caudal fin | dorsal above / anal below the skin, caudal behind "
        "the tail |\n|---|---|"
    )
    print(f"| {have}/{n} | {placed}/{n} |\n")


def walk_table(creatures, limit: int) -> None:
    """Walk cycles: planted-foot slide and ground penetration per leg count."""
    print(
        "## Walk (IK-planted feet; targets: slide ≤ 2 % of stride, penetration ≤ 0.5 % of height)\n"
    )
    print("| legs | n | slide max | slide > 2 % | penetration max | penetration > 0.5 % |")
    print("|---|---|---|---|---|---|")
    by: dict[int, list] = {}
    for c in [c for c in creatures if c.params["legs"] > 0][:limit]:
        plan = plan_walk(c)
        by.setdefault(c.params["legs"], []).append(walk_quality(c, walk_cycle(c), plan))
    for legs in sorted(by):
        sl = np.array([q["slide_fraction"] for q in by[legs]])
        pe = np.array([q["penetration_fraction"] for q in by[legs]])
        print(
            f"| {legs} | {len(sl)} | {sl.max():.2%} | {(sl > 0.02).sum()} | {pe.max():.2%} | "
            f"{(pe > 0.005).sum()} |"
        )
    print()


if __name__ == "__main__":
    main()
