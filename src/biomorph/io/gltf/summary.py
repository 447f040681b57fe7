"""Reading a glTF/GLB back as a short summary (for ``biomorph info``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pygltflib as g

from biomorph.errors import FormatError
from biomorph.io.gltf.builder import PathLike


def read_gltf_summary(path: PathLike) -> dict[str, Any]:
    """What a .glb/.gltf file holds, for ``biomorph info``.

    Keys: ``nodes``, ``skins``, ``joints`` (over all skins), ``animations``, ``duration``
    (s, longest animation), ``meshes``, ``primitives``, ``vertices``, ``triangles``,
    ``attributes`` (sorted vertex attribute names), ``bounds`` (``[min, max]`` of all
    POSITION accessors, unskinned, or ``None``), ``generator``.
    """
    p = Path(path)
    if not p.is_file():
        raise FormatError(path, "file does not exist")
    try:
        doc = g.GLTF2().load(os.fspath(p))
    except Exception as exc:  # noqa: BLE001 - pygltflib raises many kinds on bad input
        raise FormatError(
            path, f"not a readable glTF/GLB file ({type(exc).__name__}: {exc}); expected glTF 2.0"
        ) from None
    if doc is None or doc.asset is None:
        raise FormatError(path, "not a glTF 2.0 file: no asset header")
    accessors = doc.accessors or []

    def count(idx: int | None) -> int:
        if idx is None or not 0 <= idx < len(accessors):
            raise FormatError(path, f"accessor index {idx!r} out of range 0..{len(accessors) - 1}")
        return int(accessors[idx].count)

    vertices = triangles = primitives = 0
    attributes: set[str] = set()
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for mesh in doc.meshes or []:
        for prim in mesh.primitives:
            primitives += 1
            attrs = {k: v for k, v in vars(prim.attributes).items() if v is not None}
            attributes.update(attrs)
            if "POSITION" not in attrs:
                continue
            nv = count(attrs["POSITION"])
            vertices += nv
            acc = accessors[attrs["POSITION"]]
            if acc.min is not None and acc.max is not None and len(acc.min) == 3:
                lo, hi = np.minimum(lo, acc.min), np.maximum(hi, acc.max)
            mode = 4 if prim.mode is None else prim.mode
            ni = nv if prim.indices is None else count(prim.indices)
            if mode == 4:
                triangles += ni // 3
            elif mode in (5, 6):
                triangles += max(ni - 2, 0)
    duration = 0.0
    for anim in doc.animations or []:
        for s in anim.samplers:
            acc = (
                accessors[s.input]
                if s.input is not None and 0 <= s.input < len(accessors)
                else None
            )
            if acc is not None and acc.max:
                duration = max(duration, float(acc.max[0]))
    return {
        "nodes": len(doc.nodes or []),
        "skins": len(doc.skins or []),
        "joints": int(sum(len(s.joints) for s in doc.skins or [])),
        "animations": len(doc.animations or []),
        "duration": round(duration, 6),
        "meshes": len(doc.meshes or []),
        "primitives": primitives,
        "vertices": vertices,
        "triangles": triangles,
        "attributes": sorted(attributes),
        "bounds": None if not np.isfinite(lo).all() else [lo.tolist(), hi.tolist()],
        "generator": doc.asset.generator,
    }
