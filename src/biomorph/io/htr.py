"""HTR (Motion Analysis *Hierarchical Translation-Rotation*) reader — the format the seed's
studio received its capture in.

Layout::

    [Header]                  FileType htr / DataType HTRS / NumSegments / NumFrames /
                              DataFrameRate / EulerRotationOrder / CalibrationUnits /
                              RotationUnits / GlobalAxisofGravity / BoneLengthAxis / ScaleFactor
    [SegmentNames&Hierarchy]  child parent   (the root's parent is GLOBAL)
    [BasePosition]            name Tx Ty Tz Rx Ry Rz BoneLength
    [<segment>]               frame Tx Ty Tz Rx Ry Rz BoneScaleFactor   (one block per segment)
    [EndOfFile]

Conventions used here (stated, since files differ):

* Each segment's frame values are *relative to its base position*: the local transform is
  ``T(base_t + frame_t) · R(base_r) · R(frame_r)``. In the :class:`Motion` the base rotation
  becomes the skeleton's ``rest_rotation``, the base translation its ``offset``, the frame
  rotation the pose quaternion, and translations ``Motion.joint_translation`` (when any
  non-root segment translates) / ``root_position``.
* ``EulerRotationOrder ZYX`` is read with the BVH meaning ``R = Rz · Ry · Rx`` (the file's
  columns stay Rx Ry Rz). On the real HTR file this is the reading under which the left and
  right limbs are exact mirror images in the base pose and stay mirror-symmetric in motion
  (the reversed reading is not); ``reverse_order=True`` reads the order the other way round.
* Lengths are converted to metres from ``CalibrationUnits`` (mm, cm, m, in) and multiplied by
  ``ScaleFactor``. ``BoneScaleFactor`` columns are ignored (kept in ``meta``: max deviation).
* Comment lines start with ``#``; tabs/spaces/CRLF are accepted.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import FormatError, InputError

UNITS = {
    "mm": 0.001,
    "millimeters": 0.001,
    "cm": 0.01,
    "centimeters": 0.01,
    "m": 1.0,
    "meters": 1.0,
    "in": 0.0254,
    "inches": 0.0254,
}


def _sections(path: str | os.PathLike[str]) -> dict[str, list[tuple[int, list[str]]]]:
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        raise FormatError(path, "file does not exist") from None
    secs: dict[str, list[tuple[int, list[str]]]] = {}
    cur: str | None = None
    for ln, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith("[") and line.endswith("]"):
            cur = line[1:-1].strip()
            if cur in secs:
                raise FormatError(path, f"section [{cur}] appears twice", line=ln)
            secs[cur] = []
            continue
        if cur is None:
            raise FormatError(
                path, f"data {line[:30]!r} before the first [section]; expected [Header]", line=ln
            )
        secs[cur].append((ln, line.split()))
    if not secs:
        raise FormatError(path, "file is empty or has no [sections]; expected an HTR file", line=1)
    return secs


def read_htr(path: str | os.PathLike[str], reverse_order: bool = False, strict: bool = False):
    """Read an HTR file into a :class:`biomorph.motion.Motion` (see module docstring).

    Tolerated unless ``strict`` (one :class:`~biomorph.core.motion.MotionInputWarning` each,
    kept in ``meta["tolerated"]``): segment blocks whose frame count differs from
    ``NumFrames`` (the frames every segment has are read) and a missing ``[EndOfFile]``."""
    from biomorph.core.motion import Motion, dfs_preorder, guess_up_axis, reorder_joints, tolerate

    tolerated: dict = {}

    secs = _sections(path)
    for need in ("Header", "SegmentNames&Hierarchy", "BasePosition"):
        if need not in secs:
            raise FormatError(
                path,
                f"missing section [{need}]; expected an HTR file with "
                "[Header], [SegmentNames&Hierarchy], [BasePosition]",
            )
    header: dict[str, str] = {}
    for ln, toks in secs["Header"]:
        if len(toks) < 2:
            raise FormatError(path, f"header line {' '.join(toks)!r} has no value", line=ln)
        header[toks[0].lower()] = toks[1]

    def num(key: str, cast=float, default=None):
        if key.lower() not in header:
            if default is not None:
                return default
            raise FormatError(path, f"[Header] lacks {key}")
        try:
            return cast(header[key.lower()])
        except ValueError:
            raise FormatError(path, f"{key} {header[key.lower()]!r} is not a number") from None

    n_seg = num("NumSegments", int)
    n_frames = num("NumFrames", int)
    rate = num("DataFrameRate", float)
    if not math.isfinite(rate) or rate <= 0 or n_frames < 1:
        raise FormatError(
            path, f"DataFrameRate {rate} / NumFrames {n_frames}; expected positive values"
        )
    order = header.get("eulerrotationorder", "ZYX").upper()
    if order not in tf.EULER_ORDERS:
        raise FormatError(
            path, f"EulerRotationOrder {order!r}; expected one of {' '.join(tf.EULER_ORDERS)}"
        )
    bvh_order = order[::-1] if reverse_order else order
    unit_name = header.get("calibrationunits", "mm").lower()
    scale = UNITS.get(unit_name, 1.0) * num("ScaleFactor", float, 1.0)
    if not math.isfinite(scale) or scale <= 0:
        raise FormatError(
            path, f"ScaleFactor {header.get('scalefactor')!r}; expected a positive finite number"
        )
    degrees = header.get("rotationunits", "degrees").lower().startswith("deg")
    # hierarchy
    parent_name: dict[str, str] = {}
    order_names: list[str] = []
    for ln, toks in secs["SegmentNames&Hierarchy"]:
        if len(toks) != 2:
            raise FormatError(
                path, f"hierarchy line has {len(toks)} fields; expected 'child parent'", line=ln
            )
        child, par = toks
        if child in parent_name:
            raise FormatError(path, f"segment {child!r} listed twice", line=ln)
        parent_name[child] = par
        order_names.append(child)
    if len(order_names) != n_seg:
        raise FormatError(
            path, f"NumSegments {n_seg} but {len(order_names)} segments in [SegmentNames&Hierarchy]"
        )
    for child, par in parent_name.items():
        if par.upper() != "GLOBAL" and par not in parent_name:
            raise FormatError(path, f"segment {child!r} has unknown parent {par!r}")
    # parents before children (stable), GLOBAL roots first
    names: list[str] = []
    placed: set[str] = set()
    pending = list(order_names)
    while pending:
        progress = False
        for s in list(pending):
            p = parent_name[s]
            if p.upper() == "GLOBAL" or p in placed:
                names.append(s)
                placed.add(s)
                pending.remove(s)
                progress = True
        if not progress:
            raise FormatError(path, f"segment hierarchy has a cycle through {pending[0]!r}")
    idx = {s: i for i, s in enumerate(names)}
    parent = [-1 if parent_name[s].upper() == "GLOBAL" else idx[parent_name[s]] for s in names]
    # base position
    base = np.full((len(names), 7), np.nan)
    for ln, toks in secs["BasePosition"]:
        if len(toks) < 7:
            raise FormatError(
                path,
                f"[BasePosition] line has {len(toks)} fields; expected name "
                "Tx Ty Tz Rx Ry Rz [BoneLength]",
                line=ln,
            )
        if toks[0] not in idx:
            raise FormatError(path, f"[BasePosition] names unknown segment {toks[0]!r}", line=ln)
        try:
            vals = [float(v) for v in toks[1:8]]
        except ValueError:
            raise FormatError(
                path, f"[BasePosition] {toks[0]}: non-numeric value", line=ln
            ) from None
        if not all(math.isfinite(v) for v in vals):
            raise FormatError(
                path,
                f"[BasePosition] {toks[0]}: non-finite value; expected finite numbers",
                line=ln,
            )
        base[idx[toks[0]], : len(vals)] = vals
    missing = [names[i] for i in range(len(names)) if np.isnan(base[i, 0])]
    if missing:
        raise FormatError(path, f"[BasePosition] lacks segment {missing[0]!r}")
    # frames (counts checked before allocating: a damaged NumFrames must not allocate)
    counts = {s: len(secs[s]) for s in names if s in secs}
    if not strict and counts and min(counts.values()) >= 1 and (set(counts.values()) != {n_frames}):
        have = min(counts.values())
        odd = next(s for s in names if counts.get(s) != n_frames)
        tolerate(
            tolerated,
            f"{os.fspath(path)}: NumFrames {n_frames} but segment [{odd}] has "
            f"{counts[odd]} frames; read the {have} frames every segment has "
            "(--strict refuses)",
        )
        n_frames = have
        secs = {k: (v[:have] if k in counts else v) for k, v in secs.items()}
    for s in names:
        rows = secs.get(s)
        if rows is not None and len(rows) != n_frames:
            ln = rows[-1][0] if rows else None
            raise FormatError(
                path,
                f"segment [{s}] has {len(rows)} frames; NumFrames says "
                f"{n_frames} (truncated file?)",
                line=ln,
            )
    n = len(names)
    tr = np.zeros((n_frames, n, 3))
    rot = np.zeros((n_frames, n, 3))
    sf_dev = 0.0
    for s in names:
        if s not in secs:
            raise FormatError(path, f"no [{s}] block with frame data for segment {s!r}")
        rows = secs[s]
        if len(rows) != n_frames:
            ln = rows[-1][0] if rows else None
            raise FormatError(
                path,
                f"segment [{s}] has {len(rows)} frames; NumFrames says "
                f"{n_frames} (truncated file?)",
                line=ln,
            )
        try:
            block = np.array([r[1:8] for _, r in rows], dtype=float)
        except ValueError:
            for ln, r in rows:
                if len(r) < 7:
                    raise FormatError(
                        path,
                        f"[{s}] row has {len(r)} fields; expected frame Tx Ty Tz Rx Ry Rz [SF]",
                        line=ln,
                    ) from None
                for tok in r:
                    try:
                        float(tok)
                    except ValueError:
                        raise FormatError(
                            path, f"[{s}] value {tok!r} is not a number", line=ln
                        ) from None
            raise FormatError(path, f"[{s}] rows have different field counts") from None
        if not np.isfinite(block).all():
            r = int(np.argwhere(~np.isfinite(block))[0][0])
            raise FormatError(
                path, f"[{s}] non-finite value; expected finite numbers", line=rows[r][0]
            )
        if block.shape[1] < 6:
            raise FormatError(
                path, f"[{s}] rows have {block.shape[1] + 1} fields; expected 8", line=rows[0][0]
            )
        j = idx[s]
        tr[:, j] = block[:, 0:3]
        rot[:, j] = block[:, 3:6]
        if block.shape[1] >= 7:
            sf_dev = max(sf_dev, float(np.abs(block[:, 6] - 1.0).max()))
    if "EndOfFile" not in secs:
        if strict:
            raise FormatError(path, "no [EndOfFile] marker (truncated file?)")
        tolerate(
            tolerated,
            f"{os.fspath(path)}: no [EndOfFile] marker; read the frames present (--strict refuses)",
        )
    ang = rot if degrees else np.degrees(rot)
    base_r = base[:, 3:6] if degrees else np.degrees(base[:, 3:6])
    cols = ["XYZ".index(a) for a in bvh_order]  # file columns are Rx Ry Rz
    pose = tf.quat_continuous(tf.euler_to_quat(ang[..., cols], bvh_order, degrees=True), axis=0)
    rest = tf.euler_to_quat(base_r[:, cols], bvh_order, degrees=True)
    offset = base[:, 0:3] * scale
    local_t = offset[None] + tr * scale
    end = np.full((n, 3), np.nan)
    bone_axis = "XYZ".index(header.get("bonelengthaxis", "Y").upper()[:1] or "Y")
    leaves = np.setdiff1d(np.arange(n), parent)
    for j in leaves:
        if np.isfinite(base[j, 6]):
            end[j] = 0.0
            end[j, bone_axis] = base[j, 6] * scale
    rot_ch = tuple(f"{a}rotation" for a in bvh_order)
    chans = [
        (("Xposition", "Yposition", "Zposition") + rot_ch)
        if parent[j] < 0 or np.any(tr[:, j] != 0)
        else rot_ch
        for j in range(n)
    ]
    try:
        skel = JointSkeleton(
            tuple(names),
            np.asarray(parent, dtype=np.int64),
            offset,
            rest_rotation=rest,
            channels=tuple(chans),
            end_site=end,
        )
    except InputError as exc:
        raise FormatError(path, str(exc)) from None
    inner = np.any(tr[:, 1:] != 0)
    meta = {
        "source": os.fspath(path),
        "format": "htr",
        "units": "m",
        "htr_units": unit_name,
        "htr_order": order,
        "bvh_order": bvh_order,
        "gravity_axis": header.get("globalaxisofgravity", "Y"),
        "bone_scale_max_deviation": sf_dev,
        "euler_wraps_in_file": int(np.count_nonzero(np.abs(np.diff(ang, axis=0)) > 180)),
        **tolerated,
    }
    skel, perm = reorder_joints(skel, dfs_preorder(skel.parent))  # BVH joint order
    local_t = local_t[:, perm]
    mo = Motion(skel, pose[:, perm], local_t[:, 0], 1.0 / rate, local_t if inner else None, meta)
    mo.meta["up_guess"] = (
        meta["gravity_axis"].lower() if meta["gravity_axis"].lower() in "xyz" else guess_up_axis(mo)
    )
    return mo


read_motion = read_htr

__all__ = ["read_htr", "read_motion"]
