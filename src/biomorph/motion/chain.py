"""Operator chains: ``"equalize:gains=0/0/1/1/1" "cycle:mode=in-place,transition=12"`` applied
in order to a clip, with planted feet locked after every operator (the behaviour of the
single-operator CLI commands: not after ``trim``, a cut, nor ``extract-root``; a ``retarget``
locks as the CLI's does, on the source's contacts where the feet are proportioned otherwise,
and a ``resample`` on its input's contacts, as ``convert --fps``), for ``biomorph motion
batch`` and the Python API.

Each step is ``name[:key=value,key=value…]``; vector values use ``/`` between components.
Operators and their keys (angles in degrees, frames 0-based, as on the CLI):

==============  ============================================================================
``equalize``    ``gains`` (a/b/c…), ``root`` (trajectory | start | world), ``joint``, ``below``
``speed``       ``speed`` (constant factor > 0)
``cycle``       ``start``, ``stop``, ``transition``, ``cycles``, ``mode``, ``auto`` (0/1),
                ``min_length``
``trim``        ``start``, ``stop``
``resample``    ``fps``
``reorient``    ``angle``
``mirror``      —
``in-place``    ``heading`` (0/1)
``extract-root``  ``heading`` (0/1)
``retarget``    ``to`` (a motion file whose skeleton is the target), ``source``, ``target``
                (name presets)
==============  ============================================================================
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from biomorph.core.motion import Motion
from biomorph.errors import ParameterError

OPS = (
    "equalize",
    "speed",
    "cycle",
    "trim",
    "resample",
    "reorient",
    "mirror",
    "in-place",
    "extract-root",
    "retarget",
)
_TIMING_KEPT = ("equalize", "reorient", "in-place")  # same frames: feet follow the input
#: steps not locked after: a root extraction, and a trim — a cut, the input's frames as they
#: are (the CLI's ``trim`` too, unless ``--lock-feet``)
_UNLOCKED = ("extract-root", "trim")


@dataclass(frozen=True)
class Step:
    """One operator of a chain and its parameters (strings as given; parsed when applied)."""

    name: str
    params: dict[str, str] = field(default_factory=dict)

    @classmethod
    def parse(cls, text: str) -> Step:
        name, _, rest = text.strip().partition(":")
        name = name.strip().lower()
        if name not in OPS:
            raise ParameterError(
                f"--op {text!r}: unknown operator {name!r}; expected one of {', '.join(OPS)}"
            )
        params = {}
        for part in filter(None, (p.strip() for p in rest.split(","))):
            k, eq, v = part.partition("=")
            if not eq or not k.strip():
                raise ParameterError(f"--op {text!r}: {part!r} is not key=value")
            params[k.strip().lower().replace("-", "_")] = v.strip()
        return cls(name, params)


def _num(
    step: Step, key: str, default: float | None, lo: float, hi: float, integer: bool = False
) -> Any:
    raw = step.params.get(key)
    if raw is None:
        return default
    try:
        v = float(raw)
    except ValueError:
        raise ParameterError(f"{step.name}: {key}={raw!r} is not a number") from None
    if not math.isfinite(v) or not lo <= v <= hi or (integer and v != int(v)):
        raise ParameterError(
            f"{step.name}: {key}={raw!r}; expected "
            f"{'an integer' if integer else 'a number'} in [{lo:g}, {hi:g}]"
        )
    return int(v) if integer else v


def _floats(step: Step, key: str) -> list[float] | None:
    raw = step.params.get(key)
    if raw is None:
        return None
    try:
        vals = [float(x) for x in raw.split("/") if x.strip()]
    except ValueError:
        raise ParameterError(f"{step.name}: {key}={raw!r}; expected numbers a/b/c") from None
    if not vals or not all(math.isfinite(v) and abs(v) <= 1e6 for v in vals):
        raise ParameterError(f"{step.name}: {key}={raw!r}; expected finite numbers a/b/c")
    return vals


def apply_step(
    mo: Motion, step: Step, lock: Callable[[Motion], Motion] | None = None, feet: bool = False
) -> Motion:
    """One operator (module docstring) on ``mo``; ``lock`` is handed to ``make_cycle`` (the
    world-space cycle is locked before an in-place / root-motion conversion); ``feet``: a
    retarget locks its feet itself, as the CLI's ``retarget`` does (on the source's contacts
    where the feet are proportioned otherwise), and so does a resample (on the contacts of
    its input, as the CLI's ``convert --fps``)."""
    import biomorph.motion as bm
    from biomorph.motion import rootmotion as rm
    from biomorph.motion.retarget import mirror, retarget

    up = mo.meta.get("up_guess") or "y"
    n, p = step.name, step.params
    if n == "equalize":
        return bm.equalize(
            mo,
            _floats(step, "gains") or [1, 1, 1, 1, 1],
            p.get("joint"),
            "all",
            p.get("below", "0") == "1",
            "edge",
            p.get("root", "trajectory"),
        )
    if n == "speed":
        return bm.change_speed(mo, _num(step, "speed", 1.0, 1e-6, 1e6))
    if n == "cycle":
        if p.get("auto", "0") == "1":
            s, e, _ = bm.best_loop(
                mo,
                _num(step, "min_length", 30, 2, 1e9, True),
                None,
                _num(step, "transition", 10, 1, 1e7, True),
            )
        else:
            s = _num(step, "start", 0, 0, 1e12, True)
            e = _num(step, "stop", mo.n_frames, 1, 1e12, True)
        return bm.make_cycle(
            mo,
            s,
            e,
            _num(step, "transition", 10, 1, 1e7, True),
            _num(step, "cycles", 1, 1, 10000, True),
            up=up,
            mode=p.get("mode", "world"),
            lock=lock,
        )
    if n == "trim":
        return mo.frames(
            _num(step, "start", 0, 0, 1e12, True), _num(step, "stop", mo.n_frames, 1, 1e12, True)
        )
    if n == "resample":  # with ``feet``, locked on the input's contacts (timewarp.resample)
        from biomorph.motion.timewarp import resample

        return resample(mo, _num(step, "fps", mo.fps, 1e-6, 1e4), lock_feet=feet)
    if n == "reorient":
        return bm.reorient(mo, math.radians(_num(step, "angle", 0.0, -1e6, 1e6)), up=up)
    if n == "mirror":
        return mirror(mo)
    if n == "in-place":
        return rm.in_place(mo, up, p.get("heading", "1") == "1")
    if n == "extract-root":
        return rm.extract_root_motion(mo, up, with_heading=p.get("heading", "1") == "1")
    # retarget
    if "to" not in p:
        raise ParameterError("retarget: to=<motion file with the target skeleton> is missing")
    from biomorph import io

    target = io.read_motion(Path(p["to"])).skeleton
    return retarget(mo, target, p.get("source"), p.get("target"), None, feet=feet)


def apply_chain(mo: Motion, steps: list[Step], lock_feet: bool = True) -> Motion:
    """Every step in order; planted feet locked after each (against the step's input when
    the step keeps the timing, else on its own output)."""
    from biomorph.motion.contact import ContactWarning, inputs_floor
    from biomorph.motion.contact import lock_feet as lock

    for step in steps:
        floor = inputs_floor(mo, [mo]) if lock_feet else None

        def lock_cycle(c: Motion, floor: float | None = floor) -> Motion:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ContactWarning)
                return lock(c, floor=floor)

        cyc = lock_feet and step.name == "cycle"
        # retarget and resample lock inside (on the source's contacts), like the CLI's
        rt = lock_feet and step.name in ("retarget", "resample")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ContactWarning)
            out = apply_step(mo, step, lock_cycle if cyc else None, feet=rt)
        if lock_feet and not cyc and not rt and step.name not in _UNLOCKED:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ContactWarning)
                fl = floor if out.names == mo.names else None
                out = lock(out, mo if step.name in _TIMING_KEPT else None, floor=fl)
        mo = out
    return mo


def batch_item(item: tuple[str, str, list[Step], bool, str]) -> dict[str, Any]:
    """Read one file, apply the chain, write ``out`` (BVH); the batch worker (picklable)."""
    from biomorph import io

    src, out, steps, lock_feet, euler = item
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mo = io.read_motion(src)
    res = apply_chain(mo, steps, lock_feet)
    io.write_bvh(out, res, euler=euler)
    return {
        "input": src,
        "output": out,
        "frames_in": mo.n_frames,
        "frames": res.n_frames,
        "joints": res.n_joints,
        "tolerated": mo.meta.get("tolerated", []),
    }


__all__ = ["Step", "OPS", "apply_step", "apply_chain", "batch_item"]
