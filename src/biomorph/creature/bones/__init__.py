"""Procedural bone models fitted into each joint's box (the seed's plan for its terminals).

``joint_meshes(creature, shape, lod)`` gives one mesh per joint with a bone, in that joint's
local frame (bone along +Y from the joint, metres), ready to be rigidly skinned to it (glTF)
or moved to world space (OBJ, renders). ``shape="box"`` keeps the seed's boxes (and its
tapered skull); ``shape="bone"`` (default) dresses each joint by its anatomical ``part``
(:mod:`biomorph.creature.anatomy`; joints without a label fall back to their kind/region):

=================  =======================================================================
cervical … caudal  vertebra: centrum, neural arch and spine, transverse processes, caudal
                   chevrons; spine height and process span vary along each region
thoracic           + a pair of ribs arching round the trunk's cross-section to the sternum
                   (a barrel cage sized by the trunk's depth, inside the skin; floating
                   ribs behind; fish: pleural ribs), :mod:`.cage`
skull / mandible   per class (mammal muzzle, bird beak, reptile snout, amphibian, fish):
                   cranium, orbits, zygomatic arches or jugal bar, palate at the jaw's top;
                   the mandible on its own joint when the creature has one (coronoid,
                   angular / retroarticular processes), else part of the skull, :mod:`.skull`
scapula / pelvis   blade on the rib cage's side with the glenoid at the shoulder joint /
                   ilium blade + acetabulum, pubis and ischium meeting at the midline;
                   clavicle where the class has one
long bones         shaft with epiphyses (humerus, femur), paired shafts (radius + ulna,
                   tibia + fibula)
metapodials        hands/feet/wing hands: metapodials + phalanges per class, claws, hooves
                   (unguligrade stance) or nails; fins: radials and a fan of rays;
                   a fish's dorsal, anal and caudal fin rays on its vertebrae
phalanx … nail     digit joints (when the skeleton has them)
=================  =======================================================================

Levels of detail: ``lod`` 0 (5-sided rings), 1 (8, default), 2 (14). Unit models are cached
(read-only arrays), so a creature costs only the scaling (see ``bench/gltf.py``).
"""

from __future__ import annotations

import importlib
from typing import Any

# lazy, as every package here: the models load with the first name used (and the unit-model
# modules never import this package back)
__all__ = ["SHAPES", "LODS", "geometry", "joint_meshes", "world_mesh"]


def __getattr__(name: str) -> Any:
    if name not in __all__:
        raise AttributeError(f"module 'biomorph.creature.bones' has no attribute {name!r}")
    value = getattr(importlib.import_module("biomorph.creature.bones.fit"), name)
    globals()[name] = value
    return value
