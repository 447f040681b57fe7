"""Bone geometry of a creature (kept for ``from biomorph.creature.mesh import …``).

The models live in :mod:`biomorph.creature.bones` (procedural bone models fitted into each
joint's box, or the seed's boxes with ``shape="box"``); this module re-exports them. It is
the one bone-mesh generator for creatures: :mod:`biomorph.io.gltf` only writes the meshes
it is given (its ``sticks`` solids are for bare skeletons such as BVH files).
"""

from __future__ import annotations

from biomorph.creature.bones import LODS, SHAPES, joint_meshes, world_mesh

__all__ = ["SHAPES", "LODS", "joint_meshes", "world_mesh"]
