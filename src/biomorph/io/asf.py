"""Acclaim ASF (skeleton) + AMC (motion) reader — CMU's original capture format.

``read_motion(path, amc=None, asf=None, fps=120.0)`` accepts either file: given ``x.asf`` it
uses ``amc=`` or finds ``x.amc`` / ``x_*.amc`` beside it; given ``x_01.amc`` it uses ``asf=``
or ``x_01.asf`` / ``x.asf`` beside it. AMC has no frame rate; CMU captured at 120 Hz.

Model (the usual ASF/AMC semantics):

* Each bone ``b`` has a rest axis frame ``C_b`` (``axis ax ay az XYZ``: rotations applied in
  the listed order about fixed axes, i.e. ``C = Rz·Ry·Rx`` for ``XYZ``), a ``direction``
  (unit vector, world frame at rest) and a ``length``. Its AMC values (``dof rx ry rz``, any
  subset and order) give ``M_b``, the rotations applied in the listed order, in the axis frame.
  World orientation: ``W_b = W_parent · C_parent⁻¹ · C_b · M_b``; bone ``b`` starts at the end
  of its parent and ends at ``start + W_b · C_b⁻¹ · length·direction``.
* In the :class:`Motion`, joint ``b`` sits at the bone's *start*: ``rest_rotation =
  C_parent⁻¹ C_b``, pose rotation ``M_b``, ``offset = C_parent⁻¹ · (length·direction)`` of the
  parent bone, and the leaf bones' ends become End Sites. The root takes ``order TX TY TZ RX
  RY RZ`` values: translation → ``root_position``, rotation (X first) → pose, with
  ``orientation``/``axis`` as its rest rotation.
* Lengths are converted to metres: ASF ``length L`` under ``:units`` means lengths were
  multiplied by L from inches, so metres = value / L × 0.0254. ``angle deg|rad`` is honoured.
* ``#`` comment lines and CRLF are accepted anywhere (fairmotion adds a copyright line).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import FormatError, InputError, ParameterError

_AXES = {"rx": "X", "ry": "Y", "rz": "Z"}


def _lines(path: Path) -> list[tuple[int, str]]:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        raise FormatError(path, "file does not exist") from None
    return [
        (i, s.strip())
        for i, s in enumerate(text.splitlines(), start=1)
        if s.strip() and not s.lstrip().startswith("#")
    ]


def _floats(path: Path, ln: int, toks: list[str], what: str) -> list[float]:
    try:
        vals = [float(t) for t in toks]
    except ValueError:
        raise FormatError(
            path, f"{what}: non-numeric value in {' '.join(toks)!r}", line=ln
        ) from None
    if not all(np.isfinite(v) for v in vals):
        raise FormatError(
            path,
            f"{what}: non-finite value in {' '.join(toks)!r}; expected finite numbers",
            line=ln,
        )
    return vals


def _numbers(path: Path, ln: int, toks: list[str], n: int, what: str) -> list[float]:
    """Exactly ``n`` numbers after the keyword ``toks[0]`` (more tokens are left to callers)."""
    if len(toks) < n + 1:
        raise FormatError(path, f"{what} has {len(toks) - 1} value(s); expected {n}", line=ln)
    return _floats(path, ln, toks[1 : n + 1], what)


def _word(path: Path, ln: int, toks: list[str], what: str) -> str:
    if len(toks) < 2:
        raise FormatError(path, f"{what} without a value; expected '{toks[0]} <value>'", line=ln)
    return toks[1]


def _axis_order(path: Path, ln: int, order: str, n: int, what: str) -> str:
    """Axis letters of an ``axis`` line: ``n`` distinct letters out of X, Y, Z."""
    o = order.upper()
    if len(o) != n or any(c not in "XYZ" for c in o) or len(set(o)) != len(o):
        raise FormatError(
            path,
            f"{what} axis order {order!r} for {n} angle(s); expected "
            f"{n} distinct letters of X, Y, Z (e.g. 'XYZ')",
            line=ln,
        )
    return o


def read_asf(path: str | os.PathLike[str]) -> dict:
    """Parse an ASF file into a plain dict (units, root, bones, hierarchy)."""
    p = Path(path)
    lines = _lines(p)
    if not lines:
        raise FormatError(p, "file is empty; expected an ASF skeleton", line=1)
    units: dict[str, Any] = {"length": 1.0, "angle": "deg", "mass": 1.0}
    root = {
        "order": ["TX", "TY", "TZ", "RX", "RY", "RZ"],
        "axis": "XYZ",
        "position": [0.0, 0.0, 0.0],
        "orientation": [0.0, 0.0, 0.0],
    }
    bones: dict[str, dict] = {}
    bone_order: list[str] = []
    hierarchy: list[tuple[str, list[str], int]] = []
    section = None
    cur: dict | None = None
    for ln, line in lines:
        toks = line.split()
        if toks[0].startswith(":"):
            section = toks[0][1:].lower()
            continue
        key = toks[0].lower()
        if section == "units":
            if key in ("length", "mass"):
                units[key] = _numbers(p, ln, toks, 1, key)[0]
                if units[key] <= 0:
                    raise FormatError(
                        p, f"units {key} {units[key]}; expected a positive number", line=ln
                    )
            elif key == "angle":
                units["angle"] = _word(p, ln, toks, "units angle").lower()
                if not units["angle"].startswith(("deg", "rad")):
                    raise FormatError(
                        p, f"units angle {toks[1]!r}; expected 'deg' or 'rad'", line=ln
                    )
        elif section == "root":
            if key == "order":
                order = [t.upper() for t in toks[1:]]
                legal = ("TX", "TY", "TZ", "RX", "RY", "RZ")
                if any(t not in legal for t in order) or len(set(order)) != len(order):
                    raise FormatError(
                        p,
                        f"root order {' '.join(toks[1:])!r}; expected "
                        "distinct channels of TX TY TZ RX RY RZ",
                        line=ln,
                    )
                root["order"] = order
            elif key == "axis":
                root["axis"] = _axis_order(p, ln, _word(p, ln, toks, "root axis"), 3, "root")
            elif key in ("position", "orientation"):
                root[key] = _numbers(p, ln, toks, 3, f"root {key}")
        elif section == "bonedata":
            if key == "begin":
                cur = {
                    "dof": [],
                    "axis": [0.0, 0.0, 0.0],
                    "axis_order": "XYZ",
                    "direction": [0.0, 0.0, 0.0],
                    "length": 0.0,
                    "line": ln,
                }
            elif key == "end":
                if cur is None or "name" not in cur:
                    raise FormatError(p, "bone block without a name", line=ln)
                bones[cur["name"]] = cur
                bone_order.append(cur["name"])
                cur = None
            elif cur is None:
                if key.startswith("(") or key[0].isdigit() or key[0] == "-":
                    continue
                raise FormatError(p, f"{toks[0]!r} outside a bone's begin/end", line=ln)
            elif key == "name":
                cur["name"] = _word(p, ln, toks, "bone name")
                if cur["name"] in bones or cur["name"] == "root":
                    raise FormatError(
                        p,
                        f"bone {cur['name']!r} defined twice; expected unique bone names",
                        line=ln,
                    )
            elif key == "direction":
                cur["direction"] = _numbers(p, ln, toks, 3, "direction")
            elif key == "length":
                cur["length"] = _numbers(p, ln, toks, 1, "length")[0]
            elif key == "axis":
                cur["axis"] = _numbers(p, ln, toks, 3, "axis")
                cur["axis_order"] = _axis_order(
                    p, ln, toks[4] if len(toks) > 4 else "XYZ", 3, "bone"
                )
            elif key == "dof":
                dof = [t.lower() for t in toks[1:]]
                rots = [d for d in dof if d in _AXES]
                if len(set(rots)) != len(rots):
                    raise FormatError(
                        p,
                        f"dof {' '.join(toks[1:])!r} repeats a rotation; "
                        "expected each of rx ry rz at most once",
                        line=ln,
                    )
                cur["dof"] = dof
        elif section == "hierarchy":
            if key in ("begin", "end"):
                continue
            hierarchy.append((toks[0], toks[1:], ln))
    if cur is not None:
        raise FormatError(p, "file ends inside a bone block (truncated?)", line=lines[-1][0])
    if not bones or not hierarchy:
        raise FormatError(p, "no :bonedata or :hierarchy; expected an ASF skeleton file")
    return {
        "units": units,
        "root": root,
        "bones": bones,
        "order": bone_order,
        "hierarchy": hierarchy,
        "path": p,
    }


def _rot(
    angles: list[float], axes: str, degrees: bool, path: Path | None = None, line: int | None = None
) -> np.ndarray:
    """Rotation applying ``axes[0]`` first (fixed axes): BVH order = reversed string."""
    if len(angles) != len(axes):
        raise FormatError(
            path,
            f"axis line holds {len(angles)} angle(s) for the {len(axes)} "
            f"axis letter(s) {axes!r}; expected one angle per letter",
            line=line,
        )
    if not axes:
        return tf.quat_identity()
    vals = list(angles)[::-1]
    order = axes[::-1]
    q = tf.quat_identity()
    for a, v in zip(order, vals, strict=True):
        q = tf.quat_multiply(q, tf.quat_from_axis_angle(a.lower(), np.radians(v) if degrees else v))
    return q


def read_amc(path: str | os.PathLike[str], asf: dict, fps: float = 120.0, strict: bool = False):
    """Read AMC frames against a parsed ASF (:func:`read_asf`) into a Motion.

    A last frame that lists only some bones (a file cut off while writing) is dropped with a
    :class:`~biomorph.core.motion.MotionInputWarning` (kept in ``meta["tolerated"]``) unless
    ``strict``; a bone missing from an inner frame stays an error."""
    from biomorph.core.motion import Motion, dfs_preorder, guess_up_axis, reorder_joints, tolerate

    p = Path(path)
    if not (np.isfinite(fps) and fps > 0):
        raise ParameterError(f"fps {fps}; expected a positive frame rate")
    deg = asf["units"]["angle"].startswith("deg")
    scale = 0.0254 / (asf["units"]["length"] or 1.0)
    # joints in parent-first order (breadth first here; depth-first pre-order at the end)
    kids: dict[str, list[str]] = {}
    for par, ch, ln in asf["hierarchy"]:
        if par != "root" and par not in asf["bones"]:
            raise FormatError(
                asf["path"],
                f"hierarchy names unknown parent bone {par!r}; "
                "expected 'root' or a bone of :bonedata",
                line=ln,
            )
        for c in ch:
            if c not in asf["bones"]:
                raise FormatError(asf["path"], f"hierarchy names unknown bone {c!r}", line=ln)
        kids.setdefault(par, []).extend(ch)
    names = ["root"]
    parent = [-1]
    i = 0
    while i < len(names):
        for c in kids.get(names[i], []):
            if c in names:
                lns = [ln for par, ch, ln in asf["hierarchy"] if c in ch]
                raise FormatError(
                    asf["path"],
                    f"bone {c!r} has two parents; expected a tree",
                    line=lns[-1] if lns else None,
                )
            names.append(c)
            parent.append(i)
        i += 1
    n = len(names)
    root = asf["root"]
    c_world = [_rot(root["orientation"], root["axis"], deg, asf["path"])]
    offset = np.zeros((n, 3))
    end = np.full((n, 3), np.nan)
    dofs: list[list[str]] = [[t for t in root["order"] if t.startswith("R")]]
    vec = [np.zeros(3)]
    for j in range(1, n):
        b = asf["bones"][names[j]]
        c_world.append(_rot(b["axis"], b["axis_order"], deg, asf["path"], b["line"]))
        dofs.append([d for d in b["dof"] if d in _AXES])
        vec.append(np.asarray(b["direction"], float) * b["length"] * scale)
    c_world = np.array(c_world)
    rest = np.array(c_world)
    for j in range(1, n):
        cp_inv = tf.quat_conjugate(c_world[parent[j]])
        rest[j] = tf.quat_multiply(cp_inv, c_world[j])
        offset[j] = tf.quat_rotate(cp_inv, vec[parent[j]])
    leaves = np.setdiff1d(np.arange(n), parent)
    for j in leaves:
        if j > 0:
            end[j] = tf.quat_rotate(tf.quat_conjugate(c_world[j]), vec[j])
    # --- AMC values
    lines = _lines(p)
    frames: list[dict[str, tuple[int, list[float]]]] = []
    frame_line: list[int] = []
    width = {names[j]: len(asf["bones"][names[j]]["dof"]) for j in range(1, n)}
    width["root"] = len(root["order"])
    for ln, line in lines:
        if line.startswith(":"):
            continue
        toks = line.split()
        if len(toks) == 1 and toks[0].isdigit():
            frames.append({})
            frame_line.append(ln)
            continue
        if not frames:
            raise FormatError(p, f"data {toks[0]!r} before the first frame number", line=ln)
        name = toks[0]
        if name not in width:
            raise FormatError(p, f"unknown bone {name!r}; the ASF has no such bone", line=ln)
        vals = _floats(p, ln, toks[1:], name)
        if len(vals) != width[name]:
            raise FormatError(
                p,
                f"bone {name} has {len(vals)} values; the ASF declares {width[name]} dof",
                line=ln,
            )
        if name in frames[-1]:
            raise FormatError(
                p,
                f"bone {name} listed twice in frame {len(frames)}; expected "
                "one line per bone and frame",
                line=ln,
            )
        frames[-1][name] = (ln, vals)
    if not frames:
        raise FormatError(p, "no frames; expected frame numbers followed by bone values")
    tolerated: dict = {}
    needed = [nm for j, nm in enumerate(names) if j == 0 or asf["bones"][nm]["dof"]]
    if not strict and len(frames) > 1 and any(nm not in frames[-1] for nm in needed):
        tolerate(
            tolerated,
            f"{os.fspath(p)}: last frame (line {frame_line[-1]}) lists "
            f"{len(frames[-1])} of {len(needed)} bones; dropped it and read "
            f"{len(frames) - 1} frames (--strict refuses)",
        )
        frames.pop()
        frame_line.pop()
    f = len(frames)
    rot = np.zeros((f, n, 4))
    rot[..., 3] = 1.0
    root_pos = np.zeros((f, 3))
    for j, name in enumerate(names):
        if j > 0 and not asf["bones"][name]["dof"]:
            continue
        try:
            vals = np.array([fr[name][1] for fr in frames])
        except KeyError:
            bad = next(k for k, fr in enumerate(frames) if name not in fr)
            raise FormatError(
                p,
                f"frame {bad + 1} lacks bone {name!r}; expected every frame to "
                "list every bone with dof",
                line=frame_line[bad],
            ) from None
        if j == 0:
            order = root["order"]
            for a, ax in enumerate("XYZ"):
                if f"T{ax}" in order:
                    root_pos[:, a] = vals[:, order.index(f"T{ax}")] * scale
                else:
                    root_pos[:, a] = root["position"][a] * scale
            rcols = [order.index(t) for t in order if t.startswith("R")]
            axes = "".join(t[1] for t in order if t.startswith("R"))
            ang = vals[:, rcols]
        else:
            dl = asf["bones"][name]["dof"]
            keep = [k for k, d in enumerate(dl) if d in _AXES]
            axes = "".join(_AXES[dl[k]] for k in keep)
            ang = vals[:, keep]
        if not axes:
            continue
        order = axes[::-1]
        a = ang[:, ::-1]
        if not deg:
            a = np.degrees(a)
        if len(order) < 3:
            miss = "".join(x for x in "XYZ" if x not in order)
            order = order + miss
            a = np.concatenate([a, np.zeros((f, len(miss)))], axis=1)
        rot[:, j] = tf.euler_to_quat(a, order, degrees=True)
    rot = tf.quat_continuous(rot, axis=0)
    chans = []
    for j in range(n):
        axes = (
            "".join(t[1] for t in root["order"] if t.startswith("R"))
            if j == 0
            else "".join(_AXES[d] for d in dofs[j])
        )
        full = axes[::-1] + "".join(x for x in "ZYX" if x not in axes)
        rc = tuple(f"{x}rotation" for x in full)
        chans.append(("Xposition", "Yposition", "Zposition") + rc if j == 0 else rc)
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
        raise FormatError(p, str(exc)) from None
    meta = {
        "source": os.fspath(p),
        "format": "asf/amc",
        "units": "m",
        "asf": os.fspath(asf["path"]),
        "euler_wraps_in_file": 0,
        **tolerated,
    }
    skel, perm = reorder_joints(skel, dfs_preorder(skel.parent))  # BVH joint order
    mo = Motion(skel, rot[:, perm], root_pos, 1.0 / fps, None, meta)
    mo.meta["up_guess"] = guess_up_axis(mo)
    return mo


def _sibling_amc(asf: Path) -> Path:
    cand = asf.with_suffix(".amc")
    if cand.exists():
        return cand
    found = sorted(asf.parent.glob(f"{asf.stem}_*.amc"))
    if found:
        return found[0]
    raise FormatError(
        asf,
        f"no motion beside the skeleton: expected {cand.name} or {asf.stem}_*.amc (or pass amc=)",
    )


def _sibling_asf(amc: Path) -> Path:
    stem = amc.stem
    while True:
        cand = amc.with_name(stem + ".asf")
        if cand.exists():
            return cand
        if "_" not in stem:
            break
        stem = stem.rsplit("_", 1)[0]
    raise FormatError(
        amc,
        f"no skeleton beside the motion: expected {amc.stem}.asf or a "
        "shorter prefix .asf (or pass asf=)",
    )


def read_motion(
    path: str | os.PathLike[str],
    amc: str | os.PathLike[str] | None = None,
    asf: str | os.PathLike[str] | None = None,
    fps: float = 120.0,
    strict: bool = False,
):
    """Read ASF+AMC into a :class:`biomorph.motion.Motion` given either file (``strict``: see
    :func:`read_amc`)."""
    p = Path(path)
    if p.suffix.lower() == ".asf":
        asf_path, amc_path = p, Path(amc) if amc is not None else _sibling_amc(p)
    elif p.suffix.lower() == ".amc":
        amc_path, asf_path = p, Path(asf) if asf is not None else _sibling_asf(p)
    else:
        raise FormatError(p, "expected an .asf or .amc file")
    return read_amc(amc_path, read_asf(asf_path), fps, strict)


__all__ = ["read_motion", "read_asf", "read_amc"]
