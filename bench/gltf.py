"""GLB writer throughput: creature skeletons, many small meshes, a 100,000-leaf canopy.

Usage: .venv/bin/python bench/gltf.py [--repeat 7] [--baseline OLD_gltf.py]
       .venv/bin/python bench/gltf.py --creatures 1000 [--workers 2] [--no-skin]
       .venv/bin/python bench/gltf.py --blender 20
       .venv/bin/python bench/gltf.py --render demo-out/blender

``--creatures N``: N seeds generated and written as GLB with procedural bone models and the
skinned body envelope (``biomorph creature generate --skin``), on ``--workers`` processes;
prints the total wall time, per-creature stage medians and, for the first 20 seeds, the peer
(trimesh's own GLB export of the same bone and skin meshes, unskinned) beside ours as a
ratio. ``--blender N``: N seeds exported plain and ``--rigify`` and imported into Debian's
Blender headless; counts import warnings and Rigify generate failures.

Cases (each written to a temporary ``.glb`` with ``biomorph.io.gltf.write_gltf``):

* ``creature``: ``biomorph.creature.generate(seed=0)`` exported as ``biomorph creature
  export`` does (joint meshes in joint frames, skinned, ``bone_shape=None``) — the per-file
  cost of ``biomorph creature batch --format glb``;
* ``creature + anim``: the same with a 60-frame animation (random unit pose quaternions);
* ``skeleton 80 boxes``: a synthetic 80-joint ``JointSkeleton`` with the default box bones;
* ``1,000 meshes``: a list of 1,000 small meshes (12 vertices, 10 triangles, a face id),
  merged into one primitive;
* ``100k leaves``: a maize field of ~100,000 leaves (``biomorph.leaf.canopy.field_mesh``,
  19 triangles per leaf, normals, uv, ``plant``/``leaf`` face ids), Z-up.

Times are medians of ``--repeat`` runs, CPU (``time.process_time``) and wall; peak memory is
the tracemalloc peak of one extra traced run. With ``--baseline PATH`` (a copy of an older
``io/gltf.py``, e.g. ``git show REV:src/biomorph/io/gltf.py > /tmp/old.py``) both versions
run on the same inputs and the table shows before → after.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from types import ModuleType, SimpleNamespace

import numpy as np


def measure(fn: Callable[[], object], repeat: int) -> tuple[float, float, float]:
    """(median CPU s, median wall s, peak MB of one traced call)."""
    cpu, wall = [], []
    fn()  # warm-up (imports, caches)
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return float(np.median(cpu)), float(np.median(wall)), peak / 1e6


def load_module(path: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location("gltf_baseline", path)
    mod = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(mod)
    return mod


def synthetic_skeleton(n: int = 80, seed: int = 0):
    from biomorph.core import transforms as tf
    from biomorph.core.skeleton import JointSkeleton

    rng = np.random.default_rng(seed)
    parent = np.array([-1] + [int(rng.integers(0, i)) for i in range(1, n)])
    offset = rng.normal(0, 0.1, (n, 3))
    offset[0] = [0, 1, 0]
    rest = tf.quat_normalize(rng.normal(size=(n, 4)))
    end = np.full((n, 3), np.nan)
    leaves = np.setdiff1d(np.arange(n), parent)
    end[leaves[::2]] = [0, 0.05, 0]
    return JointSkeleton(
        [f"j{i}" for i in range(n)], parent, offset, rest_rotation=rest, end_site=end
    )


def random_motion(skeleton, frames: int = 60, seed: int = 1) -> SimpleNamespace:
    rng = np.random.default_rng(seed)
    rot = rng.normal(size=(frames, len(skeleton), 4))
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    root = np.c_[np.linspace(0, 2, frames), np.ones(frames), np.zeros(frames)]
    return SimpleNamespace(skeleton=skeleton, rotation=rot, root_position=root, frame_time=1 / 30)


def small_meshes(count: int = 1000, seed: int = 2) -> list:
    from biomorph.core.mesh import Mesh

    rng = np.random.default_rng(seed)
    cols = 6
    s = np.linspace(0, 1, cols)
    grid = np.stack(
        [np.r_[s, s], np.r_[np.zeros(cols), np.ones(cols) * 0.2], np.zeros(2 * cols)], axis=1
    )
    a = np.arange(cols - 1)
    faces = np.concatenate(
        [np.stack([a, a + 1, a + cols], 1), np.stack([a + 1, a + cols + 1, a + cols], 1)]
    )
    out = []
    for i in range(count):
        v = grid * rng.uniform(0.05, 0.2) + rng.uniform(-1, 1, 3)
        out.append(Mesh(v, faces, face_ids={"plant": np.full(len(faces), i // 10)}))
    return out


def leaf_field(leaves: int = 100_000):
    from biomorph.leaf.canopy import FieldSpec, build_field, field_mesh

    fld = build_field(FieldSpec(plants=max(leaves // 6, 1), rows=100), seed=0)
    return field_mesh(fld, triangles_per_leaf=19, stems=False)


def cases() -> list[tuple[str, Callable[[ModuleType, str], object]]]:
    import biomorph.creature as creature_mod
    from biomorph.creature.mesh import joint_meshes

    cr = creature_mod.generate(seed=0)
    jm = joint_meshes(cr, "box")
    motion = random_motion(cr.skeleton)
    sk80 = synthetic_skeleton()
    meshes = small_meshes()
    field = leaf_field()
    return [
        (
            f"creature ({len(cr.skeleton)} joints, joint meshes)",
            lambda m, p: m.write_gltf(p, cr.skeleton, bone_shape=None, meshes=jm, name="creature"),
        ),
        (
            "creature + 60-frame animation",
            lambda m, p: m.write_gltf(
                p, cr.skeleton, motion=motion, bone_shape=None, meshes=jm, name="creature"
            ),
        ),
        ("skeleton 80 joints, box bones", lambda m, p: m.write_gltf(p, sk80)),
        ("1,000 small meshes merged", lambda m, p: m.write_gltf(p, meshes)),
        (
            f"{field.n_faces // 19:,} leaves ({field.n_faces / 1e6:.2f} M tris, 1 mesh)",
            lambda m, p: m.write_gltf(p, field, y_up=False),
        ),
    ]


def _one_creature(args: tuple[int, str, bool]) -> tuple[float, float, int]:
    """(wall s, CPU s, file bytes) for one seed: generate + ``write_glb`` (bone models,
    skin)."""
    seed, out, skin = args
    import biomorph.creature as bc
    from biomorph.creature.exporters import write_glb

    t0, c0 = time.perf_counter(), time.process_time()
    path = write_glb(bc.generate(seed=seed), os.path.join(out, f"c{seed}.glb"), skin=skin)
    return time.perf_counter() - t0, time.process_time() - c0, os.path.getsize(path)


_START = """
import os, tempfile, time
c0 = time.process_time()
import biomorph.creature as bc
from biomorph.creature.exporters import write_glb
with tempfile.TemporaryDirectory() as tmp:
    write_glb(bc.generate(seed=0), os.path.join(tmp, "w.glb"), skin=True)
