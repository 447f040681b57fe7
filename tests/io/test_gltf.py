"""glTF writer: structure, numbers read back, Khronos validation, trimesh round trip."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pygltflib
import pytest
import trimesh

import biomorph.io as bmio
from biomorph.core import transforms as tf
from biomorph.core.mesh import Mesh
from biomorph.core.skeleton import JointSkeleton
from biomorph.errors import BiomorphError, FormatError, InputError, ParameterError
from biomorph.io.gltf import read_gltf_summary, write_gltf, write_mesh, write_mesh_animation
from tests.gltf_validator import assert_valid_glb, validate_glb, validate_many

NAN3 = [np.nan] * 3
DTYPES = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


# ----------------------------------------------------------------------------- helpers
def skeleton(rest: bool = True) -> JointSkeleton:
    """A small biped-ish hierarchy with rest rotations, End Sites and a 3-way fork."""
    names = ["hips", "spine", "head", "l_leg", "l_foot", "r_leg", "r_foot"]
    parent = [-1, 0, 1, 0, 3, 0, 5]
    offset = [
        [0, 1.0, 0],
        [0, 0.25, 0],
        [0, 0.3, 0.02],
        [0.1, -0.05, 0],
        [0, -0.45, 0],
        [-0.1, -0.05, 0],
        [0, -0.45, 0],
    ]
    rest_rot = tf.quat_identity((7,))
    if rest:
        rest_rot[1] = tf.quat_from_axis_angle("z", 0.2)
        rest_rot[3] = tf.quat_from_axis_angle([1, 1, 0], 0.4)
    end = [NAN3, NAN3, [0, 0.15, 0], NAN3, [0, 0, 0.12], NAN3, NAN3]
    return JointSkeleton(names, parent, offset, rest_rotation=rest_rot, end_site=end)


def motion(frames: int = 12, sk: JointSkeleton | None = None) -> SimpleNamespace:
    """A hand-made Motion-like object: every joint swings about its own axis."""
    sk = sk or skeleton()
    t = np.linspace(0, 1, frames)[:, None]
    axes = np.array(
        [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1]], float
    )[: len(sk)]
    rot = tf.quat_from_axis_angle(axes[None], np.sin(3 * t) * np.linspace(0.2, 1.4, len(sk)))
    root = np.c_[np.linspace(0, 2, frames), 1 + 0.05 * np.sin(6 * t[:, 0]), np.zeros(frames)]
    return SimpleNamespace(skeleton=sk, rotation=rot, root_position=root, frame_time=1 / 30)


def load(path):
    doc = pygltflib.GLTF2().load(str(path))
    return doc, doc.binary_blob()


def accessor(doc, blob, idx) -> np.ndarray:
    """Read accessor ``idx`` as a numpy array (handles byteStride; MAT4 -> (n, 4, 4))."""
    acc = doc.accessors[idx]
    view = doc.bufferViews[acc.bufferView]
    dtype = np.dtype(DTYPES[acc.componentType])
    width = WIDTH[acc.type]
    elem = dtype.itemsize * width
    stride = view.byteStride or elem
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    raw = np.frombuffer(blob, np.uint8, count=stride * (acc.count - 1) + elem, offset=start)
    rows = np.lib.stride_tricks.as_strided(raw, (acc.count, elem), (stride, 1))
    out = np.ascontiguousarray(rows).view(dtype).reshape(acc.count, width)
    if acc.type == "MAT4":
        return np.swapaxes(out.reshape(-1, 4, 4), 1, 2)  # stored column-major
    return out[:, 0] if width == 1 else out


def trs(node) -> np.ndarray:
    t = node.translation or [0, 0, 0]
    r = node.rotation or [0, 0, 0, 1]
    return tf.make_transform(tf.quat_to_matrix(np.array(r, float)), np.array(t, float))


def node_world(doc, local: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """World matrices of all nodes from per-node local matrices (scene roots down)."""
    world: dict[int, np.ndarray] = {}
    stack = [(i, np.eye(4)) for i in doc.scenes[doc.scene].nodes]
    while stack:
        i, parent = stack.pop()
        world[i] = parent @ local[i]
        stack.extend((c, world[i]) for c in doc.nodes[i].children or [])
    return world


# ----------------------------------------------------------------------------- skeleton
def test_skeleton_hierarchy_trs_and_inverse_binds(tmp_path):
    sk = skeleton()
    path = write_gltf(tmp_path / "skel.glb", sk, name="biped")
    assert_valid_glb(path, max_warnings=0)
    doc, blob = load(path)
    skin = doc.skins[0]
    joints = skin.joints
    assert [doc.nodes[j].name for j in joints] == list(sk.names)
    # hierarchy: node children reproduce the parent array
    parent_of = {c: i for i, n in enumerate(doc.nodes) for c in (n.children or [])}
    got_parent = [joints.index(parent_of[j]) if parent_of.get(j) in joints else -1 for j in joints]
    assert got_parent == list(sk.parent)
    # local TRS = rest offset and rest rotation
    local = np.stack([trs(doc.nodes[j]) for j in joints])
    np.testing.assert_allclose(local, sk.local_matrices(), atol=1e-6)
    # inverse bind matrices = inverse rest world (column-major on disk)
    ibm = accessor(doc, blob, skin.inverseBindMatrices)
    np.testing.assert_allclose(
        ibm @ sk.world_matrices(), np.broadcast_to(np.eye(4), ibm.shape), atol=1e-5
    )
    # skinned mesh node at the scene root, without a transform
    mesh_nodes = [i for i, n in enumerate(doc.nodes) if n.skin is not None]
    assert len(mesh_nodes) == 1 and mesh_nodes[0] in doc.scenes[0].nodes
    node = doc.nodes[mesh_nodes[0]]
    assert node.translation is None and node.rotation is None and node.matrix is None
    prim = doc.meshes[node.mesh].primitives[0]
    # rigid skinning: one joint per vertex with weight 1
    j0 = accessor(doc, blob, prim.attributes.JOINTS_0)
    w0 = accessor(doc, blob, prim.attributes.WEIGHTS_0)
    assert np.all(w0[:, 0] == 1) and np.all(w0[:, 1:] == 0) and np.all(j0[:, 1:] == 0)
    # every joint with a child or an End Site owns geometry; the bare leaf r_foot gets a cube
    assert set(np.unique(j0[:, 0])) == set(range(len(sk)))
    # buffer view targets on vertex and index data
    targets = {
        doc.bufferViews[doc.accessors[a].bufferView].target
        for a in (prim.attributes.POSITION, prim.attributes.JOINTS_0)
    }
    assert targets == {34962}
    assert doc.bufferViews[doc.accessors[prim.indices].bufferView].target == 34963


def test_bone_boxes_span_parent_to_child(tmp_path):
    sk = skeleton()
    path = write_gltf(tmp_path / "b.glb", sk, bone_width=0.02)
    doc, blob = load(path)
    prim = doc.meshes[0].primitives[0]
    pos = accessor(doc, blob, prim.attributes.POSITION)
    joint = accessor(doc, blob, prim.attributes.JOINTS_0)[:, 0]
    world = sk.world_positions()
    # the spine's geometry (owned by joint 1) reaches from the spine joint to the head joint
    sp = pos[joint == 1]
    d = world[2] - world[1]
    along = (sp - world[1]) @ d / (d @ d)
    assert along.min() == pytest.approx(0, abs=1e-5) and along.max() == pytest.approx(1, abs=1e-5)
    across = np.linalg.norm((sp - world[1]) - along[:, None] * d, axis=1)
    assert across.max() == pytest.approx(0.02 * np.sqrt(0.5), rel=1e-3)
    # the feet's End Site box reaches the End Site
    foot_tip = world[4] + tf.quat_rotate(
        tf.matrix_to_quat(sk.world_matrices()[4, :3, :3]), [0, 0, 0.12]
    )
    assert np.min(np.linalg.norm(pos[joint == 4] - foot_tip, axis=1)) < 0.02


def test_bone_shapes_and_multiple_roots(tmp_path):
    sk = JointSkeleton(
        ["a", "b", "fin", "fin_tip"], [-1, 0, -1, 2], [[0, 0, 0], [0, 1, 0], [1, 0, 0], [0.5, 0, 0]]
    )
    for shape in ("box", "octahedron", None):
        path = write_gltf(tmp_path / f"{shape}.glb", sk, bone_shape=shape)
        assert_valid_glb(path)
        info = read_gltf_summary(path)
        assert info["joints"] == 4 and info["skins"] == 1
        assert (info["meshes"] == 0) == (shape is None)
    doc, _ = load(tmp_path / "box.glb")
    armature = doc.skins[0].skeleton
    assert doc.nodes[armature].children == [doc.skins[0].joints[0], doc.skins[0].joints[2]]


def test_joint_meshes_and_static_meshes(tmp_path):
    sk = skeleton()
    cube = trimesh.creation.box((0.05, 0.05, 0.05))
    path = write_gltf(tmp_path / "jm.glb", sk, meshes={"head": cube, 4: cube}, bone_shape=None)
    assert_valid_glb(path)
    doc, blob = load(path)
    prim = doc.meshes[0].primitives[0]
    joint = accessor(doc, blob, prim.attributes.JOINTS_0)[:, 0]
    pos = accessor(doc, blob, prim.attributes.POSITION)
    assert set(joint) == {2, 4}
    np.testing.assert_allclose(pos[joint == 2].mean(axis=0), sk.world_positions()[2], atol=1e-5)
    path = write_gltf(tmp_path / "sm.glb", sk, meshes=[cube, cube])
    assert_valid_glb(path)
    assert read_gltf_summary(path)["meshes"] == 2  # bones + merged static meshes


# ----------------------------------------------------------------------------- animation
def channels(doc, blob) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], np.ndarray]:
    """Rotation and translation keys per node, and the key times, of animation 0."""
    anim = doc.animations[0]
    rot: dict[int, np.ndarray] = {}
    trans: dict[int, np.ndarray] = {}
    times = None
    for ch in anim.channels:
        s = anim.samplers[ch.sampler]
        assert s.interpolation == "LINEAR"
        times = accessor(doc, blob, s.input)
        (rot if ch.target.path == "rotation" else trans)[ch.target.node] = accessor(
            doc, blob, s.output
        )
    return rot, trans, times


def skinned_positions(doc, blob, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """glTF skinning by hand at key ``frame``: (bind positions, skinned positions)."""
    rot, trans, _ = channels(doc, blob)
    prim = doc.meshes[0].primitives[0]
    pos = accessor(doc, blob, prim.attributes.POSITION).astype(float)
    jnt = accessor(doc, blob, prim.attributes.JOINTS_0)[:, 0]
    ibm = accessor(doc, blob, doc.skins[0].inverseBindMatrices).astype(float)
    local = {}
    for i, n in enumerate(doc.nodes):
        r = rot[i][frame] if i in rot else (n.rotation or [0, 0, 0, 1])
        t = trans[i][frame] if i in trans else (n.translation or [0, 0, 0])
        local[i] = tf.make_transform(tf.quat_to_matrix(np.asarray(r, float)), t)
    world = node_world(doc, local)
    jm = np.stack([world[n] for n in doc.skins[0].joints]) @ ibm
    return pos, tf.apply(jm[jnt], pos)


def test_animation_keys_round_trip_and_skinning(tmp_path):
    mo = motion(frames=15)
    sk = mo.skeleton
    path = write_gltf(tmp_path / "walk.glb", mo)
    report = assert_valid_glb(path, max_warnings=0)
    assert report["info"]["animationCount"] == 1
    doc, blob = load(path)
    joints = doc.skins[0].joints
    rot, trans, times = channels(doc, blob)
    assert times.dtype == np.float32
    np.testing.assert_allclose(times, np.arange(15) / 30, atol=1e-6)
    assert sorted(rot) == sorted(joints) and list(trans) == [joints[0]]
    expected = tf.quat_multiply(sk.rest_rotation, mo.rotation)
    for j, node in enumerate(joints):
        dots = np.abs(np.sum(rot[node] * expected[:, j], axis=1))
        np.testing.assert_allclose(dots, 1, atol=1e-5)
        # hemisphere-continuous keys, so LINEAR interpolation takes the short way
        assert np.all(np.sum(rot[node][1:] * rot[node][:-1], axis=1) > 0)
    np.testing.assert_allclose(trans[joints[0]], mo.root_position, atol=1e-6)
    # glTF skinning at frame k moves each bone vertex exactly like the skeleton's pose
    k = 9
    pos, skinned = skinned_positions(doc, blob, k)
    jnt = accessor(doc, blob, doc.meshes[0].primitives[0].attributes.JOINTS_0)[:, 0]
    pose_world = sk.world_matrices(sk.local_matrices(mo.rotation[k], mo.root_position[k]))
    expected_pos = tf.apply(pose_world[jnt] @ tf.invert(sk.world_matrices())[jnt], pos)
    np.testing.assert_allclose(skinned, expected_pos, atol=1e-4)


def test_translated_inner_joints_and_scale(tmp_path):
    mo = motion(frames=6)
    sk = mo.skeleton
    jt = np.broadcast_to(sk.offset, (6, len(sk), 3)).copy()
    jt[:, 0] = mo.root_position
    jt[:, 2, 1] += np.linspace(0, 0.1, 6)  # the head slides up its neck
    mo.joint_translation = jt
    path = write_gltf(tmp_path / "jt.glb", mo, scale=100.0)  # metres -> centimetres
    assert_valid_glb(path, max_warnings=0)
    doc, blob = load(path)
    joints = doc.skins[0].joints
    _, trans, _ = channels(doc, blob)
    assert sorted(trans) == [joints[0], joints[2]]
    np.testing.assert_allclose(trans[joints[2]], 100 * jt[:, 2], atol=1e-4)
    np.testing.assert_allclose(trans[joints[0]], 100 * mo.root_position, atol=1e-4)
    np.testing.assert_allclose(doc.nodes[joints[1]].translation, 100 * sk.offset[1], atol=1e-9)
    # skinning with the translated head matches forward kinematics with those translations
    k = 5
    pos, skinned = skinned_positions(doc, blob, k)
    jnt = accessor(doc, blob, doc.meshes[0].primitives[0].attributes.JOINTS_0)[:, 0]
    q = tf.quat_multiply(sk.rest_rotation, mo.rotation[k])
    loc = tf.make_transform(tf.quat_to_matrix(q), 100 * jt[k])
    pose_world = sk.with_(offset=100 * sk.offset).world_matrices(loc)
    rest_world = sk.with_(offset=100 * sk.offset).world_matrices()
    expected_pos = tf.apply(pose_world[jnt] @ tf.invert(rest_world)[jnt], pos)
    np.testing.assert_allclose(skinned, expected_pos, atol=1e-3)
    with pytest.raises(ParameterError, match="scale"):
        write_gltf(tmp_path / "bad.glb", sk, scale=0)


def test_real_motion_types(tmp_path):
    """The motion pillar's own Motion (duck-typed here) and a real CMU capture."""
    from biomorph.motion.synthetic import walk
    from tests.conftest import shared_file

    mo = walk(n_frames=30)
    assert_valid_glb(write_gltf(tmp_path / "walk.glb", mo), max_warnings=0)
    real = bmio.read_bvh(shared_file("motion", "ad_cmu1_jumping_jacks.bvh"))
    path = write_gltf(tmp_path / "jacks.glb", real, scale=0.056)
    assert_valid_glb(path, max_warnings=0)
    info = read_gltf_summary(path)
    assert info["joints"] == 31 and info["animations"] == 1
    assert info["duration"] == pytest.approx((real.n_frames - 1) * real.frame_time, rel=1e-6)


