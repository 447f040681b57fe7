"""MuJoCo MJCF (.xml) for a generated creature, and a settle test in MuJoCo.

Bodies nest like the joint hierarchy (``pos``/``quat`` = rest offset and rotation, MuJoCo's
``w x y z`` order); each body has a box geom of the bone and an ``inertial`` with the bone's
mass, centre and box inertia. Non-root bodies get three hinge joints about their local x, y, z
with ``range`` = the joint limits (radians, ``angle="radian"``, limited); the root gets a free
joint. ``rigid=True`` omits the hinges (a rigid statue), which is what :func:`settle` uses to
test static stability: drop it on a plane, simulate, and see whether it tips over.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from biomorph.core.types import PathLike
from biomorph.errors import InputError
from biomorph.io.atomic import write_text


def _vec(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in np.ravel(v))


#: MuJoCo's default contact (solref timeconst 0.02 s, solimp width 1 mm, timestep 1 ms) is
#: tuned for models about a metre tall (its humanoid). The steady sinking of a soft contact
#: under gravity is ≈ (1 − d)/d · g · timeconst² (d the impedance), independent of mass, so a
#: 7-cm creature would sink by most of its 0.3-mm foot pads and fall through. Below
#: ``CONTACT_REF_SIZE`` the contact is scaled by Froude similarity — time as
#: √(size / ref), lengths (solimp width, margin) as size / ref — so a creature sinks by the
#: same share of its size at any scale; MuJoCo keeps ``timeconst`` ≥ 2 timesteps, so the
#: timestep shrinks with it (to ``timeconst / 4``).
CONTACT_REF_SIZE = 1.0
CONTACT_TIMECONST = 0.02
CONTACT_WIDTH = 0.001
TIMESTEP = 0.001


def contact_scale(creature) -> dict[str, float]:
    """Contact parameters for ``creature`` (size = the larger of its height and length, m):
    ``timeconst`` (s), ``width`` (solimp transition width, m) and ``timestep`` (s)."""
    size = max(float(creature.height), float(creature.length), 1e-4)
    k = min(1.0, size / CONTACT_REF_SIZE)
    tc = CONTACT_TIMECONST * np.sqrt(k)
    return {
        "timeconst": float(tc),
        "width": float(CONTACT_WIDTH * k),
        "timestep": float(min(TIMESTEP, tc / 4)),
    }


def creature_to_mjcf(
    creature,
    name: str = "creature",
    rigid: bool = False,
    drop: float = 0.0,
    support_spheres: bool = False,
) -> str:
    """MJCF XML text; ``drop`` lifts the creature (m) above the floor.

    ``support_spheres`` (with ``rigid``) makes only small spheres at the corners of the
    support polygon collide, the contact model of :mod:`biomorph.creature.balance`.
    """
    sk = creature.skeleton
    n = len(sk)
    if n == 0:
        raise InputError("creature has no joints")
    inertia = creature.inertia()
    root = ET.Element("mujoco", model=name)
    ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    cs = contact_scale(creature)
    ET.SubElement(root, "option", timestep=f"{cs['timestep']:.9g}", gravity="0 -9.81 0")
    default = ET.SubElement(root, "default")
    ET.SubElement(
        default,
        "geom",
        friction="1.0 0.01 0.001",
        condim="3",
        solref=f"{cs['timeconst']:.9g} 1",
        solimp=f"0.9 0.95 {cs['width']:.9g}",
    )
    world = ET.SubElement(root, "worldbody")
    size = max(creature.length, creature.height, 0.1) * 4
    ET.SubElement(
        world,
        "geom",
        name="floor",
        type="plane",
        size=f"{size} {size} 0.1",
        zaxis="0 1 0",
        pos="0 0 0",
    )
    elems: dict[int, ET.Element] = {}
    for i in range(n):
        p = sk.parent[i]
        q = sk.rest_rotation[i]
        parent_el = world if p < 0 else elems[p]
        pos = sk.offset[i] + (np.array([0.0, drop, 0.0]) if p < 0 else 0.0)
        b = ET.SubElement(
            parent_el, "body", name=sk.names[i], pos=_vec(pos), quat=_vec([q[3], q[0], q[1], q[2]])
        )
        elems[i] = b
        w = creature.world[i]
        com_local = w[:3, :3].T @ (creature.mass_center[i] - w[:3, 3])
        I = np.maximum(inertia[i], 1e-10)
        ET.SubElement(
            b,
            "inertial",
            pos=_vec(com_local),
            mass=f"{max(float(creature.mass[i]), 1e-6):.9g}",
            diaginertia=_vec(I),
        )
        if p < 0:
            ET.SubElement(b, "freejoint", name=f"{sk.names[i]}_free")
        elif not rigid:
            for k, ax in enumerate(("1 0 0", "0 1 0", "0 0 1")):
                lo, hi = sk.limits[i, k]
                ET.SubElement(
                    b,
                    "joint",
                    name=f"{sk.names[i]}_r{'xyz'[k]}",
                    type="hinge",
                    axis=ax,
                    range=_vec([lo, hi]),
                    damping="1",
                )
        L = float(creature.bone_length[i])
        if L > 1e-9:
            half = np.maximum(creature.box_size[i] / 2, 1e-5)
            col = "0" if support_spheres else "1"
            ET.SubElement(
                b,
                "geom",
                type="box",
                size=_vec(half),
                pos=_vec([0, L / 2, 0]),
                mass="0",
                contype=col,
                conaffinity=col,
            )
        if p < 0 and support_spheres and creature.balance is not None:
            r = 0.004 * max(creature.height, 0.01)
            for x, z in creature.balance.support:
                local = w[:3, :3].T @ (np.array([x, r, z]) - w[:3, 3])
                ET.SubElement(b, "geom", type="sphere", size=f"{r:.9g}", pos=_vec(local), mass="0")
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode")


def write_mjcf(path: PathLike, creature, name: str | None = None, rigid: bool = False) -> Path:
    """Write a creature as MuJoCo MJCF (atomically)."""
    return write_text(path, creature_to_mjcf(creature, name or Path(path).stem, rigid))


def settle(creature, seconds: float = 2.0, max_tilt_deg: float = 20.0) -> dict:
    """Drop the rigid creature 1 mm onto a plane in MuJoCo, simulate ``seconds`` and report
    whether it stayed upright (root tilt below ``max_tilt_deg``).

    The creature is a rigid statue standing on small spheres at the corners of its support
    polygon (the foot pads of the balance model); bones do not collide. A creature whose
    centre of mass lies outside the polygon tips over."""
    import mujoco

    if creature.balance is None or not creature.balance.support:
        return {
            "upright": True,
            "tilt_deg": 0.0,
            "root_height_m": float(creature.skeleton.offset[0, 1]),
            "seconds": 0.0,
            "note": "no ground contact",
        }
    xml = creature_to_mjcf(
        creature, rigid=True, drop=0.001 * max(creature.height, 0.01), support_spheres=True
    )
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    q0 = data.qpos[3:7].copy()
    steps = int(round(seconds / model.opt.timestep))
    for _ in range(steps):
        mujoco.mj_step(model, data)
    q1 = data.qpos[3:7]
    dot = abs(float(np.dot(q0, q1)) / (np.linalg.norm(q0) * np.linalg.norm(q1)))
    tilt = float(np.degrees(2 * np.arccos(np.minimum(dot, 1.0))))
    return {
        "upright": bool(tilt <= max_tilt_deg),
        "tilt_deg": tilt,
        "root_height_m": float(data.qpos[1]),
        "seconds": seconds,
    }
