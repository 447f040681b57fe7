"""The species model the generator samples from: dataset table, PCA and derived statistics.

Fitted once per dataset path and cached (:func:`species_model`); every array it holds is
read-only, so a caller cannot change what the next caller samples from (issue 12). The PCA
here (``reparam=True``: neck and tail as offsets, seed §4.5) is the one ``biomorph creature
dataset`` prints.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from functools import lru_cache
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.creature import pca as pc
from biomorph.creature import spine as sp
from biomorph.creature.dataset import CLASSES, SpeciesTable, load_species


@dataclass(frozen=True, eq=False)
class SpeciesModel:
    """What the generator samples from (all arrays read-only)."""

    table: SpeciesTable
    pca: pc.PCA  # reparametrised PCA (seed §4.5)
    feats: NDArray[np.float64]  # (n, 29) features without reparam
    region_len: NDArray[np.float64]  # (n, 3) neck/back/tail arc lengths (px)
    neck_dir: NDArray[np.float64]  # mean unit neck offset direction
    tail_dir: NDArray[np.float64]  # mean unit tail offset direction
    cls_scores: MappingProxyType[str, NDArray[np.float64]]  # class → (m, 3) PC scores


def _ro(a: Any) -> Any:
    if isinstance(a, np.ndarray):
        a = np.array(a)  # own copy: never freeze an array someone else holds
        a.flags.writeable = False
    return a


def _frozen(obj: Any) -> Any:
    """Copy of a dataclass with every array field read-only."""
    return replace(
        obj,
        **{
            f.name: _ro(getattr(obj, f.name))
            for f in fields(obj)
            if isinstance(getattr(obj, f.name), np.ndarray)
        },
    )


def _mean_dir(off: NDArray) -> NDArray[np.float64]:
    n = np.linalg.norm(off, axis=1)
    keep = n > 20
    d = (off[keep] / n[keep, None]).mean(axis=0)
    return d / np.linalg.norm(d)


@lru_cache(maxsize=8)
def species_model(dataset: str | None = None) -> SpeciesModel:
    """The (cached, read-only) model of the species CSV ``dataset`` (None = built-in)."""
    table = load_species(dataset)
    model = pc.fit_dataset(table, reparam=True)
    feats = pc.encode(table.points, table.lengths, table.wings, table.legs, table.weight)
    region_len = np.array([sp.region_lengths(*sp.sample(p, 16)[1:]) for p in table.points])
    off_n = table.points[:, 0] - table.points[:, 3]
    off_t = table.points[:, 9] - table.points[:, 6]
    cls_scores = {
        c: _ro(model.scores[[i for i, x in enumerate(table.cls) if x == c], :3]) for c in CLASSES
    }
    return SpeciesModel(
        table=_frozen(table),
        pca=_frozen(model),
        feats=_ro(feats),
        region_len=_ro(region_len),
        neck_dir=_ro(_mean_dir(off_n)),
        tail_dir=_ro(_mean_dir(off_t)),
        cls_scores=MappingProxyType(cls_scores),
    )
