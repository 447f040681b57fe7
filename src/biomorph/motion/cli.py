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

from biomorph.errors import ParameterError, UnsupportedFormatError

app = typer.Typer(name="motion", no_args_is_help=True, add_completion=False,
                  help="MotionLab: equalize, edit, blend, retime and loop motion capture.")

OUT_FORMATS = (".bvh", ".glb")

Json = Annotated[bool, typer.Option("--json", help="Print a machine-readable summary.")]
Up = Annotated[str | None, typer.Option("--up", help="Vertical axis of the input (z: convert "
                                                     "Z-up data to Y-up before editing).")]
Output = Annotated[Path, typer.Option("-o", "--output", help="Output .bvh or .glb.")]


def _read(path: Path, up: str | None = None):
    from biomorph import io
    from biomorph.motion.align import to_y_up

    mo = io.read_motion(path)
    if up is not None:
        mo = to_y_up(mo, up)
    return mo


def _check_out(path: Path) -> None:
    if path.suffix.lower() not in OUT_FORMATS:
        raise UnsupportedFormatError(f"{path}: cannot write motion as {path.suffix or '(none)'};"
                                     f" expected one of {' '.join(OUT_FORMATS)}")


def _write(path: Path, mo) -> Path:
    from biomorph import io

    if path.suffix.lower() == ".glb":
        return io.write_gltf(path, mo)
    return io.write_bvh(path, mo)


def _floats(text: str, name: str) -> list[float]:
    try:
        vals = [float(v) for v in text.replace(";", ",").split(",") if v.strip()]
    except ValueError:
        raise ParameterError(f"--{name} {text!r}: expected comma-separated numbers") from None
    if not vals:
        raise ParameterError(f"--{name} is empty; expected comma-separated numbers")
    return vals


def _summary(mo, out: Path | None, t0: float, **extra: Any) -> dict[str, Any]:
    d = {"frames": mo.n_frames, "fps": mo.fps, "duration_s": mo.duration,
         "joints": mo.n_joints, "seconds": round(time.perf_counter() - t0, 4)}
    if out is not None:
        d["output"] = str(out)
    d.update(extra)
    return d


def _emit(summary: dict[str, Any], as_json: bool) -> None:
    from biomorph._cli import out_console, print_json

    if as_json:
        print_json(summary)
    else:
        out_console.print(", ".join(f"{k}={v}" for k, v in summary.items()))


def _deg_keys(text: str, dim: int) -> list[tuple[float, Any]]:
    from biomorph.motion.keys import parse_keys

    return parse_keys(text, dim=dim)


@app.command()
def info(path: Annotated[Path, typer.Argument(help="BVH, HTR or ASF/AMC file.")],
         up: Up = None, as_json: Json = False) -> None:
    """Sizes, rates, fastest joints (angular speed/acceleration), Euler wraps, foot skate.

    Example: biomorph motion info walk.bvh --json
    """
    from biomorph.motion.quality import quality_report

    mo = _read(path, up)
    rep = quality_report(mo)
    rep["file"] = str(path)
    if as_json:
        _emit(rep, True)
        return
    from rich.table import Table

    from biomorph._cli import out_console

    t = Table(title=str(path), show_header=False)
    for k, v in rep.items():
        if k == "fastest_joints":
            v = "; ".join(f"{r['joint']} {r['max_speed_deg_s']:.0f}°/s" for r in v)
        elif k == "foot_skate":
            v = (f"{v['skate_speed']:.4g} units/s ({v['skate_per_body_scale']:.3g} body/s), "
                 f"contact {100 * v['contact_fraction']:.0f}%, ground {v['ground_height']:.3g}")
        elif isinstance(v, float):
            v = f"{v:.6g}"
        t.add_row(k, str(v))
    out_console.print(t)


@app.command()
def equalize(path: Annotated[Path, typer.Argument(help="Input motion.")], output: Output,
             gains: Annotated[str, typer.Option(help="Band gains, highest band first.")] =
             "1,1,1,1,1",
             joint: Annotated[list[str] | None, typer.Option(help="Joint(s); default all.")] =
             None,
             below: Annotated[bool, typer.Option("--below", help="Include the hierarchy below "
                                                                 "each joint.")] = False,
             channels: Annotated[str, typer.Option(help="all | rotation | position")] = "all",
             boundary: Annotated[str, typer.Option(help="edge | reflect")] = "edge",
             up: Up = None, as_json: Json = False) -> None:
    """Motion Equalizer: scale frequency bands (à-trous filter bank).

    Example: biomorph motion equalize walk.bvh -o smooth.bvh --gains 0,0,1,1,1
    """
    from biomorph.motion.equalizer import equalize as eq

    _check_out(output)
    t0 = time.perf_counter()
    mo = eq(_read(path, up), _floats(gains, "gains"), joint, channels, below, boundary)
    _write(output, mo)
    _emit(_summary(mo, output, t0, gains=_floats(gains, "gains")), as_json)


