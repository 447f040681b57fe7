"""OpenSim model (.osim, format version 40000) for a generated creature.

One ``Body`` per bone with its mass, centre of mass (body frame) and inertia (solid box of the
bone's soft-tissue volume, ``Ixx Iyy Izz Ixy Ixz Iyz`` in kg m²), a box display geometry;
one ``CustomJoint`` per bone connecting it to its parent body, with three rotational
coordinates ``<joint>_rx/_ry/_rz`` about the joint's local axes whose ``range`` is the joint
limit in **radians** (clamped), and a ``FreeJoint`` from ground to the root. Each body's
frame is the joint's rest frame; parent offset frames carry the rest translation and the
rest orientation as body-fixed XYZ Euler angles (radians), as OpenSim expects.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from biomorph.core.types import PathLike
from biomorph.errors import FormatError, InputError
from biomorph.io.atomic import write_text


def _vec(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in np.ravel(v))


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrib: str) -> ET.Element:
    e = ET.SubElement(parent, tag, attrib)
    if text is not None:
        e.text = text
    return e


def _frame(parent: ET.Element, name: str, socket: str, translation, orientation) -> None:
    f = _sub(parent, "PhysicalOffsetFrame", name=name)
    _sub(f, "socket_parent", socket)
    _sub(f, "translation", _vec(translation))
    _sub(f, "orientation", _vec(orientation))


def _axis(st: ET.Element, name: str, coord: str | None, axis) -> None:
    ta = _sub(st, "TransformAxis", name=name)
    _sub(ta, "coordinates", coord or "")
    _sub(ta, "axis", _vec(axis))
    fn = _sub(ta, "function")
    if coord:
        lf = _sub(fn, "LinearFunction")
        _sub(lf, "coefficients", "1 0")
    else:
        c = _sub(fn, "Constant")
        _sub(c, "value", "0")


def creature_to_osim(creature, name: str = "creature") -> str:
    """OpenSim XML text for a :class:`~biomorph.creature.creature.Creature`."""
    sk = creature.skeleton
    n = len(sk)
    if n == 0:
        raise InputError("creature has no joints")
    inertia = creature.inertia()
    doc = ET.Element("OpenSimDocument", Version="40000")
    model = _sub(doc, "Model", name=name)
    _sub(model, "gravity", "0 -9.8066 0")
    _sub(model, "length_units", "meters")
    _sub(model, "force_units", "N")
    _sub(model, "credits", "biomorph procedural creature")
    _sub(model, "Ground", name="ground")
    bodies = _sub(_sub(model, "BodySet", name="bodyset"), "objects")
    joints = _sub(_sub(model, "JointSet", name="jointset"), "objects")
    names = sk.names
    for i in range(n):
        b = _sub(bodies, "Body", name=names[i])
        m = max(float(creature.mass[i]), 1e-6)
        _sub(b, "mass", f"{m:.9g}")
        # centre of the bone's mass in the body (= joint) frame
        world = creature.world[i]
        com_local = world[:3, :3].T @ (creature.mass_center[i] - world[:3, 3])
        _sub(b, "mass_center", _vec(com_local))
        I = np.maximum(inertia[i], 1e-12)
        _sub(b, "inertia", _vec([I[0], I[1], I[2], 0.0, 0.0, 0.0]))
        geo = _sub(b, "attached_geometry")
        brick = _sub(geo, "Brick", name=f"{names[i]}_geom")
        _sub(brick, "socket_frame", "..")
        _sub(brick, "half_lengths", _vec(np.maximum(creature.box_size[i] / 2, 1e-6)))
        p = sk.parent[i]
        jname = f"{names[i]}_joint"
        euler = Rotation.from_quat(sk.rest_rotation[i]).as_euler("XYZ")
        if p < 0:
            j = _sub(joints, "FreeJoint", name=jname)
            _sub(j, "socket_parent_frame", "ground_offset")
            _sub(j, "socket_child_frame", f"{names[i]}_offset")
            frames = _sub(j, "frames")
            _frame(frames, "ground_offset", "/ground", sk.offset[i], euler)
            _frame(frames, f"{names[i]}_offset", f"/bodyset/{names[i]}", [0, 0, 0], [0, 0, 0])
            continue
        j = _sub(joints, "CustomJoint", name=jname)
        _sub(j, "socket_parent_frame", f"{names[p]}_offset_{i}")
        _sub(j, "socket_child_frame", f"{names[i]}_offset")
        coords = _sub(j, "coordinates")
        cnames = []
        for k, ax in enumerate("xyz"):
            cn = f"{names[i]}_r{ax}"
            cnames.append(cn)
            c = _sub(coords, "Coordinate", name=cn)
            _sub(c, "motion_type", "rotational")
            _sub(c, "default_value", "0")
            lo, hi = sk.limits[i, k]
            _sub(c, "range", _vec([lo, hi]))
            _sub(c, "clamped", "true")
            _sub(c, "locked", "false")
        frames = _sub(j, "frames")
        _frame(frames, f"{names[p]}_offset_{i}", f"/bodyset/{names[p]}", sk.offset[i], euler)
        _frame(frames, f"{names[i]}_offset", f"/bodyset/{names[i]}", [0, 0, 0], [0, 0, 0])
        st = _sub(j, "SpatialTransform")
        for k, ax in enumerate(((1, 0, 0), (0, 1, 0), (0, 0, 1))):
            _axis(st, f"rotation{k + 1}", cnames[k], ax)
        for k, ax in enumerate(((1, 0, 0), (0, 1, 0), (0, 0, 1))):
            _axis(st, f"translation{k + 1}", None, ax)
    ET.indent(doc, space="  ")
    return '<?xml version="1.0" encoding="UTF-8" ?>\n' + ET.tostring(doc, encoding="unicode")


def write_osim(path: PathLike, creature, name: str | None = None) -> Path:
    """Write a creature as an OpenSim ``.osim`` model (atomically)."""
    return write_text(path, creature_to_osim(creature, name or Path(path).stem))


def read_osim_summary(path: PathLike) -> dict:
    """Bodies (mass, inertia) and coordinate ranges of an ``.osim`` file, for tests/info."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise FormatError(path, f"not a readable OpenSim XML file ({exc})") from None

    def numbers(el: ET.Element, tag: str) -> list[float]:
        text = el.findtext(tag)
        try:
            return [float(x) for x in (text or "").split()] or [float("nan")]
        except ValueError:
            raise FormatError(
                path, f"<{tag}> of {el.get('name')!r} holds {text!r}; expected numbers"
            ) from None

    bodies = {
        b.get("name"): {"mass": numbers(b, "mass")[0], "inertia": numbers(b, "inertia")}
        for b in root.iter("Body")
    }
    coords = {c.get("name"): numbers(c, "range") for c in root.iter("Coordinate")}
    return {
        "bodies": bodies,
        "coordinates": coords,
        "joints": len(list(root.iter("CustomJoint"))) + len(list(root.iter("FreeJoint"))),
    }