def test_motion_keyword_and_wrapped_objects(tmp_path):
    mo = motion(frames=4)
    a = write_gltf(tmp_path / "a.glb", mo.skeleton, motion=mo)
    creature = SimpleNamespace(skeleton=mo.skeleton)  # e.g. a generated creature
    b = write_gltf(tmp_path / "b.glb", creature)
    assert read_gltf_summary(a)["animations"] == 1
    assert read_gltf_summary(b)["animations"] == 0
    assert read_gltf_summary(a)["duration"] == pytest.approx(3 / 30)
    single = SimpleNamespace(
        skeleton=mo.skeleton,
        rotation=mo.rotation[:1],
        root_position=mo.root_position[:1],
        frame_time=0.1,
    )
    assert_valid_glb(write_gltf(tmp_path / "one.glb", single))


def test_z_up_conversion(tmp_path):
    sk = JointSkeleton(["trunk", "branch"], [-1, 0], [[1, 2, 3], [0, 0, 1]])
    path = write_gltf(tmp_path / "z.glb", sk, y_up=False)
    assert_valid_glb(path)
    doc, blob = load(path)
    joints = doc.skins[0].joints
    world = node_world(doc, {i: trs(n) for i, n in enumerate(doc.nodes)})
    # Z-up (x, y, z) -> Y-up (x, z, -y)
    np.testing.assert_allclose(world[joints[0]][:3, 3], [1, 3, -2], atol=1e-6)
    np.testing.assert_allclose(world[joints[1]][:3, 3], [1, 4, -2], atol=1e-6)
    ibm = accessor(doc, blob, doc.skins[0].inverseBindMatrices)
    np.testing.assert_allclose(ibm[1] @ world[joints[1]], np.eye(4), atol=1e-6)
    mo = SimpleNamespace(
        skeleton=sk,
        rotation=tf.quat_identity((3, 2)),
        root_position=np.tile([1.0, 2, 3], (3, 1)),
        frame_time=0.5,
    )
    path = write_gltf(tmp_path / "zm.glb", mo, y_up=False)
    assert_valid_glb(path)
    doc, blob = load(path)
    tr = [c for c in doc.animations[0].channels if c.target.path == "translation"][0]
    np.testing.assert_allclose(
        accessor(doc, blob, doc.animations[0].samplers[tr.sampler].output)[0], [1, 3, -2]
    )


