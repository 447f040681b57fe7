"""Inkscape SVG annotations of a side-view skeleton, read the seed's way (§6.6.1).

The image sits in a 1000×1000 frame. Each annotated element is a ``<path>`` named by its
``inkscape:label`` or ``id``: the spine as three cubic Béziers ``neck``, ``back``, ``tail``
(each ``M`` + one ``C``, absolute or relative commands; the back is required, a missing neck
or tail repeats the back's first/last point, as in the seed) and the limb segments
``upper_arm``, ``lower_arm``, ``hand``, ``upper_leg``, ``lower_leg``, ``foot`` as straight
lines (``M`` + ``L``/``H``/``V``/``l``/``h``/``v``; the length is the polyline length). SVG's
origin is the top-left corner with y down; coordinates are flipped to the seed's y-up frame
``y' = H − y`` with ``H`` the frame height (viewBox height, else ``height``, else 1000).
``translate(...)`` transforms on the path or its groups are applied; other transforms are
rejected (the seed: layers must not be moved).

The dataset row built from these annotations (species columns, class checks) lives with the
creature pillar: :func:`biomorph.creature.dataset.annotations.species_row`.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from biomorph.core.types import PathLike
from biomorph.errors import FormatError

SPINE = ("neck", "back", "tail")
LIMBS = ("upper_arm", "lower_arm", "hand", "upper_leg", "lower_leg", "foot")
_INK = "{http://www.inkscape.org/namespaces/inkscape}label"
_TOKEN = re.compile(r"[MmCcLlHhVvZzSsQqTtAa]|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _tokens(d: str) -> list[str]:
    return _TOKEN.findall(d.replace(",", " "))


def parse_path(d: str, path: PathLike, name: str) -> list[tuple[str, np.ndarray]]:
    """Absolute segments of an SVG path: ``[("M", p), ("C", (3,2)), ("L", p) …]`` (y down)."""
    toks = _tokens(d)
    if not toks or toks[0] not in "Mm":
        raise FormatError(path, f"path {name!r} must start with a moveto (M/m); got {d[:20]!r}")
    out: list[tuple[str, np.ndarray]] = []
    cur = np.zeros(2)
    start = np.zeros(2)
    i, cmd = 0, ""

    def num() -> float:
        nonlocal i
        if i >= len(toks) or toks[i].isalpha():
            raise FormatError(path, f"path {name!r}: command {cmd!r} is missing numbers")
        v = float(toks[i])
        i += 1
        return v

    while i < len(toks):
        if toks[i].isalpha():
            cmd = toks[i]
            i += 1
        elif not cmd:
            raise FormatError(path, f"path {name!r}: number before any command")
        rel = cmd.islower()
        c = cmd.upper()
        if c == "M":
            p = np.array([num(), num()]) + (cur if rel else 0)
            out.append(("M", p))
            cur = start = p
            cmd = "l" if rel else "L"  # further pairs are implicit linetos
        elif c == "L":
            p = np.array([num(), num()]) + (cur if rel else 0)
            out.append(("L", p))
            cur = p
        elif c == "H":
            p = np.array([num() + (cur[0] if rel else 0), cur[1]])
            out.append(("L", p))
            cur = p
        elif c == "V":
            p = np.array([cur[0], num() + (cur[1] if rel else 0)])
            out.append(("L", p))
            cur = p
        elif c == "C":
            pts = np.array([[num(), num()] for _ in range(3)]) + (cur if rel else 0)
            out.append(("C", pts))
            cur = pts[-1]
        elif c == "Z":
            out.append(("L", start.copy()))
            cur = start
        else:
            raise FormatError(
                path,
                f"path {name!r}: SVG command {cmd!r} is not supported; "
                "use straight lines and cubic Béziers (M, L, H, V, C)",
            )
    return out


def _translate(elem_chain: list[ET.Element], path: PathLike, name: str) -> np.ndarray:
    off = np.zeros(2)
    for e in elem_chain:
        t = (e.get("transform") or "").strip()
        if not t:
            continue
        m = re.fullmatch(r"translate\(\s*([-+.\deE]+)(?:[\s,]+([-+.\deE]+))?\s*\)", t)
        if not m:
            raise FormatError(
                path,
                f"path {name!r} (or a group around it) has transform "
                f"{t!r}; only translate() is supported — do not move, "
                "scale or rotate annotation layers",
            )
        off += [float(m.group(1)), float(m.group(2) or 0.0)]
    return off


def read_annotations(path: PathLike) -> dict[str, object]:
    """Spine control points ``(10, 2)`` and limb lengths ``(6,)`` (px, y up) from an SVG."""
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, "SVG file does not exist")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as exc:
        raise FormatError(p, f"not well-formed SVG/XML ({exc})") from None
    if not root.tag.endswith("svg"):
        raise FormatError(p, f"root element is <{root.tag}>; expected <svg>")
    vb = (root.get("viewBox") or "").replace(",", " ").split()
    try:
        height = (
            float(vb[3])
            if len(vb) == 4
            else float(re.sub(r"[a-z]+$", "", root.get("height", "1000")))
        )
    except ValueError:
        raise FormatError(p, "cannot read the frame height (viewBox/height)") from None
    parents = {c: par for par in root.iter() for c in par}
    found: dict[str, tuple[list, np.ndarray]] = {}
    for el in root.iter():
        if not el.tag.endswith("path"):
            continue
        label = (el.get(_INK) or el.get("id") or "").strip().lower()
        if label not in SPINE + LIMBS:
            continue
        if label in found:
            raise FormatError(p, f"path {label!r} occurs twice; label each element once")
        chain, e = [], el
        while e is not None:
            chain.append(e)
            e = parents.get(e)
        segs = parse_path(el.get("d") or "", p, label)
        found[label] = (segs, _translate(chain, p, label))
    if "back" not in found:
        labels = sorted(found) or ["none"]
        raise FormatError(
            p,
            f"no path labelled 'back' (found: {', '.join(labels)}); label the "
            "spine paths neck, back and tail",
        )

    def flip(q: np.ndarray, off: np.ndarray) -> np.ndarray:
        q = np.asarray(q, float) + off
        return np.stack([q[..., 0], height - q[..., 1]], axis=-1)

    curves = {}
    for name in SPINE:
        if name not in found:
            continue
        segs, off = found[name]
        kinds = [k for k, _ in segs]
        if kinds != ["M", "C"]:
            raise FormatError(
                p,
                f"path {name!r} must be one cubic Bézier (M then C); got commands {''.join(kinds)}",
            )
        curves[name] = flip(np.concatenate([segs[0][1][None], segs[1][1]]), off)
    back = curves["back"]
    neck = curves.get("neck", np.repeat(back[:1], 4, axis=0))
    tail = curves.get("tail", np.repeat(back[-1:], 4, axis=0))
    points = np.concatenate([neck[:3], back, tail[1:]])
    lengths = np.zeros(6)
    for k, name in enumerate(LIMBS):
        if name not in found:
            continue
        segs, off = found[name]
        if any(kind == "C" for kind, _ in segs):
            raise FormatError(p, f"limb path {name!r} must be straight (M + L), not a curve")
        pts = np.array([q for _, q in segs])
        if len(pts) < 2:
            raise FormatError(p, f"limb path {name!r} has a single point; draw a line")
        lengths[k] = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    return {"points": points, "lengths": lengths, "height": height, "found": sorted(found)}
