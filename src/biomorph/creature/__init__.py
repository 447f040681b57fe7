"""Procedural vertebrate skeletons (seed 000: Zimbel, KIT 2020) — and beyond.

A PCA over 44 annotated species (spine Béziers, limb lengths, wings, legs, weight) gives
Gaussian samples — conditioned on any dims — from which a skeleton grows step by step:
spine (C1 fix, vertebrae by arc length) → girdles (up to two limb pairs each, centaur
girdle) → limbs (fins, arms, wings, legs grounded by the seed's angle descent) → skull
(from a small library) → finish (mass model, centre of mass, support polygon, balance
repair). Exports: glTF, BVH (+ walk cycle), OBJ, OpenSim, MJCF, JSON.

Example
-------
>>> import biomorph as bm
>>> c = bm.creature.generate(seed=7, legs=4, wings=False)
>>> c.balance.stable
True
"""

from __future__ import annotations

import importlib
from typing import Any

# lazy: ``biomorph creature --help`` loads none of the numeric stack (tests/test_fast_start.py)
_LAZY = {
    "Creature": "creature",
    "SpeciesTable": "dataset",
    "load_species": "dataset",
    "export": "exporters",
    "STEPS": "options",
    "Options": "options",
    "Generator": "generator",
    "generate": "generator",
    "DescentParams": "limbs",
    "PCA": "pca",
    "fit_dataset": "pca",
    "species_model": "model",
    "PARTS": "anatomy",
}


def __getattr__(name: str) -> Any:
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'biomorph.creature' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"biomorph.creature.{mod}"), name)
    globals()[name] = value
    return value


__all__ = sorted(_LAZY)
