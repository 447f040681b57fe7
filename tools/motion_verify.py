"""Animator's verification pass: every shared capture through every motion operator from the
CLI, each output imported by Blender (``tools/blender_bvh_check.py``), one Markdown table.

    .venv/bin/python tools/motion_verify.py --out /tmp/verify [FILES…]
    .venv/bin/python tools/motion_verify.py --out /tmp/verify --table-only   # rows.json again

Needs ``../shared/data/motion`` (``BIOMORPH_SHARED`` or the repository's sibling), a Mixamo-
named target (the Rokoko rig renamed ``mixamorig:*``, written to ``OUT/mixamo_char.bvh``)
and a creature biped (``biomorph creature generate --legs 2 --seed 3 -o OUT/biped.bvh``;
reused when present). Cells: ✓ = Blender imported the output with no importer message and
no non-finite key or bone head; the figure is ``quality.foot_skate`` of the output (body
scales/s; in-place cycles measured with the removed drift restored, ``remove_drift(...,
restore=True)``, i.e. in the treadmill's frame). "(in x)" = the like-for-like input figure
where the operator changes which frames are measured: ``trim`` (a cut) and the cycles, the
input's skate over the same (looped) frames; ``speed``, the input retimed by the same curve
with the feet not locked (a retime at speed k plays every foot k× as fast, and the metric's
mean over the in-band frames loses the stance frames it compresses). "no feet": a skeleton
without foot joints (by name or name preset) has no foot skate. "↓floor" = the lowest
foot more than 2 % of
the input's hip height below the input's lowest foot (retargets: below the target's y = 0).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BIO = str(ROOT / ".venv" / "bin" / "biomorph")
DATA = Path(os.environ.get("BIOMORPH_SHARED", ROOT.parent / "shared" / "data")) / "motion"
FILES = [
    "cmu_01_01.bvh",
    "cmu_11.asf",
    "fairmotion_sinusoidal.bvh",
    "ad_fair1_zombie_walk.bvh",
    "ad_fair1_jumping.bvh",
    "ad_cmu1_jumping_jacks.bvh",
    "ad_rokoko_jesse_dance.bvh",
    "animal3d_egnaro_skel_anim.htr",
    "dme_comp_3d_2_raw.bvh",
    "dme_comp_3d_2_fixed.bvh",
    "xia_neutral_01_000_walk.bvh",
    "xia_angry_13_000_run.bvh",
]
OPS = [
    ("equalize", "eq"),
    ("edit", "edit"),
    ("blend", "blend"),
    ("speed", "speed"),
    ("cycle-world", "cyc-W"),
    ("cycle-in-place", "cyc-IP"),
    ("cycle-root-motion", "cyc-RM"),
    ("retarget-mixamo", "rt-Mixamo"),
    ("retarget-biped", "rt-biped"),
    ("mirror", "mirror"),
    ("trim", "trim+gif"),
    ("resample", "30 fps"),
]
FEET = ("foot", "toe", "ankle", "distal")


def _read(path: Path, up: str | None = None):
    from biomorph import io
    from biomorph.core.motion import to_y_up

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = io.read_motion(str(path))
    return to_y_up(m, "z") if up == "z" else m


def _skate(m) -> float | None:
    from biomorph.motion.quality import foot_skate

    v = foot_skate(m)["skate_per_body_scale"]
    return None if v is None else round(float(v), 3)  # None: no feet, no foot skate


def _lowest(m) -> float | None:
    idx = [i for i, n in enumerate(m.names) if any(w in n.lower() for w in FEET)]
    return float(m.world_positions()[:, idx, 1].min()) if idx else None


def _floor(o, m, op: str) -> float | None:
    from biomorph.motion.quality import foot_skate

    lo = _lowest(o)
    if lo is None:
        return None
    if op.startswith("retarget"):
        return round(lo / float(foot_skate(o)["body_scale"]), 4)
    base = _lowest(m)
    return None if base is None else round((lo - base) / float(foot_skate(m)["body_scale"]), 4)


def _targets(out: Path) -> tuple[Path, Path]:
    mix, biped = out / "mixamo_char.bvh", out / "biped.bvh"
    if not mix.exists():
        from biomorph.io.bvh import write_bvh

        dance = _read(DATA / "ad_rokoko_jesse_dance.bvh")
        names = tuple(f"mixamorig:{n}" for n in dance.names)
        sk = dance.skeleton.with_(names=names) if hasattr(dance.skeleton, "with_") else None
        if sk is None:
            raise SystemExit("cannot rename the Rokoko rig; give OUT/mixamo_char.bvh")
        write_bvh(mix, dance.frames(0, 2).with_(skeleton=sk))
    if not biped.exists():
        cmd = [BIO, "creature", "generate", "--legs", "2", "--seed", "3", "-o", str(biped)]
        subprocess.run(cmd, check=True, capture_output=True)
    return mix, biped


def _ops(src: Path, n: int, names: tuple[str, ...], mix: Path, biped: Path) -> dict:
    arm = next(
        (j for j in names if "rightarm" in j.lower() or "rhumerus" in j.lower()),
        names[min(2, len(names) - 1)],
    )
    tr, ml = str(min(12, n // 8)), str(min(30, n // 3))
    cyc = ["--auto", "--transition", tr, "--cycles", "3", "--min-length", ml]
    run = DATA / "xia_angry_13_000_run.bvh"
    if src.name.startswith("xia_neutral"):
        blend = ["blend", str(src), str(run), "--transition", "40", "--align", "peaks"]
        blend += ["--align-joint", "LeftUpLeg"]
    else:
        blend = ["blend", str(src), str(src), "--transition", str(min(30, n // 4))]
    key = f"{n // 3}:0/0/30;{2 * n // 3}:0/20/0"
    return {
        "equalize": ["equalize", str(src), "--gains", "0,0,1,1,1"],
        "edit": ["edit", str(src), "--joint", arm, "--key", key, "--fade", str(max(2, n // 10))],
        "blend": blend,
        "speed": ["speed", str(src), "--speed", f"0:1,{n // 2}:1.5,{n - 1}:1"],
        "cycle-world": ["cycle", str(src), *cyc, "--mode", "world", "--json"],
        "cycle-in-place": ["cycle", str(src), *cyc, "--mode", "in-place", "--json"],
        "cycle-root-motion": ["cycle", str(src), *cyc, "--mode", "root-motion", "--json"],
        "retarget-mixamo": ["retarget", str(src), "--to", str(mix)],
        "retarget-biped": ["retarget", str(src), "--to", str(biped)],
        "mirror": ["mirror", str(src)],
        "trim": ["trim", str(src), "--start", str(n // 4), "--stop", str(3 * n // 4)],
        "resample": ["convert", str(src), "--fps", "30"],
    }


def run_ops(out: Path, files: list[str]) -> list[dict]:
    from biomorph.motion.rootmotion import remove_drift

    mix, biped = _targets(out)
    rows = []
    for name in files:
        src = DATA / name
        d = out / "out" / Path(name).stem
        d.mkdir(parents=True, exist_ok=True)
        m0 = _read(src)
        up = ["--up", "z"] if m0.meta.get("up_guess") == "z" else []
        m = _read(src, "z" if up else None)
        base = _skate(m)
        for op, args in _ops(src, m.n_frames, m.names, mix, biped).items():
            path = d / f"{op}.bvh"
            path.unlink(missing_ok=True)
            if op == "trim":
                args = [*args, "--preview", str(d / "trim.gif")]
            p = subprocess.run(
                [BIO, "motion", *args, "-o", str(path), *up], capture_output=True, text=True
            )
            msgs = [ln for ln in (p.stdout + p.stderr).splitlines() if ln.startswith("error")]
            row = {"file": name, "op": op, "exit": p.returncode, "skate_in": base, "msgs": msgs}
            if p.returncode == 0:
                o = _read(path)
                row.update(out=str(path), frames_out=o.n_frames, skate_out=_skate(o))
                if op.startswith("cycle"):  # the input over the looped range
                    js = json.loads(p.stdout[p.stdout.index("{") :])
                    row["skate_ref"] = _skate(m.frames(js["start"], js["stop"]))
                if op == "cycle-in-place":
                    dr = js["drift"]
                    back = remove_drift(o, dr["translation"], dr["yaw"], js["period"], restore=True)
                    row.update(skate_out_raw=row["skate_out"], skate_out=_skate(back))
                row["floor"] = _floor(o, m, op)
                if op == "trim":  # a cut: compared with the input over the same frames
                    n = m.n_frames
                    row["skate_ref"] = _skate(m.frames(n // 4, 3 * n // 4))
                if op == "speed":  # the input retimed by the same curve, feet not locked
                    from biomorph.motion.timewarp import change_speed

                    n = m.n_frames
                    row["skate_ref"] = _skate(
                        change_speed(m, [(0, 1.0), (n // 2, 1.5), (n - 1, 1.0)])
                    )
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def blender(rows: list[dict]) -> None:
    exe = shutil.which("blender")
    paths = [r["out"] for r in rows if "out" in r]
    if exe is None or not paths:
        return
    script = ROOT / "tools" / "blender_bvh_check.py"
    recs = {}
    for i in range(0, len(paths), 40):
        p = subprocess.run(
            [exe, "-b", "--factory-startup", "--python", str(script), "--", *paths[i : i + 40]],
            capture_output=True,
            text=True,
        )
        for line in p.stdout.splitlines():
            if line.startswith("BVHCHECK "):
                rec = json.loads(line.split(" ", 1)[1])
                recs[rec["file"]] = rec
    for r in rows:
        rec = recs.get(r.get("out", ""))
        if rec is not None:
            r["blender_ok"] = bool(
                rec.get("result") == ["FINISHED"]
                and not rec.get("messages")
                and rec.get("nan_keys") == 0
                and rec.get("nonfinite_heads") == 0
            )


def table(rows: list[dict]) -> str:
    head = "| file (skate in) | " + " | ".join(c for _, c in OPS) + " |"
    lines = [head, "|---" * (len(OPS) + 1) + "|"]
    by = {(r["file"], r["op"]): r for r in rows}
    files = list(dict.fromkeys(r["file"] for r in rows))
    low, ok, n = [], 0, 0
    for f in files:
        cells = []
        base = next(r["skate_in"] for r in rows if r["file"] == f)
        for op, _ in OPS:
            r = by.get((f, op))
            if r is None:
                cells.append("—")
                continue
            if r["exit"] != 0:
                cells.append(f"exit {r['exit']}")
                continue
            n += 1
            ok += bool(r.get("blender_ok"))
            mark = "✓" if r.get("blender_ok") else ("?" if "blender_ok" not in r else "✗")
            fl = r.get("floor")
            below = fl is not None and fl < -0.02
            if below:
                low.append((f, op, fl))
            ref = f" (in {r['skate_ref']})" if r.get("skate_ref") is not None else ""
            fig = "no feet" if r["skate_out"] is None else r["skate_out"]
            cells.append(f"{mark} {fig}{ref}" + (" ↓floor" if below else ""))
        lines.append(f"| {f} ({'no feet' if base is None else base}) | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(
        f"Blender imports OK, no NaN: {ok} of {n}; feet more than 2 % of hip height below "
        f"the input's lowest foot (retargets: below y = 0): {low or 'none'}"
    )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", default=FILES)
    ap.add_argument("--out", type=Path, default=Path("/tmp/verify"))
    ap.add_argument("--table-only", action="store_true", help="rebuild from OUT/rows.json")
    a = ap.parse_args()
    sys.path.insert(0, str(ROOT / "src"))
    a.out.mkdir(parents=True, exist_ok=True)
    rows_path = a.out / "rows.json"
    if a.table_only:
        rows = json.loads(rows_path.read_text())
    else:
        rows = run_ops(a.out, a.files)
        blender(rows)
        rows_path.write_text(json.dumps(rows))
    if not np.all([("blender_ok" in r) for r in rows if "out" in r]):
        blender(rows)
        rows_path.write_text(json.dumps(rows))
    text = table(rows)
    (a.out / "table.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
