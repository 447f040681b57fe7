"""``biomorph motion …``: MotionLab on the command line.

Reads BVH, HTR or ASF/AMC; writes BVH (or glTF ``.glb``). Angles are given in **degrees**,
frames as 0-based frame numbers of the input. Curves are ``frame:value`` keys separated by
commas (``"0:1,120:2,240:1"``), vector keys with ``/`` between components
(``"100:0/0/30;150:0/0/-10"``), or a JSON file ``[[frame, value], …]``. Every command
computes first and writes atomically, so a failure leaves no output behind (exit code 2 and
one line on stderr for bad input).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Any

import typer

from biomorph._cli import bounded
from biomorph.errors import ParameterError, UnsupportedFormatError

app = typer.Typer(
    name="motion",
    no_args_is_help=True,
    add_completion=False,
    help="MotionLab: equalize, edit, blend, retime and loop motion capture.",
)

OUT_FORMATS = (".bvh", ".glb")
# Longest clip a retiming command writes: 10 M frames is a day at 120 fps (about 14 GB of
# float64 channels for 60 joints), far beyond any capture, and below what runs out of memory.
MAX_OUTPUT_FRAMES = 10_000_000

Json = Annotated[bool, typer.Option("--json", help="Print a machine-readable summary.")]
Up = Annotated[
    str | None,
    typer.Option(
        "--up", help="Vertical axis of the input (z: convert Z-up data to Y-up before editing)."
    ),
]
Output = Annotated[Path, typer.Option("-o", "--output", help="Output .bvh or .glb.")]
Strict = Annotated[
    bool, typer.Option("--strict", help="Refuse files whose frame count disagrees with their data.")
]
Feet = Annotated[
    bool,
    typer.Option(
        "--lock-feet/--no-lock-feet",
        help="Keep planted feet in place after the operator (contact detection + two-bone IK).",
    ),
]
Euler = Annotated[
    str,
    typer.Option("--euler", help="BVH angles: wrap (±180°) or continuous (unwrapped over time)."),
]
Preview = Annotated[
    Path | None,
    typer.Option("--preview", help="Also write an animated preview (.gif, or .mp4 with ffmpeg)."),
]


def _read(path: Path, up: str | None = None, strict: bool | None = None):
    import warnings

    from biomorph import io
    from biomorph._cli import err_console
    from biomorph.core.motion import MotionInputWarning, to_y_up

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MotionInputWarning)
        mo = io.read_motion(path, strict=bool(strict))
    for w in caught:
        if issubclass(w.category, MotionInputWarning):
            err_console.print(f"warning: {w.message}", markup=False, highlight=False)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if up is not None:
        mo = to_y_up(mo, up)
    return mo


def _lock(mo, reference=None, ground=()):
    """Lock planted feet (against ``reference`` when it shares the timing; no foot below the
    lowest foot of the ``ground`` inputs with the same skeleton), one warning line each."""
    import warnings

    from biomorph._cli import err_console
    from biomorph.motion.contact import (  # numba: only to lock
        ContactWarning,
        inputs_floor,
        lock_feet,
    )

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ContactWarning)
        mo = lock_feet(mo, reference, floor=inputs_floor(mo, ground))
    for w in caught:
        err_console.print(f"warning: {w.message}", markup=False, highlight=False)
    return mo


def _resample(mo, fps: float, lock: bool):
    """``timewarp.resample`` (feet locked on the input's contacts unless ``lock`` is off),
    one warning line for each contact target out of reach."""
    import warnings

    from biomorph._cli import err_console
    from biomorph.motion.timewarp import resample

    if not lock:
        return resample(mo, fps, lock_feet=False)
    from biomorph.motion.contact import ContactWarning  # numba: only to lock

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ContactWarning)
        out = resample(mo, fps)
    for w in caught:
        if issubclass(w.category, ContactWarning):
            err_console.print(f"warning: {w.message}", markup=False, highlight=False)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return out


def _finish(
    path: Path,
    mo,
    reference=None,
    lock: bool = True,
    euler: str = "wrap",
    preview: Path | None = None,
    ground=(),
):
    """Lock planted feet (against ``reference`` when it shares the timing; no foot below
    the lowest foot of the ``ground`` inputs with the same skeleton), write, and render the
    preview (checked before anything is written)."""
    import shutil

    from biomorph._cli import check_suffix

    if euler not in ("wrap", "continuous"):
        raise ParameterError(f"--euler {euler!r}; expected wrap or continuous")
    if preview is not None:
        check_suffix(preview, (".gif", ".mp4"), "--preview")
        if preview.suffix.lower() == ".mp4" and shutil.which("ffmpeg") is None:
            raise UnsupportedFormatError(
                f"--preview {preview}: MP4 needs ffmpeg (apt-get "
                "install ffmpeg); write a .gif instead"
            )
    if lock:
        mo = _lock(mo, reference, ground)
    _write(path, mo, euler)
    if preview is not None:
        from biomorph.motion.preview import render_preview

        render_preview(mo, preview)
    return mo


def _check_out(path: Path) -> None:
    if path.suffix.lower() not in OUT_FORMATS:
        raise UnsupportedFormatError(
            f"{path}: cannot write motion as {path.suffix or '(none)'};"
            f" expected one of {' '.join(OUT_FORMATS)}"
        )


def _write(path: Path, mo, euler: str = "wrap") -> Path:
    from biomorph import io

    if path.suffix.lower() == ".glb":
        return io.write_gltf(path, mo)
    return io.write_bvh(path, mo, euler=euler)


def _floats(text: str, name: str) -> list[float]:
    try:
        vals = [float(v) for v in text.replace(";", ",").split(",") if v.strip()]
    except ValueError:
        raise ParameterError(f"--{name} {text!r}: expected comma-separated numbers") from None
    if not vals:
        raise ParameterError(f"--{name} is empty; expected comma-separated numbers")
    bad = [v for v in vals if not (abs(v) <= 1e12)]  # NaN fails the comparison too
    if bad:
        raise ParameterError(
            f"--{name} {text!r}: value {bad[0]!r}; expected finite numbers with |x| <= 1e12"
        )
    return vals


def _summary(mo, out: Path | None, t0: float, **extra: Any) -> dict[str, Any]:
    d = {
        "frames": mo.n_frames,
        "fps": mo.fps,
        "duration_s": mo.duration,
        "joints": mo.n_joints,
        "seconds": round(time.perf_counter() - t0, 4),
    }
    if out is not None:
        d["output"] = str(out)
    d.update(extra)
    return d


def _emit(summary: dict[str, Any], as_json: bool) -> None:
    from biomorph._cli import emit

    emit(summary, as_json)


def _deg_keys(text: str, dim: int) -> list[tuple[float, Any]]:
    from biomorph.motion.keys import parse_keys

    return parse_keys(text, dim=dim)


@app.command()
def info(
    path: Annotated[Path, typer.Argument(help="BVH, HTR or ASF/AMC file.")],
    up: Up = None,
    strict: Strict = False,
    as_json: Json = False,
) -> None:
    """Sizes, rates, fastest joints, Euler wraps, foot skate, and what the reader tolerated.

    Example: biomorph motion info walk.bvh --json
    """
    from biomorph.motion.quality import quality_report

    mo = _read(path, up, strict)
    rep = quality_report(mo)
    rep["file"] = str(path)
    rep["tolerated"] = list(mo.meta.get("tolerated", []))
    if as_json:
        _emit(rep, True)
        return
    from rich.table import Table

    from biomorph._cli import out_console

    t = Table(title=str(path), show_header=False)
    for k, v in rep.items():
        if k == "fastest_joints":
            v = "; ".join(f"{r['joint']} {r['max_speed_deg_s']:.0f}°/s" for r in v)
        elif k == "foot_skate" and not v["feet"]:
            v = "no feet (no joint named foot/toe/ankle, no name preset): not measured"
        elif k == "foot_skate":
            v = (
                f"{v['skate_speed']:.4g} units/s ({v['skate_per_body_scale']:.3g} body/s), "
                f"contact {100 * v['contact_fraction']:.0f}%, ground {v['ground_height']:.3g}, "
                f"band travel {v['band_travel']:.3g} body/s"
            )
        elif k == "tolerated":
            v = "; ".join(v) if v else "nothing"
        elif isinstance(v, float):
            v = f"{v:.6g}"
        t.add_row(k, str(v))
    out_console.print(t)


Gain = Annotated[str, typer.Option(help="Band gains, highest band first.")]


@app.command()
def equalize(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Output,
    gains: Gain = "1,1,1,1,1",
    joint: Annotated[list[str] | None, typer.Option(help="Joint(s); default all.")] = None,
    below: Annotated[
        bool, typer.Option("--below", help="Include the hierarchy below each joint.")
    ] = False,
    channels: Annotated[str, typer.Option(help="all | rotation | position")] = "all",
    boundary: Annotated[str, typer.Option(help="edge | reflect")] = "edge",
    root: Annotated[
        str, typer.Option(help="Last gain on the root path: trajectory (kept) | start | world.")
    ] = "trajectory",
    up: Up = None,
    strict: Strict = False,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Motion Equalizer: scale frequency bands (à-trous filter bank), feet kept planted.

    Example: biomorph motion equalize walk.bvh -o smooth.bvh --gains 0,0,1,1,1
    """
    from biomorph.motion.equalizer import equalize as eq

    _check_out(output)
    g = _floats(gains, "gains")
    t0 = time.perf_counter()
    src = _read(path, up, strict)
    mo = eq(src, g, joint, channels, below, boundary, root)
    mo = _finish(output, mo, src, lock_feet, euler, preview)
    _emit(_summary(mo, output, t0, gains=g), as_json)


@app.command()
def edit(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Output,
    joint: Annotated[str, typer.Option(help="Joint to edit.")],
    key: Annotated[
        str,
        typer.Option(
            help="Offset keys frame:x/y/z; rotation offsets are "
            "rotation vectors in degrees (joint frame), "
            "position offsets in file units."
        ),
    ],
    kind: Annotated[str, typer.Option(help="rotation | position")] = "rotation",
    fade: Annotated[
        float | None,
        typer.Option(help="Fade in/out frames (default 0.25 s).", callback=bounded(0, 1e7)),
    ] = None,
    tangent: Annotated[
        str, typer.Option(help="auto (clamped, no overshoot) | spline | linear | flat")
    ] = "auto",
    up: Up = None,
    strict: Strict = False,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Displacement map: add a smooth offset curve through keys to one joint.

    Example: biomorph motion edit walk.bvh -o reach.bvh --joint RightArm --key "120:0/0/30"
    """
    import numpy as np

    from biomorph.motion.displacement import displace

    _check_out(output)
    t0 = time.perf_counter()
    keys = _deg_keys(key, 3)
    if kind == "rotation":
        keys = [(f, np.radians(v)) for f, v in keys]
    src = _read(path, up, strict)
    mo = displace(src, joint, keys, kind, fade, tangent=tangent)
    mo = _finish(output, mo, src, lock_feet, euler, preview)
    _emit(_summary(mo, output, t0, keys=len(keys)), as_json)


@app.command()
def layers(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Output,
    layer: Annotated[
        list[str],
        typer.Option(
            help="name:joint:kind:weight:keys, e.g. 'reach:RightArm:rotation:1:120:0/0/30' "
            "(repeat for more layers; rotation keys in degrees)."
        ),
    ],
    up: Up = None,
    strict: Strict = False,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Additive animation layers (overAnimate): each layer a displacement map with a weight.

    Example: biomorph motion layers walk.bvh -o out.bvh --layer "up:Hips:position:1:60:0/2/0"
    """
    import numpy as np

    from biomorph.motion.displacement import Layer, apply_layers

    _check_out(output)
    t0 = time.perf_counter()
    made = []
    for text in layer:
        parts = text.split(":", 4)
        if len(parts) != 5:
            raise ParameterError(f"--layer {text!r}: expected name:joint:kind:weight:keys")
        name, joint, kind, weight, keys = parts
        try:
            w = float(weight)
        except ValueError:
            raise ParameterError(f"--layer {text!r}: weight {weight!r} is not a number") from None
        from biomorph._cli import check_value

        check_value("--layer weight", w, -1e6, 1e6)
        k = _deg_keys(keys, 3)
        if kind == "rotation":
            k = [(f, np.radians(v)) for f, v in k]
        made.append(Layer.make(name, joint, k, kind, w))
    src = _read(path, up, strict)
    mo = apply_layers(src, made)
    mo = _finish(output, mo, src, lock_feet, euler, preview)
    _emit(_summary(mo, output, t0, layers=len(made)), as_json)


@app.command()
def reorient(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Output,
    angle: Annotated[
        float, typer.Option(help="Turn about the vertical, degrees.", callback=bounded(-1e6, 1e6))
    ] = 0.0,
    move: Annotated[str, typer.Option(help="Translation x,y,z (file units).")] = "0,0,0",
    up: Up = None,
    strict: Strict = False,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Re-orient / re-position the whole motion (root recomputed, the rest untouched).

    Example: biomorph motion reorient walk.bvh -o west.bvh --angle 90 --move 0,0,2
    """
    import numpy as np

    from biomorph._cli import check_value
    from biomorph.motion.align import reorient as ro

    _check_out(output)
    t = _floats(move, "move")
    if len(t) != 3:
        raise ParameterError(f"--move {move!r}: expected three numbers x,y,z")
    for v in t:
        check_value("--move", v, -1e12, 1e12)
    t0 = time.perf_counter()
    mo = ro(_read(path, up, strict), np.radians(angle), t)
    _finish(output, mo, None, False, euler, preview)
    _emit(_summary(mo, output, t0, angle_deg=angle), as_json)


@app.command()
def blend(
    paths: Annotated[list[Path], typer.Argument(help="Two or more clips, same skeleton.")],
    output: Output,
    transition: Annotated[
        float, typer.Option(help="Cross-fade length, frames.", callback=bounded(0, 1e7))
    ] = 30,
    offsets: Annotated[str | None, typer.Option(help="Start frame of every clip.")] = None,
    scales: Annotated[str | None, typer.Option(help="Time scale of every clip.")] = None,
    curve: Annotated[
        str | None, typer.Option(help="Weight of B: keys frame:w or a number (two clips).")
    ] = None,
    align: Annotated[str | None, typer.Option(help="peaks | dtw (automatic timing).")] = None,
    align_joint: Annotated[str | None, typer.Option(help="Joint for --align peaks.")] = None,
    align_channel: Annotated[str, typer.Option(help="Channel for --align peaks.")] = "Xrotation",
    no_align_root: Annotated[
        bool, typer.Option("--no-align-root", help="Keep each clip's root.")
    ] = False,
    joint: Annotated[
        str | None,
        typer.Option(
            help="Blend only this joint and the hierarchy below it (the rest from the first clip)."
        ),
    ] = None,
    up: Up = None,
    strict: Strict = False,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Blend clips with a blend curve, timing offsets/scales and automatic alignment.

    Example: biomorph motion blend walk.bvh run.bvh -o walk2run.bvh --transition 40
    --align peaks --align-joint LeftUpLeg
    """
    from biomorph.motion.blending import blend as bl
    from biomorph.motion.keys import parse_keys
    from biomorph.motion.partial import merge_below

    _check_out(output)
    if len(paths) < 2:
        raise ParameterError("blend needs at least two input clips")
    t0 = time.perf_counter()
    clips = [_read(p, up, strict) for p in paths]
    off = None if offsets is None else _floats(offsets, "offsets")
    sc = None if scales is None else _floats(scales, "scales")
    cv: Any = None
    if curve is not None:
        from biomorph._cli import check_value

        try:
            cv = float(curve)
        except ValueError:
            cv = [(f, float(v[0])) for f, v in parse_keys(curve, dim=1)]
        for w in [cv] if isinstance(cv, float) else [w for _, w in cv]:
            check_value("--curve", w, 0, 1)  # a weight of clip B (NaN or 2 is no weight)
    mo = bl(clips, off, sc, transition, cv, not no_align_root, align, align_joint, align_channel)
    ref = None
    if joint is not None:
        mo = merge_below(clips[0], mo, joint)
        ref = clips[0]
    mo = _finish(output, mo, ref, lock_feet, euler, preview, clips)
    _emit(_summary(mo, output, t0, offsets=mo.meta["blend"]["offsets"]), as_json)


@app.command()
def speed(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Output,
    curve: Annotated[
        str, typer.Option("--speed", help="Constant or keys frame:speed (1 = original).")
    ] = "1",
    joint: Annotated[
        str | None,
        typer.Option(
            help="Retime only this joint and the hierarchy below it (the rest keeps its "
            "timing; output keeps the input's length)."
        ),
    ] = None,
    up: Up = None,
    strict: Strict = False,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Retime with a speed curve (2 = twice as fast), output at the original frame rate.

    Example: biomorph motion speed walk.bvh -o fast.bvh --speed "0:1,100:2,200:1"
    """
    from biomorph._cli import check_value
    from biomorph.motion.keys import parse_keys
    from biomorph.motion.partial import merge_below
    from biomorph.motion.timewarp import change_speed

    _check_out(output)
    t0 = time.perf_counter()
    try:
        sp: Any = float(curve)
        check_value("--speed", sp, 0, 1e6, lo_open=True)
    except ValueError:
        sp = [(f, float(v[0])) for f, v in parse_keys(curve, dim=1)]
    src = _read(path, up, strict)
    if not isinstance(sp, float):
        bad = [f for f, _ in sp if not 0 <= f <= src.n_frames - 1]
        if bad:
            raise ParameterError(
                f"speed key at frame {bad[0]:g} is outside the clip; expected 0..{src.n_frames - 1}"
            )
        for _, v in sp:
            check_value("--speed", v, 0, 1e6, lo_open=True)
    slowest = sp if isinstance(sp, float) else min(v for _, v in sp)
    out_frames = src.n_frames / slowest
    if out_frames > MAX_OUTPUT_FRAMES:
        raise ParameterError(
            f"--speed {slowest:g} would make {out_frames:.3g} frames from "
            f"{src.n_frames}; at most {MAX_OUTPUT_FRAMES:,} frames are "
            "written (use a speed of at least "
            f"{src.n_frames / MAX_OUTPUT_FRAMES:.3g})"
        )
    mo = change_speed(src, sp)
    ref = None
    if joint is not None:
        mo = merge_below(src, mo, joint)
        ref = src
    mo = _finish(output, mo, ref, lock_feet, euler, preview, [src])
    _emit(_summary(mo, output, t0, frames_in=src.n_frames), as_json)


@app.command()
def cycle(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Output,
    start: Annotated[
        int | None, typer.Option(help="First frame of the range.", callback=bounded(0, 1e9))
    ] = None,
    stop: Annotated[
        int | None, typer.Option(help="End frame (exclusive).", callback=bounded(1, 1e9))
    ] = None,
    transition: Annotated[
        int, typer.Option(help="Cross-fade frames.", callback=bounded(1, 1e7))
    ] = 10,
    cycles: Annotated[
        int, typer.Option(help="Number of cycles to write.", callback=bounded(1, 10000))
    ] = 1,
    auto: Annotated[bool, typer.Option("--auto", help="Search the best loop range.")] = False,
    min_length: Annotated[
        int, typer.Option(help="Shortest loop for --auto.", callback=bounded(2, 1e9))
    ] = 30,
    mode: Annotated[
        str,
        typer.Option(
            help="world (travel on) | in-place | root-motion (path on a ground-level root joint)."
        ),
    ] = "world",
    no_offset: Annotated[
        bool, typer.Option("--no-offset", help="Same as --mode in-place.")
    ] = False,
    joint: Annotated[
        str | None,
        typer.Option(
            help="Loop only this joint and the hierarchy below it over the input's length "
            "(the rest as captured)."
        ),
    ] = None,
    up: Up = None,
    strict: Strict = False,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Make a seamless loop (cycle with offset, in place, or root motion); never teleports.

    Example: biomorph motion cycle walk.bvh -o loop.bvh --auto --transition 12 --cycles 4
    """
    from biomorph.motion.cycle import best_loop, make_cycle

    _check_out(output)
    t0 = time.perf_counter()
    mo = _read(path, up, strict)
    cost = None
    if auto:
        start, stop, cost = best_loop(mo, min_length, None, transition)
    s = 0 if start is None else start
    e = mo.n_frames if stop is None else stop
    up_axis = (up and "y") or mo.meta.get("up_guess") or "y"
    whole = joint is None and lock_feet  # lock the world-space cycle before in-place / root
    out = make_cycle(
        mo,
        s,
        e,
        transition,
        cycles,
        up=up_axis,
        mode="in-place" if no_offset else mode,
        lock=(lambda c: _lock(c, None, [mo])) if whole else None,
    )
    ref = None
    if joint is not None:
        from biomorph.motion.partial import merge_below

        info = out.meta["cycle"]
        out = merge_below(mo, out, joint)
        out.meta["cycle"] = info
        ref = mo
    locked_here = lock_feet and not whole and mode != "root-motion"
    out = _finish(output, out, ref, locked_here, euler, preview, [mo])
    _emit(
        _summary(
            out,
            output,
            t0,
            start=s,
            stop=e,
            period=out.meta["cycle"]["period"],
            mode=out.meta["cycle"]["mode"],
            loop_cost=cost,
            **({"drift": out.meta["cycle"]["drift"]} if "drift" in out.meta["cycle"] else {}),
        ),
        as_json,
    )


@app.command()
def root(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Output,
    action: Annotated[
        str,
        typer.Option(
            help="extract (path onto a ground-level root "
            "joint) | in-place | apply (fold a ground "
            "root back into the hips)."
        ),
    ] = "extract",
    keep_heading: Annotated[
        bool,
        typer.Option("--keep-heading", help="Leave the turns in the body (path translation only)."),
    ] = False,
    up: Up = None,
    strict: Strict = False,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Root motion: extract the path to a ground-level root, make a clip in place, re-apply.

    Example: biomorph motion root walk.bvh -o walk_rm.bvh --action extract
    """
    from biomorph.motion import rootmotion as rm

    _check_out(output)
    t0 = time.perf_counter()
    mo = _read(path, up, strict)
    up_axis = (up and "y") or mo.meta.get("up_guess") or "y"
    if action == "extract":
        out = rm.extract_root_motion(mo, up_axis, with_heading=not keep_heading)
    elif action == "in-place":
        out = rm.in_place(mo, up_axis, with_heading=not keep_heading)
    elif action == "apply":
        out = rm.apply_root_motion(mo)
    else:
        raise ParameterError(f"--action {action!r}; expected extract, in-place or apply")
    _finish(output, out, None, False, euler, preview)
    _emit(_summary(out, output, t0, action=action), as_json)


@app.command()
def trim(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Output,
    start: Annotated[int, typer.Option(help="First frame kept.", callback=bounded(0, 1e12))] = 0,
    stop: Annotated[
        int | None,
        typer.Option(help="End frame (exclusive; default: the end).", callback=bounded(1, 1e12)),
    ] = None,
    up: Up = None,
    strict: Strict = False,
    lock_feet: Annotated[
        bool,
        typer.Option(
            "--lock-feet/--no-lock-feet",
            help="Also hold the planted feet of the part (default: a plain cut, the frames "
            "as they are in the input).",
        ),
    ] = False,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Keep frames start..stop-1 (a cut: the frames are the input's unless --lock-feet).

    Example: biomorph motion trim take.bvh -o part.bvh --start 120 --stop 480
    """
    _check_out(output)
    t0 = time.perf_counter()
    mo = _read(path, up, strict)
    out = mo.frames(start, mo.n_frames if stop is None else stop)
    out = _finish(output, out, None, lock_feet, euler, preview, [mo])
    _emit(_summary(out, output, t0, start=start), as_json)


@app.command()
def convert(
    path: Annotated[Path, typer.Argument(help="BVH, HTR or ASF/AMC.")],
    output: Output,
    fps: Annotated[
        float | None,
        typer.Option(help="Resample to this rate.", callback=bounded(0, 10000, lo_open=True)),
    ] = None,
    up: Up = None,
    strict: Strict = False,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Convert (and optionally resample / make Y-up) a motion to BVH or glTF; a resample
    keeps planted feet planted (contacts found on the input, --no-lock-feet to skip).

    Example: biomorph motion convert take.htr -o take.bvh --fps 30
    """
    _check_out(output)
    t0 = time.perf_counter()
    mo = _read(path, up, strict)
    if fps is not None:
        mo = _resample(mo, fps, lock_feet)
    _finish(output, mo, None, False, euler, preview)
    _emit(_summary(mo, output, t0), as_json)


@app.command()
def mirror(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Output,
    up: Up = None,
    strict: Strict = False,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Swap left and right (names Left/Right, .L/.R, _l/_r, L_/R_): a mirror-image clip.

    Example: biomorph motion mirror walk.bvh -o walk_mirrored.bvh
    """
    from biomorph.motion.retarget import mirror as mi

    _check_out(output)
    t0 = time.perf_counter()
    src = _read(path, up, strict)
    out = mi(src)
    out = _finish(output, out, None, lock_feet, euler, preview, [src])
    _emit(_summary(out, output, t0), as_json)


@app.command()
def retarget(
    path: Annotated[Path, typer.Argument(help="Source motion.")],
    output: Output,
    to: Annotated[
        Path,
        typer.Option(
            "--to", help="Target skeleton: any motion file (BVH/HTR/ASF; its skeleton is used)."
        ),
    ],
    source_names: Annotated[
        str | None,
        typer.Option(
            help="Source name preset: cmu | cmu_asf | cmu_max | mixamo | humanik | rokoko | "
            "rigify | creature | htr (default: detected)."
        ),
    ] = None,
    target_names: Annotated[
        str | None, typer.Option(help="Target name preset (default: detected).")
    ] = None,
    map_csv: Annotated[
        Path | None,
        typer.Option("--map", help="CSV of source,target joint names (instead of presets)."),
    ] = None,
    up: Up = None,
    strict: Strict = False,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    preview: Preview = None,
    as_json: Json = False,
) -> None:
    """Play a clip on another skeleton (other names, proportions, rest pose); feet planted.

    Example: biomorph motion retarget cmu_walk.bvh --to mixamo_char.bvh -o walk_on_char.bvh
    """
    from biomorph.motion.retarget import retarget as rt

    _check_out(output)
    t0 = time.perf_counter()
    src = _read(path, up, strict)
    tgt = _read(to, None, strict)
    import warnings

    from biomorph._cli import err_console

    if lock_feet:  # retarget locks on the source's contacts where the feet differ (numba)
        from biomorph.motion.contact import ContactWarning

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ContactWarning)
            out = rt(src, tgt.skeleton, source_names, target_names, map_csv, feet=True)
        for w in caught:
            if issubclass(w.category, ContactWarning):
                err_console.print(f"warning: {w.message}", markup=False, highlight=False)
    else:
        out = rt(src, tgt.skeleton, source_names, target_names, map_csv, feet=False)
    out = _finish(output, out, None, False, euler, preview)
    _emit(
        _summary(
            out,
            output,
            t0,
            mapped=out.meta["retarget"]["joints"],
            leg_scale=out.meta["retarget"]["leg_scale"],
        ),
        as_json,
    )


@app.command()
def batch(
    inputs: Annotated[list[Path], typer.Argument(help="Motion files (BVH/HTR/ASF).")],
    op: Annotated[
        list[str],
        typer.Option(
            "--op",
            help="Operator step name[:key=value,…], applied in order (repeat); "
            "e.g. equalize:gains=0/0/1/1/1  cycle:auto=1,mode=in-place.",
        ),
    ],
    out: Annotated[Path, typer.Option("--out", help="Output folder (OUT/<name>.bvh).")] = Path(
        "motion-batch"
    ),
    workers: Annotated[
        int | None,
        typer.Option(
            help="Worker processes (0 = serial; default: CPU count).", callback=bounded(0, 1024)
        ),
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option(help="Address of a running dask scheduler.")
    ] = None,
    lock_feet: Feet = True,
    euler: Euler = "wrap",
    as_json: Json = False,
) -> None:
    """Apply a chain of operators to many files in parallel (dask), feet locked after each.

    Failed inputs are reported without stopping the others; re-runs resume. Exit code 1 if
    any input failed.

    Example: biomorph motion batch takes/*.bvh --op equalize:gains=0/0/1/1/1 --op
    cycle:auto=1,transition=12,cycles=4,mode=in-place --out loops/
    """
    from biomorph.motion.chain import Step, batch_item
    from biomorph.scale.batch import run_batch

    if not inputs:
        raise ParameterError("no input files given")
    if euler not in ("wrap", "continuous"):
        raise ParameterError(f"--euler {euler!r}; expected wrap or continuous")
    stems = [p.stem for p in inputs]
    if len(set(stems)) != len(stems):
        raise ParameterError("input file names must be unique (outputs go to OUT/<name>.bvh)")
    steps = [Step.parse(t) for t in op]
    out.mkdir(parents=True, exist_ok=True)
    items = [(str(p), str(out / f"{p.stem}.bvh"), steps, lock_feet, euler) for p in inputs]
    report = run_batch(
        items,
        batch_item,
        out_dir=out,
        key=lambda it: Path(it[0]).stem,
        workers=workers,
        scheduler=scheduler,
        description="motions",
        options={"ops": op, "lock_feet": lock_feet, "euler": euler},
    )
    if as_json:
        from biomorph._cli import print_json

        data = report.to_dict()
        data["results"] = report.results
        print_json(data)
    else:
        from biomorph._cli import err_console, out_console

        out_console.print(report.summary())
        for key, msg in report.failed:
            err_console.print(f"failed: {key}: {msg}")
    if report.exit_code:
        raise typer.Exit(report.exit_code)


@app.command()
def plot(
    path: Annotated[Path, typer.Argument(help="Input motion.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="PNG to write.")],
    joint: Annotated[str | None, typer.Option(help="Joint (default: first with motion).")] = None,
    channel: Annotated[str, typer.Option(help="Xrotation.. or Xposition..")] = "Xrotation",
    gains: Annotated[str | None, typer.Option(help="Also draw the equalized channel.")] = None,
    kind: Annotated[str, typer.Option(help="bands | poses")] = "bands",
    up: Up = None,
    as_json: Json = False,
) -> None:
    """PNG of a channel with its frequency bands, or a strip of poses.

    Example: biomorph motion plot walk.bvh -o bands.png --joint LeftUpLeg --gains 0,0,1,1,1
    """
    import numpy as np

    from biomorph.motion.plots import plot_bands, plot_poses

    if output.suffix.lower() != ".png":
        raise UnsupportedFormatError(f"{output}: plots are PNG; expected a .png output")
    t0 = time.perf_counter()
    mo = _read(path, up)
    if kind == "poses":
        frames = np.linspace(0, mo.n_frames - 1, 8).round().astype(int)
        plot_poses([(path.name, mo)], frames, output)
    elif kind == "bands":
        j = joint if joint is not None else mo.names[min(1, mo.n_joints - 1)]
        x = mo.channel(j, channel, degrees=True)
        levels = min(4, max(1, int(np.floor(np.log2(mo.n_frames)))))
        g = None if gains is None else _floats(gains, "gains")
        plot_bands(x, output, levels, mo.fps, g, title=f"{path.name}: {j}.{channel}")
    else:
        raise ParameterError(f"--kind {kind!r}; expected bands or poses")
    _emit(_summary(mo, output, t0), as_json)


__all__ = ["app"]