# ----------------------------------------------------------------------------- meshes
def leaf_mesh(seed: int = 0, n: int = 6) -> Mesh:
    """A strip of quads with normals, uv, colours and per-face ids."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 1, n)
    v = np.concatenate([np.c_[s, -0.1 + 0 * s, s**2], np.c_[s, 0.1 + 0 * s, s**2]])
    v += rng.normal(0, 0.001, v.shape)
    i = np.arange(n - 1)
    faces = np.concatenate([np.c_[i, i + 1, n + i], np.c_[i + 1, n + i + 1, n + i]])
    m = Mesh(
        v,
        faces,
        uv=np.c_[np.r_[s, s], np.r_[0 * s, 0 * s + 1]],
        vertex_colors=np.tile([30, 160, 40, 255], (2 * n, 1)),
        face_ids={"plant": np.full(len(faces), seed), "leaf": np.arange(len(faces)) % 2},
    )
    return m.compute_normals()


def test_mesh_attributes_round_trip(tmp_path):
    m = leaf_mesh(3)
    path = write_mesh(tmp_path / "leaf.glb", m, y_up=False)
    assert_valid_glb(path)
    doc, blob = load(path)
    prim = doc.meshes[0].primitives[0]
    a = vars(prim.attributes)
    assert {"POSITION", "NORMAL", "TEXCOORD_0", "COLOR_0", "_PLANT_ID", "_LEAF_ID"} <= set(
        k for k, v in a.items() if v is not None
    )
    pos = accessor(doc, blob, a["POSITION"])
    acc = doc.accessors[a["POSITION"]]
    np.testing.assert_array_equal(acc.min, pos.min(axis=0))
    np.testing.assert_array_equal(acc.max, pos.max(axis=0))
    faces = accessor(doc, blob, prim.indices).reshape(-1, 3)
    assert faces.dtype == np.uint16
    # the "leaf" id alternates between neighbouring faces, so shared vertices were split
    assert len(pos) > m.n_vertices
    leaf = accessor(doc, blob, a["_LEAF_ID"])
    plant = accessor(doc, blob, a["_PLANT_ID"])
    assert leaf.dtype == np.uint16 and np.all(plant == 3)
    # ids constant over each face and equal to the face's id, in the original face order
    assert np.all(leaf[faces] == leaf[faces][:, :1])
    np.testing.assert_array_equal(leaf[faces[:, 0]], m.face_ids["leaf"])
    # geometry preserved: Z-up converted to Y-up (x, z, -y)
    orig = m.vertices[m.faces] @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T
    np.testing.assert_allclose(pos[faces], orig, atol=1e-6)
    np.testing.assert_allclose(
        np.linalg.norm(accessor(doc, blob, a["NORMAL"]), axis=1), 1, atol=1e-6
    )
    uv = accessor(doc, blob, a["TEXCOORD_0"])
    np.testing.assert_allclose(uv[faces], m.uv[m.faces] * [1, -1] + [0, 1], atol=1e-6)
    col = accessor(doc, blob, a["COLOR_0"])
    assert doc.accessors[a["COLOR_0"]].normalized and np.all(col == [30, 160, 40, 255])


def test_no_split_when_ids_agree_and_large_ids_as_float(tmp_path):
    m = Mesh(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],
        [[0, 1, 2], [1, 3, 2]],
        face_ids={"plant": [70000, 70000], "organ": [-1, -1]},
    )
    path = write_mesh(tmp_path / "ids.glb", m)
    assert_valid_glb(path)
    doc, blob = load(path)
    a = vars(doc.meshes[0].primitives[0].attributes)
    ids = accessor(doc, blob, a["_PLANT_ID"])
    assert ids.dtype == np.float32 and np.all(ids == 70000) and len(ids) == 4
    assert np.all(accessor(doc, blob, a["_ORGAN_ID"]) == -1)


def test_many_meshes_merge_into_one_primitive(tmp_path):
    parts = [leaf_mesh(i % 50, n=3) for i in range(3000)]
    path = write_gltf(tmp_path / "canopy.glb", parts, y_up=False, name="canopy")
    assert_valid_glb(path)
    info = read_gltf_summary(path)
    assert info["nodes"] == 1 and info["meshes"] == 1 and info["primitives"] == 1
    assert info["triangles"] == sum(p.n_faces for p in parts)
    assert "_MESH_ID" in info["attributes"]
    doc, blob = load(path)
    a = vars(doc.meshes[0].primitives[0].attributes)
    mesh_id = accessor(doc, blob, a["_MESH_ID"])
    faces = accessor(doc, blob, doc.meshes[0].primitives[0].indices).reshape(-1, 3)
    np.testing.assert_array_equal(mesh_id[faces[:, 0]], np.repeat(np.arange(3000), 4))
    # separate nodes on request
    few = write_gltf(tmp_path / "few.glb", parts[:3], merge=False)
    assert_valid_glb(few)
    assert read_gltf_summary(few)["meshes"] == 3


def test_uint32_indices_for_large_meshes(tmp_path):
    n = 260  # 67,600 vertices > 65,535
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    v = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)]
    i = (np.arange(n - 1)[:, None] + n * np.arange(n - 1)[None]).ravel()
    faces = np.concatenate([np.c_[i, i + 1, i + n], np.c_[i + 1, i + n + 1, i + n]])
    path = write_mesh(tmp_path / "big.glb", (v, faces))
    assert_valid_glb(path)
    doc, blob = load(path)
    idx = doc.accessors[doc.meshes[0].primitives[0].indices]
    assert idx.componentType == pygltflib.UNSIGNED_INT and idx.count == faces.size
    assert read_gltf_summary(path)["vertices"] == n * n


def test_trimesh_loads_what_we_write(tmp_path):
    m = leaf_mesh(1)
    scene = trimesh.load(write_mesh(tmp_path / "m.glb", m))
    geom = list(scene.geometry.values())
    assert len(geom) == 1
    tm = geom[0]
    assert len(tm.faces) == m.n_faces
    assert {"_PLANT_ID", "_LEAF_ID"} <= set(tm.vertex_attributes)
    np.testing.assert_allclose(tm.area, m.area(), rtol=1e-5)
    sk = skeleton()
    skel = trimesh.load(write_gltf(tmp_path / "s.glb", sk))
    info = read_gltf_summary(tmp_path / "s.glb")
    # the joint hierarchy survives in trimesh's scene graph: names, parents, world matrices
    world = sk.world_matrices()
    for j, name in enumerate(sk.names):
        np.testing.assert_allclose(skel.graph.get(name)[0], world[j], atol=1e-6)
        parent = skel.graph.transforms.parents[name]
        assert parent == (sk.names[sk.parent[j]] if sk.parent[j] >= 0 else "armature")
    assert sum(len(g.vertices) for g in skel.geometry.values()) == info["vertices"]
    assert sum(len(g.faces) for g in skel.geometry.values()) == info["triangles"]


def test_morph_frames_animation(tmp_path):
    base = leaf_mesh(0)
    frames = [
        base.with_(vertices=base.vertices * (0.5 + 0.25 * k)).compute_normals() for k in range(4)
    ]
    path = write_mesh_animation(tmp_path / "grow.glb", frames, frame_time=0.5, y_up=False)
    assert_valid_glb(path)
    doc, blob = load(path)
    prim = doc.meshes[0].primitives[0]
    assert len(prim.targets) == 3
    w = accessor(doc, blob, doc.animations[0].samplers[0].output).reshape(4, 3)
    np.testing.assert_array_equal(w, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    base_pos = accessor(doc, blob, prim.attributes.POSITION)
    last = base_pos + accessor(doc, blob, prim.targets[2]["POSITION"])
    # face ids survive (vertices split the same way in every frame)
    faces = accessor(doc, blob, prim.indices).reshape(-1, 3)
    leaf = accessor(doc, blob, vars(prim.attributes)["_LEAF_ID"])
    np.testing.assert_array_equal(leaf[faces[:, 0]], base.face_ids["leaf"])
    want = frames[3].vertices[frames[3].faces][..., [0, 2, 1]] * [1, 1, -1]
    np.testing.assert_allclose(last[faces], want, atol=1e-6)
    nrm = accessor(doc, blob, prim.attributes.NORMAL) + accessor(
        doc, blob, prim.targets[2]["NORMAL"]
    )
    want_n = frames[3].normals[frames[3].faces][..., [0, 2, 1]] * [1, 1, -1]
    np.testing.assert_allclose(nrm[faces], want_n, atol=1e-5)
    with pytest.raises(InputError, match="topology"):
        write_mesh_animation(tmp_path / "bad.glb", [base, leaf_mesh(0, n=5)], 0.1)


def test_embedded_json_gltf(tmp_path):
    path = write_gltf(tmp_path / "walk.gltf", motion(frames=5))
    assert path.read_bytes()[:1] == b"{"
    assert_valid_glb(path, max_warnings=0)
    glb = read_gltf_summary(write_gltf(tmp_path / "walk.glb", motion(frames=5)))
    assert read_gltf_summary(path) == glb


def test_dispatch_from_biomorph_io(tmp_path):
    assert_valid_glb(bmio.write_mesh(tmp_path / "d.glb", leaf_mesh(0)))
    assert_valid_glb(bmio.write_gltf(tmp_path / "s.glb", skeleton()))


# ----------------------------------------------------------------------------- random
def test_random_skeletons_motions_and_meshes_validate(tmp_path):
    """Random hierarchies (several roots, zero/tiny/huge offsets, random rest rotations,
    End Sites), random non-normalised motions, random meshes with ids: all valid."""
    paths = []
    for seed in range(8):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(1, 30))
        parent = [-1] + [int(rng.integers(-1, i)) for i in range(1, n)]
        off = rng.normal(size=(n, 3)) * rng.choice([0, 1, 1e-3, 100], size=(n, 1))
        end = np.where(rng.random((n, 1)) < 0.3, rng.normal(size=(n, 3)), np.nan)
        sk = JointSkeleton(
            [f"j{i}" for i in range(n)],
            parent,
            off,
            rest_rotation=tf.quat_normalize(rng.normal(size=(n, 4))),
            end_site=end,
        )
        f = int(rng.integers(1, 40))
        mo = SimpleNamespace(
            skeleton=sk,
            rotation=rng.normal(size=(f, n, 4)),
            root_position=rng.normal(size=(f, 3)),
            frame_time=float(rng.uniform(0.001, 1)),
        )
        path = write_gltf(
            tmp_path / f"sk{seed}.glb",
            mo,
            y_up=bool(seed % 2),
            bone_shape=("box", "octahedron", None)[seed % 3],
        )
        doc, blob = load(path)
        world = node_world(doc, {i: trs(nd) for i, nd in enumerate(doc.nodes)})
        ibm = accessor(doc, blob, doc.skins[0].inverseBindMatrices)
        w = np.stack([world[j] for j in doc.skins[0].joints])
        np.testing.assert_allclose(
            ibm @ w, np.broadcast_to(np.eye(4), w.shape), atol=1e-4 * max(1.0, np.abs(w).max())
        )
        paths.append(path)
    for seed in range(6):
        rng = np.random.default_rng(100 + seed)
        nv, nf = int(rng.integers(3, 200)), int(rng.integers(1, 300))
        m = Mesh(
            rng.normal(size=(nv, 3)) * 10 ** rng.uniform(-3, 3),
            rng.integers(0, nv, (nf, 3)),
            normals=rng.normal(size=(nv, 3)) * (rng.random((nv, 1)) > 0.1),
            uv=rng.random((nv, 2)),
            vertex_colors=rng.integers(0, 256, (nv, 4)),
            face_ids={"plant": rng.integers(0, 3, nf), "organ": rng.integers(-2, 10**5, nf)},
        )
        paths.append(
            write_gltf(tmp_path / f"m{seed}.glb", [m] * (1 + seed % 3), y_up=bool(seed % 2))
        )
    for path, report in zip(paths, validate_many(paths), strict=True):
        issues = report["issues"]
        assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, (path, issues)


def test_biomorph_info_reports_gltf(tmp_path, capsys):
    import json

    from biomorph.cli import run

    path = write_gltf(tmp_path / "walk.glb", motion(frames=31))
    capsys.readouterr()
    assert run(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["joints"] == 7 and info["animations"] == 1 and info["duration"] == 1.0
    assert info["faces"] == read_gltf_summary(path)["triangles"] > 0
    bare = write_gltf(tmp_path / "bare.glb", skeleton(), bone_shape=None)
    assert run(["info", str(bare), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["faces"] == 0


# ----------------------------------------------------------------------------- errors
def test_bad_input_raises_and_leaves_no_file(tmp_path):
    out = tmp_path / "x.glb"
    out.write_bytes(b"old")
    sk = skeleton()
    bad = [
        lambda: write_gltf(out, sk, bone_shape="sphere"),
        lambda: write_gltf(out, sk, bone_width=-1.0),
        lambda: write_gltf(out, None),
        lambda: write_mesh(out, (np.zeros((0, 3)), np.zeros((0, 3), int))),
        lambda: write_gltf(
            out,
            SimpleNamespace(
                skeleton=sk,
                rotation=np.full((2, 7, 4), np.nan),
                root_position=np.zeros((2, 3)),
                frame_time=0.1,
            ),
        ),
        lambda: write_gltf(
            out,
            SimpleNamespace(
                skeleton=sk,
                rotation=tf.quat_identity((2, 7)),
                root_position=np.zeros((3, 3)),
                frame_time=0.1,
            ),
        ),
        lambda: write_gltf(
            out,
            SimpleNamespace(
                skeleton=sk,
                rotation=tf.quat_identity((2, 7)),
                root_position=np.zeros((2, 3)),
                frame_time=0,
            ),
        ),
        lambda: write_gltf(out, sk, meshes={"tail": trimesh.creation.box()}),
    ]
    for call in bad:
        with pytest.raises(BiomorphError):
            call()
    with pytest.raises(ParameterError, match="bone_shape"):
        bad[0]()
    assert out.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.glb"]


def test_failed_save_leaves_no_partial_file(tmp_path, monkeypatch):
    from biomorph.io import gltf

    real = gltf._Builder.glb_parts

    def interrupted(self):
        parts = real(self)

        def gen():
            yield parts[0]  # the header reaches the disk, then Ctrl-C
            raise KeyboardInterrupt

        return gen()

    monkeypatch.setattr(gltf._Builder, "glb_parts", interrupted)
    (tmp_path / "x.glb").write_bytes(b"old")
    with pytest.raises(KeyboardInterrupt):
        write_gltf(tmp_path / "x.glb", skeleton())
    assert [p.name for p in tmp_path.iterdir()] == ["x.glb"]
    assert (tmp_path / "x.glb").read_bytes() == b"old"


def test_validator_catches_a_broken_file(tmp_path):
    """The validation helper itself can fail: a non-unit node rotation is an error."""
    import json
    import struct

    data = write_gltf(tmp_path / "ok.glb", skeleton()).read_bytes()
    (jlen,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20 : 20 + jlen])
    doc["nodes"][0]["rotation"] = [0, 0, 0.5, 0.5]
    doc["skins"][0]["joints"].append(len(doc["nodes"]) + 5)
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    rest = data[20 + jlen :]
    broken = tmp_path / "broken.glb"
    broken.write_bytes(
        struct.pack("<4sII", b"glTF", 2, 20 + len(js) + len(rest))
        + struct.pack("<I4s", len(js), b"JSON")
        + js
        + rest
    )
    report = validate_glb(broken)
    codes = {m["code"] for m in report["issues"]["messages"] if m["severity"] == 0}
    assert report["issues"]["numErrors"] >= 2 and "ROTATION_NON_UNIT" in codes
    with pytest.raises(AssertionError, match="error"):
        assert_valid_glb(broken)


def test_list_of_vertex_face_pairs(tmp_path):
    tri = ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    one = write_mesh(tmp_path / "one.glb", [np.array(tri[0]), np.array(tri[1])])
    two = write_mesh(tmp_path / "two.glb", [tri, tri])
    assert read_gltf_summary(one)["triangles"] == 1
    assert read_gltf_summary(two)["triangles"] == 2


def test_summary_rejects_garbage(tmp_path):
    junk = tmp_path / "junk.glb"
    junk.write_bytes(b"glTF\x02\x00\x00\x00garbage")
    with pytest.raises(FormatError, match="junk.glb"):
        read_gltf_summary(junk)
    with pytest.raises(FormatError, match="does not exist"):
        read_gltf_summary(tmp_path / "missing.glb")


# ----------------------------------------------------------------------------- equivalence
def decoded_arrays(path) -> dict[str, np.ndarray]:
    """Every accessor a file's meshes, skins and animations use, decoded with pygltflib and
    named by what it holds (``mesh0.POSITION``, ``skin0.ibm``, ``anim0.hips.rotation``…)."""
    doc, blob = load(path)
    out: dict[str, np.ndarray] = {}
    for i, mesh in enumerate(doc.meshes or []):
        for k, prim in enumerate(mesh.primitives):
            tag = f"mesh{i}.{k}"
            for name, idx in vars(prim.attributes).items():
                if idx is not None:
                    out[f"{tag}.{name}"] = accessor(doc, blob, idx)
            out[f"{tag}.indices"] = accessor(doc, blob, prim.indices)
            for t, target in enumerate(prim.targets or []):
                for name, idx in target.items():
                    out[f"{tag}.target{t}.{name}"] = accessor(doc, blob, idx)
    for i, skin in enumerate(doc.skins or []):
        out[f"skin{i}.ibm"] = accessor(doc, blob, skin.inverseBindMatrices)
        out[f"skin{i}.joints"] = np.array([doc.nodes[j].name for j in skin.joints])
    for i, anim in enumerate(doc.animations or []):
        for ch in anim.channels:
            s = anim.samplers[ch.sampler]
            tag = f"anim{i}.{doc.nodes[ch.target.node].name}.{ch.target.path}"
            out[f"{tag}.input"] = accessor(doc, blob, s.input)
            out[f"{tag}.output"] = accessor(doc, blob, s.output)
    for i, node in enumerate(doc.nodes):
        out[f"node{i}.{node.name}"] = np.r_[
            node.translation or [0, 0, 0], node.rotation or [0, 0, 0, 1], node.children or []
        ].astype(float)
    return out


def fingerprint(arr: np.ndarray) -> list:
    """dtype, shape and three sums (plain, absolute, position-weighted) of an array."""
    if arr.dtype.kind in "US":
        return [str(arr.dtype.kind), list(arr.shape), "|".join(arr.tolist())]
    a = np.asarray(arr, dtype=np.float64).ravel()
    w = np.arange(a.size) % 7 + 1.0
    return [
        arr.dtype.str,
        list(arr.shape),
        float(a.sum()),
        float(np.abs(a).sum()),
        float((a * w).sum()),
    ]


def equivalence_files(writer, tmp) -> dict[str, object]:
    """The inputs of ``test_same_decoded_data_as_pygltflib_writer``, written by ``writer``
    (a module with ``write_gltf``)."""
    rng = np.random.default_rng(11)
    sk = skeleton()
    box = Mesh(
        np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]),
        [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
    split = leaf_mesh(5)  # alternating ids: vertices split
    parts = [leaf_mesh(i, n=4) for i in range(20)]
    base = leaf_mesh(2)
    frames = [
        base.with_(vertices=base.vertices * (1 + 0.3 * k)).compute_normals() for k in range(3)
    ]
    big = Mesh(
        rng.normal(size=(70_000, 3)),
        rng.integers(0, 70_000, (300, 3)),
        face_ids={"organ": np.repeat(np.arange(100), 3)},
    )
    jt = SimpleNamespace(**vars(motion(9)))
    jt.joint_translation = np.broadcast_to(sk.offset, (9, 7, 3)).copy()
    jt.joint_translation[:, 2] += np.linspace(0, 0.1, 9)[:, None]
    return {
        "motion": writer.write_gltf(tmp / "a.glb", motion(12)),
        "z_up_scaled_octa": writer.write_gltf(
            tmp / "b.glb",
            sk,
            motion=jt,
            y_up=False,
            scale=0.01,
            bone_shape="octahedron",
            bone_width=rng.uniform(1, 3, 7),
        ),
        "joint_meshes": writer.write_gltf(
            tmp / "c.glb",
            sk,
            bone_shape=None,
            meshes={"head": box, 3: box.with_(vertices=box.vertices * 2).compute_normals()},
            name="creature",
        ),
        "skeleton_and_world_meshes": writer.write_gltf(tmp / "d.glb", sk, meshes=[box, split]),
        "split_ids_z_up": writer.write_gltf(tmp / "e.glb", split, y_up=False),
        "merged_list": writer.write_gltf(tmp / "f.glb", parts, y_up=False, scale=2.0),
        "separate_nodes": writer.write_gltf(tmp / "g.glb", parts[:3], merge=False),
        "frames": writer.write_gltf(tmp / "h.glb", None, frames=frames, y_up=False),
        "uint32_unreferenced": writer.write_gltf(tmp / "i.glb", big),
    }


#: fingerprints (dtype, shape, sum, sum of |x|, position-weighted sum) of every decoded
#: accessor of ``equivalence_files``, as written by the pygltflib-based writer (commit
#: b7966a5) before the dict/json.dumps rewrite; read back with pygltflib
PYGLTFLIB_REFERENCE = {
    "motion": {
        "mesh0.0.POSITION": ["<f4", [324, 3], 300.046642, 338.9960917, 1201.48049],
        "mesh0.0.NORMAL": ["<f4", [324, 3], 3.552713679e-15, 375.1993602, 14.88626705],
        "mesh0.0.JOINTS_0": ["|u1", [324, 4], 756.0, 756.0, 3040.0],
        "mesh0.0.WEIGHTS_0": ["<f4", [324, 4], 324.0, 324.0, 1294.0],
        "mesh0.0.indices": ["<u2", [324], 52326.0, 52326.0, 208980.0],
        "skin0.ibm": ["<f4", [7, 4, 4], 21.0636613, 38.79490084, 84.7213998],
        "skin0.joints": ["U", [7], "hips|spine|head|l_leg|l_foot|r_leg|r_foot"],
        "anim0.hips.rotation.input": ["<f4", [12], 2.200000066, 2.200000066, 8.566666916],
        "anim0.hips.rotation.output": ["<f4", [12, 4], 12.70259646, 12.70259646, 48.81936899],
        "anim0.spine.rotation.input": ["<f4", [12], 2.200000066, 2.200000066, 8.566666916],
        "anim0.spine.rotation.output": ["<f4", [12, 4], 14.31729408, 14.60838338, 55.38327075],
        "anim0.head.rotation.input": ["<f4", [12], 2.200000066, 2.200000066, 8.566666916],
        "anim0.head.rotation.output": ["<f4", [12, 4], 13.91692123, 13.91692123, 53.6328727],
        "anim0.l_leg.rotation.input": ["<f4", [12], 2.200000066, 2.200000066, 8.566666916],
        "anim0.l_leg.rotation.output": ["<f4", [12, 4], 16.56835475, 17.37666527, 64.19222547],
        "anim0.l_foot.rotation.input": ["<f4", [12], 2.200000066, 2.200000066, 8.566666916],
        "anim0.l_foot.rotation.output": ["<f4", [12, 4], 16.32597657, 16.32597657, 63.49225362],
        "anim0.r_leg.rotation.input": ["<f4", [12], 2.200000066, 2.200000066, 8.566666916],
        "anim0.r_leg.rotation.output": ["<f4", [12, 4], 15.20601186, 15.20601186, 58.69075286],
        "anim0.r_foot.rotation.input": ["<f4", [12], 2.200000066, 2.200000066, 8.566666916],
        "anim0.r_foot.rotation.output": ["<f4", [12, 4], 17.49225171, 17.49225171, 67.84810072],
        "anim0.hips.translation.input": ["<f4", [12], 2.200000066, 2.200000066, 8.566666916],
        "anim0.hips.translation.output": ["<f4", [12, 3], 23.99657476, 23.99657476, 99.63511109],
        "node0.hips": ["<f8", [10], 11.0, 11.0, 31.0],
        "node1.spine": ["<f8", [8], 3.344837582, 3.344837582, 10.06402966],
        "node2.head": ["<f8", [7], 1.32, 1.32, 7.66],
        "node3.l_leg": ["<f8", [8], 5.31102744, 5.41102744, 12.12478992],
        "node4.l_foot": ["<f8", [7], 0.55, 1.45, 6.1],
        "node5.r_leg": ["<f8", [8], 6.85, 7.15, 12.8],
        "node6.r_foot": ["<f8", [7], 0.55, 1.45, 6.1],
        "node7.armature": ["<f8", [8], 1.0, 1.0, 7.0],
        "node8.armature_bones": ["<f8", [7], 1.0, 1.0, 7.0],
    },
    "z_up_scaled_octa": {
        "mesh0.0.POSITION": ["<f4", [228, 3], -2.189901457, 6.021427243, -8.714348684],
        "mesh0.0.NORMAL": ["<f4", [228, 3], -1.09211284, 283.043818, -10.67111111],
        "mesh0.0.JOINTS_0": ["|u1", [228, 4], 576.0, 576.0, 2310.0],
        "mesh0.0.WEIGHTS_0": ["<f4", [228, 4], 228.0, 228.0, 910.0],
        "mesh0.0.indices": ["<u2", [228], 25878.0, 25878.0, 103060.0],
        "skin0.ibm": ["<f4", [7, 4, 4], 14.08189875, 30.84029804, 56.64004002],
        "skin0.joints": ["U", [7], "hips|spine|head|l_leg|l_foot|r_leg|r_foot"],
        "anim0.hips.rotation.input": ["<f4", [9], 1.200000037, 1.200000037, 4.500000134],
        "anim0.hips.rotation.output": ["<f4", [9, 4], 0.7507988811, 12.69833094, 2.443548381],
        "anim0.spine.rotation.input": ["<f4", [9], 1.200000037, 1.200000037, 4.500000134],
        "anim0.spine.rotation.output": ["<f4", [9, 4], 10.70938302, 10.9206787, 39.9984622],
        "anim0.head.rotation.input": ["<f4", [9], 1.200000037, 1.200000037, 4.500000134],
        "anim0.head.rotation.output": ["<f4", [9, 4], 10.39114254, 10.39114254, 38.20668692],
        "anim0.l_leg.rotation.input": ["<f4", [9], 1.200000037, 1.200000037, 4.500000134],
        "anim0.l_leg.rotation.output": ["<f4", [9, 4], 12.39093499, 12.97765533, 46.74298427],
        "anim0.l_foot.rotation.input": ["<f4", [9], 1.200000037, 1.200000037, 4.500000134],
        "anim0.l_foot.rotation.output": ["<f4", [9, 4], 12.13916133, 12.13916133, 45.83462522],
        "anim0.r_leg.rotation.input": ["<f4", [9], 1.200000037, 1.200000037, 4.500000134],
        "anim0.r_leg.rotation.output": ["<f4", [9, 4], 11.32580884, 11.32580884, 41.53033669],
        "anim0.r_foot.rotation.input": ["<f4", [9], 1.200000037, 1.200000037, 4.500000134],
        "anim0.r_foot.rotation.output": ["<f4", [9, 4], 12.98465683, 12.98465683, 48.77950898],
        "anim0.hips.translation.input": ["<f4", [9], 1.200000037, 1.200000037, 4.500000134],
        "anim0.hips.translation.output": [
            "<f4",
            [9, 3],
            4.455726594e-05,
            0.1799554406,
            -0.0433670315,
        ],
        "anim0.head.translation.input": ["<f4", [9], 1.200000037, 1.200000037, 4.500000134],
        "anim0.head.translation.output": [
            "<f4",
            [9, 3],
            0.04230000047,
            0.04230000047,
            0.1676500025,
        ],
        "node0.hips": ["<f8", [10], 8.99, 10.42421356, 24.09132034],
        "node1.spine": ["<f8", [8], 3.097337582, 3.097337582, 9.569029657],
        "node2.head": ["<f8", [7], 1.0032, 1.0032, 7.0066],
        "node3.l_leg": ["<f8", [8], 5.26152744, 5.26252744, 12.12478992],
        "node4.l_foot": ["<f8", [7], 0.9955, 1.0045, 6.991],
        "node5.r_leg": ["<f8", [8], 6.9985, 7.0015, 12.998],
        "node6.r_foot": ["<f8", [7], 0.9955, 1.0045, 6.991],
        "node7.armature": ["<f8", [8], 1.0, 1.0, 7.0],
        "node8.armature_bones": ["<f8", [7], 1.0, 1.0, 7.0],
    },
    "joint_meshes": {
        "mesh0.0.POSITION": ["<f4", [8, 3], 11.09790206, 11.60538486, 39.66730716],
        "mesh0.0.NORMAL": ["<f4", [8, 3], 2.485685244, 10.77548324, 9.394271672],
        "mesh0.0.JOINTS_0": ["|u1", [8, 4], 20.0, 20.0, 73.0],
        "mesh0.0.WEIGHTS_0": ["<f4", [8, 4], 8.0, 8.0, 29.0],
        "mesh0.0.indices": ["<u2", [24], 84.0, 84.0, 327.0],
        "skin0.ibm": ["<f4", [7, 4, 4], 21.0636613, 38.79490084, 84.7213998],
        "skin0.joints": ["U", [7], "hips|spine|head|l_leg|l_foot|r_leg|r_foot"],
        "node0.hips": ["<f8", [10], 11.0, 11.0, 31.0],
        "node1.spine": ["<f8", [8], 3.344837582, 3.344837582, 10.06402966],
        "node2.head": ["<f8", [7], 1.32, 1.32, 7.66],
        "node3.l_leg": ["<f8", [8], 5.31102744, 5.41102744, 12.12478992],
        "node4.l_foot": ["<f8", [7], 0.55, 1.45, 6.1],
        "node5.r_leg": ["<f8", [8], 6.85, 7.15, 12.8],
        "node6.r_foot": ["<f8", [7], 0.55, 1.45, 6.1],
        "node7.creature": ["<f8", [8], 1.0, 1.0, 7.0],
        "node8.creature_bones": ["<f8", [7], 1.0, 1.0, 7.0],
    },
    "skeleton_and_world_meshes": {
        "mesh0.0.POSITION": ["<f4", [324, 3], 300.046642, 338.9960917, 1201.48049],
        "mesh0.0.NORMAL": ["<f4", [324, 3], 3.552713679e-15, 375.1993602, 14.88626705],
        "mesh0.0.JOINTS_0": ["|u1", [324, 4], 756.0, 756.0, 3040.0],
        "mesh0.0.WEIGHTS_0": ["<f4", [324, 4], 324.0, 324.0, 1294.0],
        "mesh0.0.indices": ["<u2", [324], 52326.0, 52326.0, 208980.0],
        "mesh1.0.POSITION": ["<f4", [26, 3], 19.08501055, 21.2865688, 72.55939348],
        "mesh1.0._PLANT_ID": ["<f4", [26], 106.0, 114.0, 435.0],
        "mesh1.0._LEAF_ID": ["<f4", [26], 7.0, 15.0, 36.0],
        "mesh1.0._MESH_ID": ["<u2", [26], 22.0, 22.0, 89.0],
        "mesh1.0.indices": ["<u2", [42], 453.0, 453.0, 1885.0],
        "skin0.ibm": ["<f4", [7, 4, 4], 21.0636613, 38.79490084, 84.7213998],
        "skin0.joints": ["U", [7], "hips|spine|head|l_leg|l_foot|r_leg|r_foot"],
        "node0.hips": ["<f8", [10], 11.0, 11.0, 31.0],
        "node1.spine": ["<f8", [8], 3.344837582, 3.344837582, 10.06402966],
        "node2.head": ["<f8", [7], 1.32, 1.32, 7.66],
        "node3.l_leg": ["<f8", [8], 5.31102744, 5.41102744, 12.12478992],
        "node4.l_foot": ["<f8", [7], 0.55, 1.45, 6.1],
        "node5.r_leg": ["<f8", [8], 6.85, 7.15, 12.8],
        "node6.r_foot": ["<f8", [7], 0.55, 1.45, 6.1],
        "node7.armature": ["<f8", [8], 1.0, 1.0, 7.0],
        "node8.armature_bones": ["<f8", [7], 1.0, 1.0, 7.0],
        "node9.mesh": ["<f8", [7], 1.0, 1.0, 7.0],
    },
    "split_ids_z_up": {
        "mesh0.0.POSITION": ["<f4", [22, 3], 18.78391881, 20.98656879, 69.35549955],
        "mesh0.0.NORMAL": ["<f4", [22, 3], 2.232441762, 29.65016144, 10.15360773],
        "mesh0.0.TEXCOORD_0": ["<f4", [22, 2], 22.00000018, 22.00000018, 86.40000077],
        "mesh0.0.COLOR_0": ["|u1", [22, 4], 10670.0, 10670.0, 42230.0],
        "mesh0.0._PLANT_ID": ["<u2", [22], 110.0, 110.0, 425.0],
        "mesh0.0._LEAF_ID": ["<u2", [22], 11.0, 11.0, 44.0],
        "mesh0.0.indices": ["<u2", [30], 315.0, 315.0, 1203.0],
        "node0.mesh": ["<f8", [7], 1.0, 1.0, 7.0],
    },
    "merged_list": {
        "mesh0.0.POSITION": ["<f4", [280, 3], 488.7695831, 545.0725004, 2235.102041],
        "mesh0.0.NORMAL": ["<f4", [280, 3], 24.15936669, 381.6742038, 18.06637663],
        "mesh0.0.TEXCOORD_0": ["<f4", [280, 2], 280.0000024, 280.0000024, 1213.333343],
        "mesh0.0.COLOR_0": ["|u1", [280, 4], 135800.0, 135800.0, 543200.0],
        "mesh0.0._PLANT_ID": ["<u2", [280], 2660.0, 2660.0, 10640.0],
        "mesh0.0._LEAF_ID": ["<u2", [280], 140.0, 140.0, 680.0],
        "mesh0.0._MESH_ID": ["<u2", [280], 2660.0, 2660.0, 10640.0],
        "mesh0.0.indices": ["<u2", [360], 50220.0, 50220.0, 200318.0],
        "node0.mesh": ["<f8", [7], 1.0, 1.0, 7.0],
    },
    "separate_nodes": {
        "mesh0.0.POSITION": ["<f4", [14, 3], 12.21505697, 13.6304524, 54.87717342],
        "mesh0.0.NORMAL": ["<f4", [14, 3], 1.235118096, 19.07435446, 2.707840305],
        "mesh0.0.TEXCOORD_0": ["<f4", [14, 2], 14.00000012, 14.00000012, 60.66666716],
        "mesh0.0.COLOR_0": ["|u1", [14, 4], 6790.0, 6790.0, 27160.0],
        "mesh0.0._PLANT_ID": ["<u2", [14], 0.0, 0.0, 0.0],
        "mesh0.0._LEAF_ID": ["<u2", [14], 7.0, 7.0, 34.0],
        "mesh0.0.indices": ["<u2", [18], 117.0, 117.0, 448.0],
        "mesh1.0.POSITION": ["<f4", [14, 3], 12.22426536, 13.62143682, 54.89823757],
        "mesh1.0.NORMAL": ["<f4", [14, 3], 1.234677617, 19.08605359, 2.669324144],
        "mesh1.0.TEXCOORD_0": ["<f4", [14, 2], 14.00000012, 14.00000012, 60.66666716],
        "mesh1.0.COLOR_0": ["|u1", [14, 4], 6790.0, 6790.0, 27160.0],
        "mesh1.0._PLANT_ID": ["<u2", [14], 14.0, 14.0, 56.0],
        "mesh1.0._LEAF_ID": ["<u2", [14], 7.0, 7.0, 34.0],
        "mesh1.0.indices": ["<u2", [18], 117.0, 117.0, 448.0],
        "mesh2.0.POSITION": ["<f4", [14, 3], 12.22359276, 13.61257535, 54.88515036],
        "mesh2.0.NORMAL": ["<f4", [14, 3], 1.254571741, 19.09869734, 2.792165805],
        "mesh2.0.TEXCOORD_0": ["<f4", [14, 2], 14.00000012, 14.00000012, 60.66666716],
        "mesh2.0.COLOR_0": ["|u1", [14, 4], 6790.0, 6790.0, 27160.0],
        "mesh2.0._PLANT_ID": ["<u2", [14], 28.0, 28.0, 112.0],
        "mesh2.0._LEAF_ID": ["<u2", [14], 7.0, 7.0, 34.0],
        "mesh2.0.indices": ["<u2", [18], 117.0, 117.0, 448.0],
        "node0.mesh_0": ["<f8", [7], 1.0, 1.0, 7.0],
        "node1.mesh_1": ["<f8", [7], 1.0, 1.0, 7.0],
        "node2.mesh_2": ["<f8", [7], 1.0, 1.0, 7.0],
    },
    "frames": {
        "mesh0.0.POSITION": ["<f4", [22, 3], 18.79445092, 20.99018133, 69.36933311],
        "mesh0.0.NORMAL": ["<f4", [22, 3], 2.278524522, 29.63470663, 10.34356548],
        "mesh0.0.TEXCOORD_0": ["<f4", [22, 2], 22.00000018, 22.00000018, 86.40000077],
        "mesh0.0.COLOR_0": ["|u1", [22, 4], 10670.0, 10670.0, 42230.0],
        "mesh0.0._PLANT_ID": ["<u2", [22], 44.0, 44.0, 170.0],
        "mesh0.0._LEAF_ID": ["<u2", [22], 11.0, 11.0, 44.0],
        "mesh0.0.indices": ["<u2", [30], 315.0, 315.0, 1203.0],
        "mesh0.0.target0.POSITION": ["<f4", [22, 3], 5.638335242, 6.297054359, 20.81079981],
        "mesh0.0.target0.NORMAL": [
            "<f4",
            [22, 3],
            -3.923558256e-16,
            5.029956079e-15,
            -3.070797672e-15,
        ],
        "mesh0.0.target1.POSITION": ["<f4", [22, 3], 11.27667048, 12.59410872, 41.62159962],
        "mesh0.0.target1.NORMAL": [
            "<f4",
            [22, 3],
            -2.126760817e-15,
            4.459963892e-15,
            -8.855846354e-15,
        ],
        "anim0.frames.weights.input": ["<f4", [3], 0.1000000052, 0.1000000052, 0.2666666806],
        "anim0.frames.weights.output": ["<f4", [6], 2.0, 2.0, 9.0],
        "node0.frames": ["<f8", [7], 1.0, 1.0, 7.0],
    },
    "uint32_unreferenced": {
        "mesh0.0.POSITION": ["<f4", [899, 3], 47.15682676, 2128.568, 129.970509],
        "mesh0.0._ORGAN_ID": ["<u2", [899], 44531.0, 44531.0, 178797.0],
        "mesh0.0.indices": ["<u2", [900], 403974.0, 403974.0, 1635992.0],
        "node0.mesh": ["<f8", [7], 1.0, 1.0, 7.0],
    },
}


def test_same_decoded_data_as_pygltflib_writer(tmp_path):
    """The fast writer (plain-dict document, vectorised joint meshes and id handling) gives
    the same positions, indices, normals, ids, joints/weights, inverse binds, node TRS and
    animation keys as the pygltflib-based writer did, on skeletons, motion (Z-up, scaled,
    translated inner joints), joint meshes, split ids, merged lists, frames, uint32."""
    from biomorph.io import gltf

    files = equivalence_files(gltf, tmp_path)
    paths = [str(p) for p in files.values()]
    for path, report in zip(paths, validate_many(paths), strict=True):
        assert report["issues"]["numErrors"] == 0, (path, report["issues"]["messages"][:5])
    assert set(files) == set(PYGLTFLIB_REFERENCE)
    for case, path in files.items():
        got = {k: fingerprint(v) for k, v in decoded_arrays(path).items()}
        want = PYGLTFLIB_REFERENCE[case]
        assert list(got) == list(want), case
        for key, (g, w) in ((k, (got[k], want[k])) for k in want):
            assert g[:2] == w[:2], (case, key, g, w)
            if w[0] in "US":
                assert g == w, (case, key)
                continue
            tol = 1e-6 * max(w[3], 1.0)
            np.testing.assert_allclose(g[2:], w[2:], rtol=1e-7, atol=tol, err_msg=f"{case} {key}")


# ----------------------------------------------------------------------------- creature paths
def test_joint_geometry_skinned_mesh_and_extras(tmp_path):
    sk = skeleton()
    n = len(sk)
    box_v = np.array(
        [
            [-0.1, 0, -0.1],
            [0.1, 0, -0.1],
            [0.1, 0, 0.1],
            [-0.1, 0, 0.1],
            [-0.1, 0.2, -0.1],
            [0.1, 0.2, -0.1],
            [0.1, 0.2, 0.1],
            [-0.1, 0.2, 0.1],
        ]
    )
    box_f = np.array(
        [
            [0, 1, 2],
            [0, 2, 3],
            [4, 6, 5],
            [4, 7, 6],
            [0, 4, 5],
            [0, 5, 1],
            [1, 5, 6],
            [1, 6, 2],
            [2, 6, 7],
            [2, 7, 3],
            [3, 7, 4],
            [3, 4, 0],
        ]
    )
    verts = np.concatenate([box_v] * n)
    faces = np.concatenate([box_f + 8 * j for j in range(n)])
    jnt = np.repeat(np.arange(n), 8)
    nrm = verts / np.linalg.norm(verts + 1e-9, axis=1, keepdims=True)
    world = sk.world_matrices()
    skin_v = world[:, :3, 3] + 0.01
    k = len(skin_v)
    sv = np.concatenate([skin_v, skin_v + [0, 0.05, 0], skin_v + [0.05, 0, 0]])
    sf = np.stack([np.arange(k), np.arange(k) + k, np.arange(k) + 2 * k], axis=1)
    sj = np.tile([0, 1, 2, 3], (3 * k, 1))
    sw = np.tile([2.0, 1.0, 1.0, 0.0], (3 * k, 1))
    extras = [{"rigify_type": "basic.super_copy"} if j == 1 else None for j in range(n)]
    p = write_gltf(
        tmp_path / "c.glb",
        sk,
        bone_shape=None,
        name="c",
        joint_geometry=(verts, nrm, jnt, faces),
        skinned_mesh=(sv, np.tile([0, 0, 1.0], (3 * k, 1)), sj, sw, sf),
        joint_extras=extras,
        extras={"biomorph_metarig": 1},
    )
    assert_valid_glb(p)
    doc, blob = load(p)
    assert [m.name for m in doc.meshes] == ["c_bones", "c_skin_mesh"]
    w = accessor(doc, blob, doc.meshes[1].primitives[0].attributes.WEIGHTS_0)
    assert np.allclose(w.sum(axis=1), 1.0, atol=1e-6) and np.allclose(w[0], [0.5, 0.25, 0.25, 0])
    # bone geometry moved from joint frames into bind space
    pos = accessor(doc, blob, doc.meshes[0].primitives[0].attributes.POSITION)
    assert np.allclose(pos[8:16], box_v @ world[1, :3, :3].T + world[1, :3, 3], atol=1e-6)
    assert doc.nodes[1].extras == {"rigify_type": "basic.super_copy"}
    assert next(nd for nd in doc.nodes if nd.name == "c").extras == {"biomorph_metarig": 1}
    with pytest.raises(ParameterError, match="joint_geometry"):
        write_gltf(tmp_path / "x.glb", sk, joint_geometry=(verts, nrm, jnt[:-1], faces))
    with pytest.raises(ParameterError, match="joint index"):
        write_gltf(tmp_path / "x.glb", sk, joint_geometry=(verts, nrm, jnt + n, faces))
    with pytest.raises(ParameterError, match="weights sum to 0"):
        write_gltf(tmp_path / "x.glb", sk, skinned_mesh=(sv, sv, sj, sw * 0, sf))
    with pytest.raises(ParameterError, match="joint_extras"):
        write_gltf(tmp_path / "x.glb", sk, joint_extras=[{}])
    assert not (tmp_path / "x.glb").exists()