print(time.process_time() - c0)
"""


def _worker_start() -> float:
    """CPU s a fresh process spends on imports, kernel-cache loads and its first creature
    (what each pool worker pays once)."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _START], capture_output=True, text=True)
    return float(out.stdout.split()[-1])


def _warm() -> None:
    """Pool initializer: imports and compiled kernels loaded before the timed jobs."""
    import biomorph.creature as bc
    from biomorph.creature.exporters import write_glb

    with tempfile.TemporaryDirectory() as tmp:
        write_glb(bc.generate(seed=0), os.path.join(tmp, "w.glb"), skin=True)


def _peer_trimesh(seed: int, out: str, skin: bool) -> tuple[float, ...]:
    """(ours s, trimesh s, generate s, bone models s, skin s). Ours and trimesh write the
    same finished meshes: ours the skinned GLB (``write_gltf`` with ``joint_geometry`` and
    ``skinned_mesh``), trimesh its scene export of the world-space bone (and skin) meshes
    (no armature, no skin)."""
    import trimesh

    import biomorph.creature as bc
    from biomorph.creature.bones import geometry, world_mesh
    from biomorph.creature.skin import body
    from biomorph.io.gltf import write_gltf

    s0 = time.process_time()
    c = bc.generate(seed=seed)
    t1 = time.process_time()
    geo = geometry(c)
    t2 = time.process_time()
    b = body(c) if skin else None
    t3 = time.process_time()
    w = world_mesh(c)
    meshes = [trimesh.Trimesh(w.vertices, w.faces, vertex_normals=w.normals, process=False)]
    skinned = None
    if b is not None:
        e = b.envelope
        skinned = (e.vertices, e.normals, b.joints, b.weights, e.faces)
        meshes.append(trimesh.Trimesh(e.vertices, e.faces, vertex_normals=e.normals, process=False))
    t0 = time.process_time()
    trimesh.Scene(meshes).export(os.path.join(out, "peer.glb"))
    t_peer = time.process_time() - t0
    t0 = time.process_time()
    write_gltf(
        os.path.join(out, "ours.glb"),
        c.skeleton,
        bone_shape=None,
        joint_geometry=geo,
        skinned_mesh=skinned,
    )
    return time.process_time() - t0, t_peer, t1 - s0, t2 - t1, t3 - t2