@app.command()
def edit(path: Annotated[Path, typer.Argument(help="Input motion.")], output: Output,
         joint: Annotated[str, typer.Option(help="Joint to edit.")],
         key: Annotated[str, typer.Option(help="Offset keys frame:x/y/z; rotation offsets are "
                                               "rotation vectors in degrees (joint frame), "
                                               "position offsets in file units.")],
         kind: Annotated[str, typer.Option(help="rotation | position")] = "rotation",
         fade: Annotated[float | None, typer.Option(help="Fade in/out frames (default "
                                                         "0.25 s).")] = None,
         up: Up = None, as_json: Json = False) -> None:
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
    mo = displace(_read(path, up), joint, keys, kind, fade)
    _write(output, mo)
    _emit(_summary(mo, output, t0, keys=len(keys)), as_json)


@app.command()
def reorient(path: Annotated[Path, typer.Argument(help="Input motion.")], output: Output,
             angle: Annotated[float, typer.Option(help="Turn about the vertical, degrees.")] =
             0.0,
             move: Annotated[str, typer.Option(help="Translation x,y,z (file units).")] =
             "0,0,0",
             up: Up = None, as_json: Json = False) -> None:
    """Re-orient / re-position the whole motion (root recomputed, the rest untouched).

    Example: biomorph motion reorient walk.bvh -o west.bvh --angle 90 --move 0,0,2
    """
    import numpy as np

    from biomorph.motion.align import reorient as ro

    _check_out(output)
    t = _floats(move, "move")
    if len(t) != 3:
        raise ParameterError(f"--move {move!r}: expected three numbers x,y,z")
    t0 = time.perf_counter()
    mo = ro(_read(path, up), np.radians(angle), t)
    _write(output, mo)
    _emit(_summary(mo, output, t0, angle_deg=angle), as_json)


@app.command()
def blend(paths: Annotated[list[Path], typer.Argument(help="Two or more clips, same "
                                                           "skeleton.")],
          output: Output,
          transition: Annotated[float, typer.Option(help="Cross-fade length, frames.")] = 30,
          offsets: Annotated[str | None, typer.Option(help="Start frame of every clip.")] =
          None,
          scales: Annotated[str | None, typer.Option(help="Time scale of every clip.")] = None,
          curve: Annotated[str | None, typer.Option(help="Weight of B: keys frame:w or a "
                                                         "number (two clips).")] = None,
          align: Annotated[str | None, typer.Option(help="peaks | dtw (automatic timing).")] =
          None,
          align_joint: Annotated[str | None, typer.Option(help="Joint for --align peaks.")] =
          None,
          align_channel: Annotated[str, typer.Option(help="Channel for --align peaks.")] =
          "Xrotation",
          no_align_root: Annotated[bool, typer.Option("--no-align-root",
                                                      help="Keep each clip's root.")] = False,
          up: Up = None, as_json: Json = False) -> None:
    """Blend clips with a blend curve, timing offsets/scales and automatic alignment.

    Example: biomorph motion blend walk.bvh run.bvh -o walk2run.bvh --transition 40
    --align peaks --align-joint LeftUpLeg
    """
    from biomorph.motion.blend import blend as bl
    from biomorph.motion.keys import parse_keys

    _check_out(output)
    if len(paths) < 2:
        raise ParameterError("blend needs at least two input clips")
    t0 = time.perf_counter()
    clips = [_read(p, up) for p in paths]
    off = None if offsets is None else _floats(offsets, "offsets")
    sc = None if scales is None else _floats(scales, "scales")
    cv: Any = None
    if curve is not None:
        try:
            cv = float(curve)
        except ValueError:
            cv = [(f, float(v[0])) for f, v in parse_keys(curve, dim=1)]
    mo = bl(clips, off, sc, transition, cv, not no_align_root, align, align_joint,
            align_channel)
    _write(output, mo)
    _emit(_summary(mo, output, t0, offsets=mo.meta["blend"]["offsets"]), as_json)


