"""glTF 2.0 binary (.glb) writer: skinned skeletons, skeletal animation, plain meshes.

What gets written
-----------------
* **JointSkeleton** → one node per joint (TRS = the joint's local rest transform: translation
  ``offset``, rotation ``rest_rotation``), all under one armature node; a skin over all joints
  with inverse bind matrices (inverse rest world matrices, column-major float32); one box
  (or octahedron) per bone, from the joint towards each child (leaf joints: towards the BVH
  ``End Site``, or a small cube), rigidly skinned to the joint through ``JOINTS_0`` /
  ``WEIGHTS_0``. The skinned mesh node sits at the scene root with no transform, as the
  spec asks, so Blender imports an armature with one bone per joint.
* **Motion-like objects** (duck-typed: ``.skeleton``, ``.rotation`` ``float[f, n, 4]`` pose
  quaternions xyzw applied after each joint's rest rotation, ``.root_position``
  ``float[f, 3]``, ``.frame_time`` seconds) → the skeleton above plus one animation: a
  rotation channel per joint (rest · pose, hemisphere-continuous) and a translation channel
  per root joint (and per translated inner joint when the motion has ``joint_translation``),
  LINEAR samplers, float32 key times ``k · frame_time``.
* **Meshes** (:class:`biomorph.core.mesh.Mesh` or anything ``Mesh.from_any`` accepts, or a
  list of them) → plain mesh nodes with ``POSITION`` (with min/max), ``NORMAL``,
  ``TEXCOORD_0`` (v flipped: glTF's origin is top-left), ``COLOR_0`` (RGBA unsigned byte,
  normalised) and each ``face_ids`` entry as a per-vertex custom attribute ``_<NAME>_ID``
  (unsigned short when the ids fit in 0..65535, else float). Vertices shared by faces with
  different ids are split so every face keeps its ids. A list of meshes is merged into a
  single primitive (with a ``_MESH_ID`` attribute giving each vertex's list index) unless
  ``merge=False``: 100,000 small leaves become one draw call, not 100,000 nodes.
* **Mesh frames** (``frames=[mesh0, mesh1, …]``, equal topology) → one mesh with a morph
  target per frame after the first and a weight animation that steps through them (linear
  blends between consecutive frames), for growing leaves; face ids and normals are kept.

Frames and units: metres, seconds, glTF is Y-up. ``y_up=True`` (default) means the input is
already Y-up (creatures, motion); pass ``y_up=False`` for Z-up data (trees, leaves) and it is
rotated by −90° about x, ``(x, y, z) → (x, z, −y)``, on the way out. ``scale`` multiplies
every length (``0.01`` turns a centimetre BVH into metres).

Buffers are built with numpy (``tobytes``), every buffer view 4-byte aligned with its
``target`` set for vertex/index data; indices are ``uint16`` when they fit, ``uint32``
otherwise. Files are written atomically.

Modules: ``builder`` (bytes, accessors, save), ``arrays`` (shared array helpers),
``meshes`` (plain mesh primitives), ``sticks`` (display solids for bare skeletons),
``skin`` (joints, skin, skinned mesh), ``animation`` (channels, morph frames), ``writer``
(public writers), ``summary`` (reading back). Example::

    from biomorph.io.gltf import write_gltf, read_gltf_summary
    write_gltf("walk.glb", motion)                   # skinned, animated armature
    write_gltf("canopy.glb", leaves, y_up=False)     # list of Z-up leaf meshes, merged
    read_gltf_summary("walk.glb")["animations"]      # -> 1
"""

from __future__ import annotations

from biomorph.io.gltf.builder import _Builder
from biomorph.io.gltf.summary import read_gltf_summary
from biomorph.io.gltf.writer import write_gltf, write_mesh, write_mesh_animation

__all__ = ["write_gltf", "write_mesh", "write_mesh_animation", "read_gltf_summary", "_Builder"]
