"""Write a creature in any supported format, chosen by the file extension.

========  =====================================================================
.json     parameters, seed, bones (offsets, rotations, limits, boxes), masses, balance
.glb      skinned glTF: joint hierarchy + one bone mesh per joint, rigidly weighted
.bvh      hierarchy and rest pose (frame 0), optionally a procedural walk cycle
.obj      bone meshes in world space, one OBJ group per bone
.osim     OpenSim model: bodies with mass/inertia, joints with ranges in radians
.xml      MuJoCo MJCF (also ``.mjcf``)
========  =====================================================================
"""

from __future__ import annotations

import os
from pathlib import Path

from biomorph.creature.creature import Creature, write_json
from biomorph.errors import UnsupportedFormatError

FORMATS = (".json", ".glb", ".bvh", ".obj", ".osim", ".xml", ".mjcf")


def check_extension(path: str | os.PathLike[str]) -> str:
    """The lower-case extension of ``path`` if it is a creature format, else raise."""
    ext = Path(path).suffix.lower()
    if ext not in FORMATS:
        raise UnsupportedFormatError(f"{os.fspath(path)}: cannot write a creature as "
                                     f"{ext or '(no extension)'!r}; expected one of "
                                     f"{' '.join(FORMATS)}")
    return ext


def export(creature: Creature, path: str | os.PathLike[str], bone_shape: str = "box",
           walk: bool = False, rigify: bool = False) -> Path:
    """Write ``creature`` to ``path`` (format by extension); atomic; returns the path.

    ``walk`` adds a procedural walk cycle (glb, bvh); ``rigify`` renames bones the way
    Blender's Rigify expects (``spine.001``, ``thigh.L`` …)."""
    ext = check_extension(path)
    original = creature
    if rigify:
        from biomorph.creature.rigify import with_rigify_names
        creature = with_rigify_names(creature)

    def walk_motion():
        from biomorph.creature.walk import walk_cycle
        return walk_cycle(original).with_(skeleton=creature.skeleton)

    if ext == ".json":
        return write_json(path, creature)
    if ext == ".glb":
        from biomorph.creature.mesh import joint_meshes
        from biomorph.io.gltf import write_gltf

        motion = walk_motion() if walk else None
        return write_gltf(path, creature.skeleton, motion=motion, bone_shape=None,
                          meshes=joint_meshes(creature, bone_shape), name="creature")
    if ext == ".bvh":
        from biomorph.io.bvh import write_bvh

        if walk:
            return write_bvh(path, walk_motion())
        return write_bvh(path, creature.skeleton)
    if ext == ".obj":
        from biomorph.creature.mesh import world_mesh
        from biomorph.io.obj import write_mesh

        return write_mesh(path, world_mesh(creature, bone_shape), object_name="creature")
    if ext == ".osim":
        from biomorph.io.osim import write_osim
        return write_osim(path, creature)
    from biomorph.io.mjcf import write_mjcf
    return write_mjcf(path, creature)
