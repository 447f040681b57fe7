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

from biomorph.creature.creature import Creature
from biomorph.creature.dataset import SpeciesTable, load_species
from biomorph.creature.export import export
from biomorph.creature.generator import STEPS, Generator, Options, generate
from biomorph.creature.limbs import DescentParams
from biomorph.creature.pca import PCA, fit_dataset

__all__ = ["Creature", "Generator", "Options", "generate", "export", "DescentParams", "PCA",
           "fit_dataset", "load_species", "SpeciesTable", "STEPS"]
