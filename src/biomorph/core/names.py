"""Joint-name conventions (in ``core``: the BVH reader and the motion pillar use them):
canonical humanoid names, presets (CMU, Mixamo, Rokoko/HumanIK, Rigify as written by
``biomorph creature``), user CSV maps, and left/right pairs.

Canonical names are ``hips spine chest upper_chest neck head`` and, per side ``l_``/``r_``,
``shoulder upper_arm forearm hand thigh shin foot toe``. A preset maps canonical names to a
convention's joint names; :func:`detect_preset` picks the preset matching most joints of a
skeleton (Mixamo's ``mixamorig:`` namespace prefix and ``:``-namespaces in general are
ignored when matching).
"""

from __future__ import annotations

import csv
import os
import re
from pathlib import Path

from biomorph.errors import FormatError, InputError, ParameterError

_SIDE = ("shoulder", "upper_arm", "forearm", "hand", "thigh", "shin", "foot", "toe")
CANONICAL = (
    "hips",
    "spine",
    "chest",
    "upper_chest",
    "neck",
    "head",
    *(f"{s}_{b}" for s in ("l", "r") for b in _SIDE),
)
#: joints a retarget map must cover (the legs carry the root height and the contacts)
REQUIRED = ("hips", "l_thigh", "l_shin", "l_foot", "r_thigh", "r_shin", "r_foot")


def _humanik(spine: tuple[str, ...], side_names: tuple[str, ...]) -> dict[str, str]:
    out = {"hips": "Hips", "neck": "Neck", "head": "Head"}
    out.update(zip(("spine", "chest", "upper_chest"), spine, strict=False))
    for s, word in (("l", "Left"), ("r", "Right")):
        out.update({f"{s}_{b}": f"{word}{n}" for b, n in zip(_SIDE, side_names, strict=True)})
    return out


_HIK_SIDE = ("Shoulder", "Arm", "ForeArm", "Hand", "UpLeg", "Leg", "Foot", "ToeBase")
PRESETS: dict[str, dict[str, str]] = {
    # CMU (cgspeed BVH conversion): Hips LowerBack Spine Spine1 Neck Neck1 Head ...
    "cmu": _humanik(("LowerBack", "Spine", "Spine1"), _HIK_SIDE),
    # Mixamo (namespace prefix mixamorig: stripped when matching)
    "mixamo": _humanik(("Spine", "Spine1", "Spine2"), _HIK_SIDE),
    # Rokoko / HumanIK (MotionBuilder): Spine Spine1 Spine2 ... (Rokoko's Mixamo preset too)
    "humanik": _humanik(("Spine", "Spine1", "Spine2"), _HIK_SIDE),
    # Rigify metarig names as biomorph creature writes them
    "rigify": {
        "hips": "spine",
        "spine": "spine.001",
        "chest": "spine.002",
        "upper_chest": "spine.003",
        "neck": "neck",
        "head": "head",
        **{f"{s}_{b}": f"{b}.{s.upper()}" for s in ("l", "r") for b in _SIDE},
    },
}
PRESETS["rokoko"] = PRESETS["humanik"]
# CMU in the "3ds-Max-friendly" BVH dialect (AnimatedDrawings' cmu1): LeftHip LeftKnee
# LeftAnkle LeftToe, LeftCollar LeftShoulder LeftElbow LeftWrist, lowerback Chest Chest2
PRESETS["cmu_max"] = _humanik(
    ("lowerback", "Chest", "Chest2"),
    ("Collar", "Shoulder", "Elbow", "Wrist", "Hip", "Knee", "Ankle", "Toe"),
)
# Motion Analysis HTR joint names (the animal3D egnaro file): main, spine1…, L_hip L_knee
# L_ankle L_football
PRESETS["htr"] = {
    "hips": "main",
    "spine": "spine1",
    **{
        f"{s}_{b}": f"{s.upper()}_{n}"
        for s in ("l", "r")
        for b, n in (("thigh", "hip"), ("shin", "knee"), ("foot", "ankle"), ("toe", "football"))
    },
}
# CMU's own Acclaim ASF/AMC bones (root lowerback upperback thorax lowerneck upperneck head,
# l/r + hipjoint femur tibia foot toes clavicle humerus radius wrist hand …); a joint sits at
# its bone's start, so the ankle is ``lfoot`` and the hand ``lwrist``
PRESETS["cmu_asf"] = {
    "hips": "root",
    "spine": "lowerback",
    "chest": "upperback",
    "upper_chest": "thorax",
    "neck": "lowerneck",
    "head": "head",
    **{
        f"{s}_{b}": f"{s}{n}"
        for s in ("l", "r")
        for b, n in zip(
            _SIDE,
            ("clavicle", "humerus", "radius", "wrist", "femur", "tibia", "foot", "toes"),
            strict=True,
        )
    },
}
# biomorph creature's generator names (BVH export): limbs hip1_/shoulder1_ + girdle, upper,
# lower, distal, digits; the hips are the vertebra the hip girdles hang from (found from the
# hierarchy by :func:`resolve`), the toe the middle digit's first bone
PRESETS["creature"] = {
    "head": "skull",
    **{
        f"{s}_{b}": f"{limb}_{part}_{s}"
        for s in ("l", "r")
        for b, limb, part in (
            ("shoulder", "shoulder1", "girdle"),
            ("upper_arm", "shoulder1", "upper"),
            ("forearm", "shoulder1", "lower"),
            ("hand", "shoulder1", "distal"),
            ("thigh", "hip1", "upper"),
            ("shin", "hip1", "lower"),
            ("foot", "hip1", "distal"),
            ("toe", "hip1", "digit3_1"),
        )
    },
}