@app.command()
def speed(path: Annotated[Path, typer.Argument(help="Input motion.")], output: Output,
          curve: Annotated[str, typer.Option("--speed", help="Constant or keys frame:speed "
                                                             "(1 = original).")] = "1",
          up: Up = None, as_json: Json = False) -> None:
    """Retime with a speed curve (2 = twice as fast), output at the original frame rate.

    Example: biomorph motion speed walk.bvh -o fast.bvh --speed "0:1,100:2,200:1"
    """
    from biomorph.motion.keys import parse_keys
    from biomorph.motion.timewarp import change_speed

    _check_out(output)
    t0 = time.perf_counter()
    try:
        sp: Any = float(curve)
    except ValueError:
        sp = [(f, float(v[0])) for f, v in parse_keys(curve, dim=1)]
    src = _read(path, up)
    if not isinstance(sp, float):
        bad = [f for f, _ in sp if not 0 <= f <= src.n_frames - 1]
        if bad:
            raise ParameterError(f"speed key at frame {bad[0]:g} is outside the clip; "
                                 f"expected 0..{src.n_frames - 1}")
    mo = change_speed(src, sp)
    _write(output, mo)
    _emit(_summary(mo, output, t0, frames_in=src.n_frames), as_json)


@app.command()
def cycle(path: Annotated[Path, typer.Argument(help="Input motion.")], output: Output,
          start: Annotated[int | None, typer.Option(help="First frame of the range.")] = None,
          stop: Annotated[int | None, typer.Option(help="End frame (exclusive).")] = None,
          transition: Annotated[int, typer.Option(help="Cross-fade frames.")] = 10,
          cycles: Annotated[int, typer.Option(help="Number of cycles to write.")] = 1,
          auto: Annotated[bool, typer.Option("--auto", help="Search the best loop range.")] =
          False,
          min_length: Annotated[int, typer.Option(help="Shortest loop for --auto.")] = 30,
          no_offset: Annotated[bool, typer.Option("--no-offset",
                                                  help="Loop in place.")] = False,
          up: Up = None, as_json: Json = False) -> None:
    """Make a seamless loop (cycle with offset); --auto finds the best range.

    Example: biomorph motion cycle walk.bvh -o loop.bvh --auto --transition 12 --cycles 4
    """
    from biomorph.motion.cycle import best_loop, make_cycle

    _check_out(output)
    t0 = time.perf_counter()
    mo = _read(path, up)
    cost = None
    if auto:
        start, stop, cost = best_loop(mo, min_length, None, transition)
    s = 0 if start is None else start
    e = mo.n_frames if stop is None else stop
    out = make_cycle(mo, s, e, transition, cycles, not no_offset)
    _write(output, out)
    _emit(_summary(out, output, t0, start=s, stop=e, period=out.meta["cycle"]["period"],
                   loop_cost=cost), as_json)


@app.command()
def convert(path: Annotated[Path, typer.Argument(help="BVH, HTR or ASF/AMC.")], output: Output,
            fps: Annotated[float | None, typer.Option(help="Resample to this rate.")] = None,
            up: Up = None, as_json: Json = False) -> None:
    """Convert (and optionally resample / make Y-up) a motion to BVH or glTF.

    Example: biomorph motion convert take.htr -o take.bvh --fps 30
    """
    _check_out(output)
    t0 = time.perf_counter()
    mo = _read(path, up)
    if fps is not None:
        mo = mo.resample(fps)
    _write(output, mo)
    _emit(_summary(mo, output, t0), as_json)


@app.command()
def plot(path: Annotated[Path, typer.Argument(help="Input motion.")],
         output: Annotated[Path, typer.Option("-o", "--output", help="PNG to write.")],
         joint: Annotated[str | None, typer.Option(help="Joint (default: first with "
                                                        "motion).")] = None,
         channel: Annotated[str, typer.Option(help="Xrotation.. or Xposition..")] =
         "Xrotation",
         gains: Annotated[str | None, typer.Option(help="Also draw the equalized "
                                                        "channel.")] = None,
         kind: Annotated[str, typer.Option(help="bands | poses")] = "bands",
         up: Up = None, as_json: Json = False) -> None:
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