def creatures_bench(n: int, workers: int, skin: bool) -> None:
    from multiprocessing import get_context

    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        jobs = [(s, tmp, skin) for s in range(n)]
        w0 = time.perf_counter()
        with get_context("spawn").Pool(workers, initializer=_warm) as pool:
            res = pool.map(_one_creature, jobs, chunksize=max(1, n // (workers * 8)))
        wall = time.perf_counter() - w0
        r = np.array(res, float)
        peer = np.array([_peer_trimesh(s, tmp, skin) for s in range(min(20, n))])
    load1 = os.getloadavg()[0]
    start = [_worker_start() for _ in range(workers)]
    cpu = float(r[:, 1].sum())
    print(f"load average {load0:.2f} -> {load1:.2f}, {os.cpu_count()} CPUs, {workers} workers\n")
    print(
        f"{n} creatures with bone models{' and skin' if skin else ''} written as GLB: "
        f"{wall:.1f} s wall ({wall / n * 1e3:.0f} ms per creature; target 1,000 in 60 s)"
    )
    print(
        f"CPU {cpu:.1f} s in the workers ({cpu / n * 1e3:.0f} ms per creature, median "
        f"{np.median(r[:, 1]) * 1e3:.0f} ms) + {sum(start):.1f} s worker start-up: on "
        f"{workers} otherwise idle cores {(cpu + sum(start)) / workers:.1f} s, 1,000 "
        f"creatures {(cpu / n * 1000 + sum(start)) / workers:.1f} s"
    )
    print(
        f"median {np.median(r[:, 0]) * 1e3:.0f} ms wall per creature on one worker, file "
        f"{np.median(r[:, 2]) / 1e6:.2f} MB"
    )
    print(f"\n| stage (median of {len(peer)} seeds, one process) | ms CPU |\n|---|---:|")
    for k, label in (
        (2, "generate"),
        (3, "bone models"),
        (4, "muscles + envelope + weights"),
        (0, "skinned GLB write (finished meshes)"),
    ):
        print(f"| {label} | {np.median(peer[:, k]) * 1e3:.1f} |")
    ratio = peer[:, 0] / peer[:, 1]
    print(
        f"\nwriting the finished meshes, {len(peer)} seeds: ours (skinned GLB with armature) "
        f"median {np.median(peer[:, 0]) * 1e3:.1f} ms, trimesh (plain GLB scene) "
        f"{np.median(peer[:, 1]) * 1e3:.1f} ms, ours / trimesh {np.median(ratio):.2f}"
    )


def blender_bench(n: int) -> None:
    import json
    import shutil
    import subprocess

    import biomorph.creature as bc
    from biomorph.creature.exporters import export
    from biomorph.creature.rigify_setup import SCRIPT

    blender = shutil.which("blender")
    if blender is None:
        print("blender not installed (apt-get install -y blender python3-numpy)")
        return
    import sys

    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from tests.creature.test_blender import DRIVER

    with tempfile.TemporaryDirectory() as tmp:
        jobs = []
        for s in range(n):
            c = bc.generate(seed=s)
            for rig in (False, True):
                p = os.path.join(tmp, f"c{s}_{int(rig)}.glb")
                export(c, p, rigify=rig, skin=True)
                jobs.append({"path": p, "rigify": rig, "result": os.path.join(tmp, "r.json")})
        with open(os.path.join(tmp, "jobs.json"), "w") as fh:
            json.dump(jobs, fh)
        for name, text in (("driver.py", DRIVER), ("setup.py", SCRIPT)):
            with open(os.path.join(tmp, name), "w") as fh:
                fh.write(text)
        t0 = time.perf_counter()
        proc = subprocess.run(
            [
                blender,
                "-b",
                "--factory-startup",
                "--python",
                os.path.join(tmp, "driver.py"),
                "--",
                os.path.join(tmp, "jobs.json"),
                os.path.join(tmp, "setup.py"),
            ],
            capture_output=True,
            text=True,
        )
        wall = time.perf_counter() - t0
        with open(os.path.join(tmp, "r.json")) as fh:
            res = json.load(fh)
    chunks = proc.stdout.split("BIOMORPH_IMPORT_START")[1:]
    warn = sum(
        sum(
            1
            for ln in ch.split("BIOMORPH_IMPORT_END")[0].splitlines()
            if "WARNING" in ln or "ERROR" in ln
        )
        for ch in chunks
    )
    rigs = [r for r in res if r["path"].endswith("_1.glb")]
    ok = sum(1 for r in rigs if r["error"] is None and r["generated"])
    print(
        f"Blender {n} seeds (plain + --rigify, bone models + skin): {len(chunks)} imports, "
        f"{warn} warnings; Rigify generate succeeded on {ok}/{len(rigs)}; {wall:.0f} s"
    )
    for r in rigs:
        if r["error"]:
            print("  ", os.path.basename(r["path"]), r["error"][:200])


RENDER = r"""
import math, sys, warnings
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import numpy
    if "bool" not in numpy.__dict__:
        numpy.bool = bool
import addon_utils, bpy
from mathutils import Vector
glb, out = sys.argv[sys.argv.index("--") + 1:][:2]
bpy.ops.wm.read_factory_settings(use_empty=True)
addon_utils.enable("io_scene_gltf2", default_set=True)
bpy.ops.import_scene.gltf(filepath=glb)
meshes = [o for o in bpy.data.objects if o.type == "MESH"]
pts = [o.matrix_world @ Vector(c) for o in meshes for c in o.bound_box]
lo = Vector([min(p[i] for p in pts) for i in range(3)])
hi = Vector([max(p[i] for p in pts) for i in range(3)])
mid, size = (lo + hi) / 2, max(hi - lo)
for o in meshes:  # the envelope translucent over the bones
    if "skin" in o.name.lower() or "envelope" in o.name.lower():
        o.display.show_shadows = False
        o.color = (0.85, 0.6, 0.5, 0.35)
scene = bpy.context.scene
scene.render.engine = "BLENDER_WORKBENCH"
scene.display.shading.light = "STUDIO"
scene.display.shading.color_type = "OBJECT"
scene.display.shading.show_xray = False
scene.render.resolution_x, scene.render.resolution_y = 900, 600
cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
scene.collection.objects.link(cam)
scene.camera = cam
cam.data.type = "ORTHO"
cam.data.ortho_scale = 1.25 * size
for name, az, el in (("side", 0.0, 0.0), ("three_quarter", 35.0, 20.0)):
    # the creature faces -Y, its right side on -X: the side view looks from -X
    a, e = math.radians(az), math.radians(el)
    d = Vector((-math.cos(a) * math.cos(e), -math.sin(a) * math.cos(e), math.sin(e)))
    cam.location = mid + d * 3 * size
    cam.rotation_euler = (-d).to_track_quat("-Z", "Y").to_euler()
    scene.render.filepath = f"{out}_{name}.png"
    bpy.ops.render.render(write_still=True)
"""


def blender_render(out_dir: str) -> None:
    """The demo set exported with bone models (and one with skin) and rendered in Debian's
    Blender (Workbench, orthographic) from the side and three-quarter views."""
    import shutil
    import subprocess

    import biomorph.creature as bc
    from biomorph.creature.demo import DEMO_SET
    from biomorph.creature.exporters import export

    blender = shutil.which("blender")
    if blender is None:
        print("blender not installed (apt-get install -y blender python3-numpy)")
        return
    os.makedirs(out_dir, exist_ok=True)
    script = os.path.join(out_dir, "render.py")
    with open(script, "w") as fh:
        fh.write(RENDER)
    for title, opts in DEMO_SET:
        for skin in (False, True):
            stem = os.path.join(out_dir, f"{title}{'_skin' if skin else ''}")
            export(bc.generate(**opts), stem + ".glb", skin=skin)
            subprocess.run(
                [blender, "-b", "--factory-startup", "--python", script, "--", stem + ".glb", stem],
                capture_output=True,
                check=True,
            )
            print("wrote", stem + "_side.png", stem + "_three_quarter.png")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--baseline", help="path of an older io/gltf.py to compare against")
    ap.add_argument("--creatures", type=int, help="N creatures with bone models + skin")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-skin", action="store_true")
    ap.add_argument("--blender", type=int, help="N seeds through Blender + Rigify")
    ap.add_argument("--render", metavar="DIR", help="render the demo set in Blender into DIR")
    args = ap.parse_args()
    if args.render:
        return blender_render(args.render)
    if args.creatures:
        return creatures_bench(args.creatures, args.workers, not args.no_skin)
    if args.blender:
        return blender_bench(args.blender)
    import biomorph.io.gltf as current

    versions = [("after", current)]
    if args.baseline:
        versions.insert(0, ("before", load_module(args.baseline)))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "out.glb")
        for label, fn in cases():
            res = {}
            for vname, mod in versions:
                big = "leaves" in label
                res[vname] = measure(
                    lambda fn=fn, mod=mod: fn(mod, path),
                    max(1, args.repeat // 3) if big else args.repeat,
                )
                res[vname] += (os.path.getsize(path) / 1e6,)
            rows.append((label, res))
    print(f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs, repeat {args.repeat}\n")
    if args.baseline:
        print(
            "| case | CPU before | CPU after | speed-up | wall before | wall after | "
            "peak MB before | peak MB after | file MB |"
        )
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for label, r in rows:
            b, a = r["before"], r["after"]
            print(
                f"| {label} | {fmt(b[0])} | {fmt(a[0])} | {b[0] / max(a[0], 1e-9):.1f}× | "
                f"{fmt(b[1])} | {fmt(a[1])} | {b[2]:.1f} | {a[2]:.1f} | {a[3]:.2f} |"
            )
    else:
        print("| case | CPU | wall | peak MB | file MB |")
        print("|---|---:|---:|---:|---:|")
        for label, r in rows:
            a = r["after"]
            print(f"| {label} | {fmt(a[0])} | {fmt(a[1])} | {a[2]:.1f} | {a[3]:.2f} |")


def fmt(seconds: float) -> str:
    return f"{seconds * 1e3:.1f} ms" if seconds < 1 else f"{seconds:.2f} s"


if __name__ == "__main__":
    main()