def bare(name: str) -> str:
    """A joint name without a ``namespace:`` prefix, lower case."""
    return name.rsplit(":", 1)[-1].strip().lower()


def detect_preset(names: tuple[str, ...] | list[str]) -> str:
    """The preset matching most of ``names`` (ties: the order of :data:`PRESETS`)."""
    have = {bare(n) for n in names}
    scores = {k: sum(bare(v) in have for v in p.values()) for k, p in PRESETS.items()}
    best = max(scores, key=lambda k: scores[k])
    if scores[best] == 0:
        raise InputError(
            f"no joint-name preset matches the skeleton (joints "
            f"{', '.join(list(names)[:5])}, …); expected CMU, Mixamo, Rokoko/HumanIK "
            "or Rigify names, or pass a CSV map"
        )
    return best


def resolve(
    names: tuple[str, ...] | list[str], preset: str | dict[str, str], parent=None
) -> dict[str, int]:
    """Canonical name → joint index in ``names`` under ``preset`` (name or mapping);
    ``parent`` (joint parents) lets the ``creature`` preset find its hips vertebra."""
    table = PRESETS.get(preset) if isinstance(preset, str) else preset
    if table is None:
        raise ParameterError(
            f"name preset {preset!r}; expected one of {', '.join(sorted(PRESETS))} or a CSV file"
        )
    index = {bare(n): i for i, n in enumerate(names)}
    out = {c: index[bare(v)] for c, v in table.items() if bare(v) in index}
    if preset == "creature" and parent is not None and "l_thigh" in out:
        girdle = int(parent[out["l_thigh"]])
        if girdle >= 0 and parent[girdle] >= 0:
            out["hips"] = int(parent[girdle])
    return out


