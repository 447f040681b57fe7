"""Grass leaves: plastic, dynamic, reducible leaf model (Fournier & Pradal 2012) and canopies.

* :class:`LeafShape` (``shape``) — fit from digitised midrib/width data, presets
  ``maize``/``wheat``/``grass``, surface ``S(s, u)`` with twist and undulation;
* ``growth`` — growing leaves (:class:`LeafTimeline`, :class:`GrowthRates`);
* ``plastic`` — length-conserving curvature and width operators;
* ``reduction`` — triangle-budget reduction with a correct lazy-deletion heap;
* ``mesh`` — vectorised meshing of many leaves (:class:`LeafBatch`, :func:`mesh_batch`);
* ``canopy`` — plants (distichous phyllotaxy) and fields in rows, LAI, growth animation.

Units: metres, radians; leaves are Z-up (midrib in the local x–z plane).

>>> import biomorph as bm
>>> m = bm.leaf.LeafShape.from_preset("maize").mesh(age=0.6, triangles=200)
>>> m.n_faces
200
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "LeafShape": "shape",
    "MidribCollection": "shape",
    "load_presets": "shape",
    "LeafState": "growth",
    "GrowthRates": "growth",
    "LeafTimeline": "growth",
    "state_at_age": "growth",
    "LeafBatch": "mesh",
    "mesh_batch": "mesh",
    "mesh_leaf": "reduction",
    "leaf_areas": "mesh",
    "Reduction": "reduction",
    "reduce_leaf": "reduction",
    "reduced_mesh": "reduction",
    "bend": "plastic",
    "scale_width": "plastic",
    "PlasticOp": "plastic",
    "apply_ops": "plastic",
    "PlantSpec": "canopy",
    "FieldSpec": "canopy",
    "build_plant": "canopy",
    "build_field": "canopy",
    "field_mesh": "canopy",
    "plant_growth_frames": "canopy",
}


def __getattr__(name: str) -> Any:
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'biomorph.leaf' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"biomorph.leaf.{mod}"), name)
    globals()[name] = value
    return value


__all__ = sorted(_LAZY)
