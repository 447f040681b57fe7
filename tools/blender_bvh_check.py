"""Import BVH files with Blender's own importer (headless) and report one JSON line each.

Run inside Blender::

    blender -b --factory-startup --python tools/blender_bvh_check.py -- a.bvh b.bvh …

Each line is ``BVHCHECK {json}`` with: ``file``; ``result`` (the operator's return set) or
``error`` (the importer raised); ``messages`` (importer output mentioning warn / error /
fail / nan / inf); ``frames`` (the action's key range) and ``fps`` (the scene's after
import); ``fcurves`` and
``nan_keys`` (non-finite keyframe values); ``nonfinite_heads`` (world bone heads that are
not finite, sampled every ⌈frames / 150⌉ frames); ``feet`` (bones named foot / toe / ankle /
distal) with ``min_foot_z`` (their lowest world head height) and ``root_z_median``.

Blender imports BVH Y-up files as Z-up (axes converted), so heights are Blender's ``z``.
Debian's Blender 3.4 opens BVH files with mode ``'rU'``, which Python 3.11 refuses: ``open``
is patched to drop the ``U`` (a packaging bug, not a file problem). Used by
``tests/motion/test_blender_bvh.py`` and the animator's verification pass (docs/motion.md).
"""

from __future__ import annotations

import builtins
import contextlib
import io
import json
import math
import sys

_open = builtins.open


def _open_without_u(file, mode="r", *args, **kwargs):
    return _open(file, mode.replace("U", ""), *args, **kwargs)


builtins.open = _open_without_u

import bpy  # noqa: E402  (Blender's module: after the open patch)

FEET = ("foot", "toe", "ankle", "distal")
WORDS = ("warn", "error", "fail", "nan", "inf")


def _import(path: str) -> dict:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rec: dict = {"file": path}
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            res = bpy.ops.import_anim.bvh(
                filepath=path,
                update_scene_fps=True,
                update_scene_duration=True,
                rotate_mode="NATIVE",
            )
    except (RuntimeError, ValueError, OSError, KeyError, IndexError) as exc:
        rec["error"] = f"{type(exc).__name__}: {exc}"
        return rec
    rec["result"] = sorted(res)
    lines = [m for m in buf.getvalue().splitlines() if m.strip()]
    rec["messages"] = [m for m in lines if any(w in m.lower() for w in WORDS)][:5]
    return rec


def _measure(rec: dict) -> None:
    sc = bpy.context.scene
    ob = next(o for o in sc.objects if o.type == "ARMATURE")
    act = ob.animation_data.action if ob.animation_data else None
    first, last = sc.frame_start, sc.frame_end
    if act:  # the action's keys (the scene keeps its 250-frame default for shorter clips)
        first, last = (round(v) for v in act.frame_range)
    rec["frames"] = last - first + 1
    rec["fps"] = sc.render.fps / sc.render.fps_base
    nan_keys = 0
    if act:
        for fc in act.fcurves:
            nan_keys += sum(not math.isfinite(kp.co[1]) for kp in fc.keyframe_points)
        rec["fcurves"] = len(act.fcurves)
    rec["nan_keys"] = nan_keys
    feet = [pb for pb in ob.pose.bones if any(w in pb.name.lower() for w in FEET)]
    root = ob.pose.bones[0]
    step = max(1, -(-rec["frames"] // 150))
    low, rz, bad = math.inf, [], 0
    for fr in range(first, last + 1, step):
        sc.frame_set(fr)
        for pb in ob.pose.bones:
            h = ob.matrix_world @ pb.head
            bad += not all(math.isfinite(c) for c in h)
        for pb in feet:
            low = min(low, (ob.matrix_world @ pb.head).z)
        rz.append((ob.matrix_world @ root.head).z)
    rz.sort()
    rec["nonfinite_heads"] = bad
    rec["feet"] = len(feet)
    rec["min_foot_z"] = low if feet else None
    rec["root_z_median"] = rz[len(rz) // 2] if rz else None


def main(paths: list[str]) -> None:
    for path in paths:
        rec = _import(path)
        if "error" not in rec:
            _measure(rec)
        print("BVHCHECK " + json.dumps(rec), flush=True)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else [])
