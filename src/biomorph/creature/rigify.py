"""Optional Rigify-style bone names (Blender's rigging add-on conventions).

``spine``, ``spine.001`` … from the hips forward along the back, ``neck``, ``neck.001`` …
from the shoulders to the head, ``head``, ``tail``, ``tail.001`` … away from the hips;
limbs ``shoulder/upper_arm/forearm/hand`` at shoulder girdles, ``pelvis/thigh/shin/foot`` at
the hip, with ``.L``/``.R`` suffixes (left = −z). Extra pairs and the centaur girdle get a
``_2``/``_centaur`` infix, wings and fins their own stems. Only names change.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from biomorph.creature.creature import Creature

_LIMB = {("shoulder", "leg"): ("shoulder", "upper_arm", "forearm", "hand"),
         ("shoulder", "arm"): ("shoulder", "upper_arm", "forearm", "hand"),
         ("centaur", "arm"): ("shoulder", "upper_arm", "forearm", "hand"),
         ("hip", "leg"): ("pelvis", "thigh", "shin", "foot"),
         ("shoulder", "wing"): ("wing_root", "wing", "wing.001", "wing.002"),
         ("centaur", "wing"): ("wing_root", "wing", "wing.001", "wing.002")}
_SEG = {"girdle": 0, "upper": 1, "lower": 2, "distal": 3}


def _numbered(stem: str, k: int) -> str:
    return stem if k == 0 else f"{stem}.{k:03d}"


def rigify_names(c: Creature) -> tuple[str, ...]:
    """Rigify-style names for every joint of ``c`` (same order)."""
    names = list(c.names)
    out = list(names)
    spine_idx = {r: [i for i, n in enumerate(names) if n.startswith(f"{r}_")]
                 for r in ("neck", "back", "tail")}
    # vertebra numbers in the source names run head -> tail
    back = sorted(spine_idx["back"], key=lambda i: -int(names[i].split("_")[1]))
    for k, i in enumerate(back):
        out[i] = _numbered("spine", k)
    neck = sorted(spine_idx["neck"], key=lambda i: -int(names[i].split("_")[1]))
    for k, i in enumerate(neck):
        out[i] = _numbered("neck", k)
    tail = sorted(spine_idx["tail"], key=lambda i: int(names[i].split("_")[1]))
    for k, i in enumerate(tail):
        out[i] = _numbered("tail", k)
    for i, n in enumerate(names):
        if n == "skull":
            out[i] = "head"
        elif c.side[i] != 0:
            tag, seg, side = n.rsplit("_", 2)
            girdle, pair = tag[:-1], int(tag[-1])
            kind = c.kind[i] if c.kind[i] != "girdle" else c.kind[int(np.flatnonzero(
                c.skeleton.parent == i)[0])]
            stems = _LIMB.get((girdle, kind), (f"{kind}_root", kind, f"{kind}.001",
                                               f"{kind}.002"))
            stem = stems[_SEG[seg]]
            infix = "" if girdle != "centaur" else "_centaur"
            if pair > 1:
                infix += f"_{pair}"
            out[i] = f"{stem}{infix}.{'L' if side == 'l' else 'R'}"
    if len(set(out)) != len(out):  # never produce duplicates: fall back to the source name
        seen: set[str] = set()
        for i, n in enumerate(out):
            if n in seen:
                out[i] = names[i]
            seen.add(out[i])
    return tuple(out)


def with_rigify_names(c: Creature) -> Creature:
    """A copy of ``c`` whose skeleton uses :func:`rigify_names`."""
    return replace(c, skeleton=c.skeleton.with_(names=rigify_names(c)))
