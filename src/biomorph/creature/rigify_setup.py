"""The Blender-side half of ``--rigify``: a Python script run inside Blender.

Blender's glTF importer turns node ``extras`` into bone custom properties but always
imports bones unconnected, picks their tails by a heuristic and cannot set Rigify's
parameters. The script :data:`SCRIPT` (printed or written by ``biomorph creature
rigify-setup``) imports a ``--rigify`` GLB (or works on the armature already in the scene),
puts every bone's head, tail and roll back exactly from ``biomorph_head`` /
``biomorph_tail`` / ``biomorph_z``, restores the connected chains, clears the pose (a
metarig is edited at rest), sets ``rigify_type`` and its parameters on the pose bones and,
with ``--generate``, runs Rigify's generate and re-binds the bone mesh to the new rig's
deform bones. Usage::

    blender -b --python-exit-code 1 --python rigify_setup.py -- creature.glb --generate \
        --save creature_rig.blend

Inside Blender's UI: open the script in the Text Editor, set ``GLB`` at the top (or import
the file first) and press Run Script.
"""

from __future__ import annotations

SCRIPT = r'''# biomorph rigify-setup: finish a biomorph --rigify GLB as a Rigify metarig in Blender
import sys

import warnings

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import numpy
    if "bool" not in numpy.__dict__:
        numpy.bool = bool  # Debian's Blender 3.4 glTF add-on still uses numpy.bool

import addon_utils
import bpy
from mathutils import Matrix, Vector

GLB = None  # set a path here when running from Blender's Text Editor


def _args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    out = {"glb": GLB, "generate": False, "save": None}
    it = iter(argv)
    for a in it:
        if a == "--generate":
            out["generate"] = True
        elif a == "--save":
            out["save"] = next(it)
        else:
            out["glb"] = a
    return out


def import_glb(path):
    addon_utils.enable("io_scene_gltf2", default_set=True)
    bpy.ops.import_scene.gltf(filepath=path)


def find_metarig():
    for obj in bpy.data.objects:
        if obj.type == "ARMATURE" and any("biomorph_head" in b for b in obj.data.bones):
            return obj
    raise SystemExit("biomorph rigify-setup: no armature with biomorph bone data in the "
                     "scene; import a GLB written with --rigify first")


def restore(obj):
    """Exact heads/tails/rolls, connect flags, rest pose, rig types and parameters."""
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    if obj.animation_data is not None:
        obj.animation_data.action = None  # a metarig is edited and generated at rest
    bpy.ops.object.mode_set(mode="EDIT")
    for eb in obj.data.edit_bones:
        if "biomorph_head" in eb:
            eb.use_connect = False
            eb.head = Vector(eb["biomorph_head"])
            eb.tail = Vector(eb["biomorph_tail"])
            eb.align_roll(Vector(eb["biomorph_z"]))
    for eb in obj.data.edit_bones:
        eb.use_connect = bool(eb.get("biomorph_connect", 0)) and eb.parent is not None
    bpy.ops.object.mode_set(mode="POSE")
    for pb in obj.pose.bones:
        pb.matrix_basis = Matrix.Identity(4)
        rig_type = pb.bone.get("rigify_type", "")
        if hasattr(pb, "rigify_type"):
            pb.rigify_type = rig_type
            for key, value in dict(pb.bone.get("biomorph_parameters", {})).items():
                setattr(pb.rigify_parameters, key, value)
    bpy.ops.object.mode_set(mode="OBJECT")


def generate(metarig):
    """Rigify's generate; the bone mesh is moved over to the generated rig."""
    bpy.context.view_layer.objects.active = metarig
    bpy.ops.pose.rigify_generate()
    rig = bpy.context.view_layer.objects.active
    names = set(rig.data.bones.keys())
    for obj in bpy.data.objects:
        mods = [m for m in getattr(obj, "modifiers", []) if m.type == "ARMATURE"
                and m.object == metarig]
        for mod in mods:
            mod.object = rig
            for vg in obj.vertex_groups:
                if "DEF-" + vg.name in names:
                    vg.name = "DEF-" + vg.name
            if obj.parent == metarig:
                obj.parent = rig
    return rig


def main():
    args = _args()
    addon_utils.enable("rigify", default_set=True)
    if args["glb"]:
        import_glb(args["glb"])
    metarig = find_metarig()
    restore(metarig)
    rig = generate(metarig) if args["generate"] else None
    print("biomorph rigify-setup: metarig %r with %d bones%s" % (
        metarig.name, len(metarig.data.bones),
        "" if rig is None else ", generated %r with %d bones" % (rig.name,
                                                              len(rig.data.bones))))
    if args["save"]:
        bpy.ops.wm.save_as_mainfile(filepath=args["save"])


main()
'''


def script() -> str:
    """The Blender script (see the module docstring)."""
    return SCRIPT