def read_map_csv(path: str | os.PathLike[str]) -> dict[str, str]:
    """A user map: CSV rows ``source_joint,target_joint`` (``#`` comments, optional header
    ``source,target``). Returns source name → target name."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise FormatError(p, "file does not exist") from None
    out: dict[str, str] = {}
    for ln, row in enumerate(csv.reader(text.splitlines()), 1):
        if not row or row[0].lstrip().startswith("#"):
            continue
        if len(row) != 2:
            raise FormatError(p, f"row has {len(row)} fields; expected source,target", line=ln)
        a, b = row[0].strip(), row[1].strip()
        if ln == 1 and (a.lower(), b.lower()) == ("source", "target"):
            continue
        if not a or not b:
            raise FormatError(p, "empty joint name; expected source,target", line=ln)
        out[a] = b
    if not out:
        raise FormatError(p, "no rows; expected source,target joint names")
    return out


_LR = [
    (re.compile(r"^(.*?)(Left)(.*)$"), "Right"),
    (re.compile(r"^(.*?)(Right)(.*)$"), "Left"),
    (re.compile(r"^(.*?)(left)(.*)$"), "right"),
    (re.compile(r"^(.*?)(right)(.*)$"), "left"),
    (re.compile(r"^(.*)(\.L)(\.\d+)?$"), ".R"),
    (re.compile(r"^(.*)(\.R)(\.\d+)?$"), ".L"),
    (re.compile(r"^(.*)(_L)$"), "_R"),
    (re.compile(r"^(.*)(_R)$"), "_L"),
    (re.compile(r"^(.*)(_l)$"), "_r"),
    (re.compile(r"^(.*)(_r)$"), "_l"),
    (re.compile(r"^()(L_)(.*)$"), "R_"),
    (re.compile(r"^()(R_)(.*)$"), "L_"),
    (re.compile(r"^()(l)([A-Z].*)$"), "r"),
    (re.compile(r"^()(r)([A-Z].*)$"), "l"),
    (re.compile(r"^()(L)([A-Z][a-z].*)$"), "R"),
    (re.compile(r"^()(R)([A-Z][a-z].*)$"), "L"),
    # CMU ASF: lfemur/rfemur, lhumerus/rhumerus (a pair only when both names exist)
    (re.compile(r"^()(l)([a-z]{3,})$"), "r"),
    (re.compile(r"^()(r)([a-z]{3,})$"), "l"),
]


def mirror_name(name: str) -> str | None:
    """The other side's name (Left↔Right, .L↔.R, _l↔_r, L_↔R_, lFoot↔rFoot, LThumb↔RThumb,
    CMU ASF's lfemur↔rfemur) or None (the name need not exist: see :func:`left_right_pairs`)."""
    for pat, other in _LR:
        m = pat.match(name)
        if m:
            tail = m.group(3) or "" if m.lastindex and m.lastindex >= 3 else ""
            return f"{m.group(1)}{other}{tail}"
    return None


def left_right_pairs(names: tuple[str, ...] | list[str]) -> list[tuple[int, int]]:
    """Index pairs ``(i, j)``, ``i < j``, of joints whose names are each other's mirror."""
    index = {n: i for i, n in enumerate(names)}
    pairs = set()
    for i, n in enumerate(names):
        o = mirror_name(n)
        if o is not None and o in index and index[o] != i:
            pairs.add((min(i, index[o]), max(i, index[o])))
    return sorted(pairs)


__all__ = [
    "CANONICAL",
    "REQUIRED",
    "PRESETS",
    "bare",
    "detect_preset",
    "resolve",
    "read_map_csv",
    "mirror_name",
    "left_right_pairs",
    "preset_feet",
    "foot_joints",
]


def preset_feet(names: tuple[str, ...] | list[str], parent) -> list[int]:
    """Foot and toe joints named by the skeleton's name preset, sorted (none when no preset
    fits): how a skeleton without ``foot``/``toe`` in its names (``biomorph creature``'s
    Rigify-style bipeds) tells its feet."""
    try:
        idx = resolve(names, detect_preset(names), parent)
    except InputError:
        return []
    return sorted(idx[k] for k in ("l_foot", "l_toe", "r_foot", "r_toe") if k in idx)


def foot_joints(names: tuple[str, ...] | list[str], parent) -> list[int]:
    """The feet: joints with ``foot``, ``toe`` or ``ankle`` in their name, else those of the
    skeleton's name preset (:func:`preset_feet`); empty when neither finds any."""
    low = [s.lower() for s in names]
    feet = [i for i, s in enumerate(low) if any(k in s for k in ("foot", "toe", "ankle"))]
    return feet or preset_feet(names, parent)
