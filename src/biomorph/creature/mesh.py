"""Bone geometry: boxes (the seed's terminals) or simple procedural bone shapes.

Every mesh is built in its joint's local frame (bone along +Y from the joint), so it can be
rigidly skinned to that joint (glTF) or moved to world space (OBJ). ``shape="bone"`` is a
lathe profile with knobbly ends and a slimmer shaft (six sides); the skull always comes from
the skull library.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from biomorph.core.mesh import Mesh
from biomorph.creature import skulls
from biomorph.creature.creature import Creature
from biomorph.errors import ParameterError

SHAPES = ("box", "bone")

_BOX_V = np.array([[-.5, 0, -.5], [.5, 0, -.5], [.5, 0, .5], [-.5, 0, .5],
                   [-.5, 1, -.5], [.5, 1, -.5], [.5, 1, .5], [-.5, 1, .5]])
_BOX_F = np.array([[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6], [0, 4, 5], [0, 5, 1],
                   [1, 5, 6], [1, 6, 2], [2, 6, 7], [2, 7, 3], [3, 7, 4], [3, 4, 0]])


def _lathe(sides: int = 6) -> tuple[NDArray, NDArray]:
    """Unit bone: rings along y in [0, 1] with knobbly ends, radius 0.5 at the ends."""
    ys = np.array([0.0, 0.0, 0.1, 0.22, 0.5, 0.78, 0.9, 1.0, 1.0])
    rs = np.array([0.0, 0.45, 0.5, 0.3, 0.26, 0.3, 0.5, 0.45, 0.0])
    a = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    rings = []
    for y, r in zip(ys, rs, strict=True):
        rings.append(np.stack([r * np.cos(a), np.full(sides, y), r * np.sin(a)], axis=1))
    v = np.concatenate(rings)
    faces = []
    for k in range(len(ys) - 1):
        for j in range(sides):
            a0, a1 = k * sides + j, k * sides + (j + 1) % sides
            b0, b1 = a0 + sides, a1 + sides
            faces += [[a0, b1, a1], [a0, b0, b1]]
    f = np.array(faces)
    # drop triangles degenerate at the collapsed end rings
    keep = np.array([len({tuple(np.round(v[i], 12)) for i in tri}) == 3 for tri in f])
    return v, f[keep]


_BONE_V, _BONE_F = _lathe()
_BOX_N = Mesh(_BOX_V, _BOX_F).compute_normals().normals
_BONE_N = Mesh(_BONE_V, _BONE_F).compute_normals().normals


def _scaled(v: NDArray, f: NDArray, n: NDArray, scale: NDArray) -> Mesh:
    """Template scaled per axis, normals by the inverse-transpose (no per-mesh recompute)."""
    nn = n / np.where(scale > 0, scale, 1.0)
    nn /= np.maximum(np.linalg.norm(nn, axis=1, keepdims=True), 1e-12)
    return Mesh(v * scale, f, normals=nn)


def joint_meshes(creature: Creature, shape: str = "box", lod: int = 1) -> dict[int, Mesh]:
    """One mesh per joint with a bone, in that joint's local frame (metres)."""
    if shape not in SHAPES:
        raise ParameterError(f"bone shape {shape!r} unknown; expected one of "
                             f"{', '.join(SHAPES)}")
    out: dict[int, Mesh] = {}
    tv, tf_, tn = (_BOX_V, _BOX_F, _BOX_N) if shape == "box" else (_BONE_V, _BONE_F, _BONE_N)
    for j in range(len(creature)):
        L = creature.bone_length[j]
        if L <= 1e-9:
            continue
        if creature.kind[j] == "skull":
            v, f = skulls.mesh(skulls.get(creature.params.get("skull", "mammal_long")), L)
            out[j] = Mesh(v, f)
        else:
            size = creature.box_size[j]
            out[j] = _scaled(tv, tf_, tn, np.array([size[0], L, size[2]]))
    return out


def world_mesh(creature: Creature, shape: str = "box", lod: int = 1) -> Mesh:
    """All bone meshes merged in world space, faces labelled ``face_ids["bone"]``."""
    world = creature.world
    verts, faces, ids = [], [], []
    base = 0
    for j, m in joint_meshes(creature, shape).items():
        v = m.vertices @ world[j, :3, :3].T + world[j, :3, 3]
        verts.append(v)
        faces.append(m.faces + base)
        ids.append(np.full(m.n_faces, j))
        base += m.n_vertices
    return Mesh(np.concatenate(verts), np.concatenate(faces),
                face_ids={"bone": np.concatenate(ids)})
