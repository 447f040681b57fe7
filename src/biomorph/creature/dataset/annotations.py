"""A species-dataset row from an annotated Inkscape SVG side view (``creature annotate``).

:mod:`biomorph.io.svg_annotations` reads the drawing (spine Béziers, limb lines, in the seed's
1000-px y-up frame); this module checks the species facts and lays the numbers out in the
columns of :mod:`biomorph.creature.dataset`.
"""

from __future__ import annotations

import numpy as np

from biomorph.creature.dataset import CLASSES, LIMB_COLUMNS, POINT_COLUMNS
from biomorph.errors import ParameterError
from biomorph.io.svg_annotations import PathLike, read_annotations


def species_row(
    path: PathLike, name: str, cls: str, weight: float, wings: bool, legs: int
) -> dict[str, object]:
    """A dataset row (see :mod:`biomorph.creature.dataset`) from an annotated SVG."""
    if cls not in CLASSES:
        raise ParameterError(f"class {cls!r} unknown; expected one of {', '.join(CLASSES)}")
    if not (np.isfinite(weight) and weight > 0):
        raise ParameterError(f"weight {weight} kg must be > 0")
    if legs not in (0, 2, 4):
        raise ParameterError(f"legs {legs}: annotated species have 0, 2 or 4 legs on the ground")
    ann = read_annotations(path)
    row: dict[str, object] = {
        "name": name,
        "german": "",
        "class": cls,
        "weight_kg": float(weight),
        "wings": int(bool(wings)),
        "legs": int(legs),
    }
    for k, col in enumerate(POINT_COLUMNS):
        row[col] = round(float(ann["points"].reshape(-1)[k]), 3)
    for k, col in enumerate(LIMB_COLUMNS):
        row[col] = round(float(ann["lengths"][k]), 3)
    return row
