"""Mass model: Henderson-style slices along the spine plus cylinders around limb bones.

The body is a chain of elliptical slices along the spine curve (height ``h(s)``, width
``b(s)``, centred a little below the spine, which runs along the back), a skull ellipsoid and
one cylinder per limb bone. Its volume in frame units fixes the creature's size: with density
``ρ`` the metres-per-px scale is ``s = (w / (ρ · V_px))^(1/3)``, so the body weighs exactly the
sampled weight ``w`` (the seed's px ÷ 1000 × a body-size scale from the weight). Every slice's
and cylinder's mass goes to the bone it belongs to.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

DENSITY = {"bird": 750.0}  # kg/m³; others 1000 (water)
#: Soft-tissue radius of a limb segment relative to its length, per limb type.
LIMB_RADIUS = {"leg": 0.13, "arm": 0.11, "wing": 0.05, "fin": 0.06}
#: Bone box thickness relative to the soft-tissue size.
BONE_FRACTION = 0.35


def density(cls: str) -> float:
    return DENSITY.get(cls, 1000.0)


_PROFILES: dict[tuple, tuple] = {}


def profile(
    s: NDArray, region_len: NDArray, girth: float, cls: str, skull_h: float, legless: bool
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray]:
    """Body height ``h``, width ``b`` and centre offset below the spine at arc lengths ``s``
    (frame px, from the head end). Profiles along a whole sampled spine are memoised
    (read-only arrays): limbs, balance repair and assembly ask for the same one."""
    s = np.asarray(s, float)
    if s.ndim != 1 or len(s) < 16:
        return _profile(s, region_len, girth, cls, skull_h, legless)
    key = (
        s.tobytes(),
        np.asarray(region_len, float).tobytes(),
        float(girth),
        cls,
        float(skull_h),
        bool(legless),
    )
    hit = _PROFILES.get(key)
    if hit is None:
        hit = _profile(s, region_len, girth, cls, skull_h, legless)
        for a in hit:
            a.setflags(write=False)
        if len(_PROFILES) > 128:
            _PROFILES.clear()
        _PROFILES[key] = hit
    return hit


def _profile(
    s: NDArray, region_len: NDArray, girth: float, cls: str, skull_h: float, legless: bool
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray]:
    neck, back, tail = region_len
    total = max(neck + back + tail, 1e-9)
    h_back = girth * (back if back > 0.15 * total else total)
    h_back = max(h_back, 0.01 * total)
    s = np.asarray(s, float)
    # clip(x, 0, 1) as maximum / minimum (np.clip's wrapper cost more than the arithmetic
    # on the few positions the limbs ask for; the only difference, a -0.0 for +0.0, is
    # added to or multiplied into the same values below)
    u_neck = np.minimum(np.maximum(s / max(neck, 1e-9), 0.0), 1.0)
    u_back = np.minimum(np.maximum((s - neck) / max(back, 1e-9), 0.0), 1.0)
    u_tail = np.minimum(np.maximum((s - neck - back) / max(tail, 1e-9), 0.0), 1.0)
    head_h = max(0.8 * skull_h, 0.2 * h_back)
    fishy = cls == "fish" or legless
    # continuous at the joins (the back ends at 0.75 h_back at both girdles)
    tail0, tail1 = (0.75, 0.25) if fishy else (0.75, 0.06)
    h = np.where(
        s < neck,
        head_h + (0.75 * h_back - head_h) * u_neck,
        np.where(
            s <= neck + back,
            h_back * (0.75 + 0.25 * np.sin(np.pi * u_back)),
            h_back * (tail0 + (tail1 - tail0) * u_tail),
        ),
    )
    b = h * (0.5 if cls == "fish" else 0.8)
    off = h * (0.12 if fishy else 0.35)
    return h, b, off


def slice_volumes(s: NDArray, h: NDArray, b: NDArray) -> NDArray[np.float64]:
    """Volume of each slice between consecutive samples (midpoint rule), ``(m-1,)``."""
    ds = np.diff(s)
    hm = 0.5 * (h[1:] + h[:-1])
    bm = 0.5 * (b[1:] + b[:-1])
    return np.pi / 4.0 * hm * bm * ds


def ellipsoid_volume(size: NDArray) -> float:
    """Volume of the ellipsoid inscribed in a box ``(3,)``."""
    return float(np.pi / 6.0 * np.prod(size))


def limb_volume(lengths: NDArray, kind: str) -> NDArray[np.float64]:
    """Cylinder volumes of the three segments of one limb."""
    L = np.asarray(lengths, float)
    r = LIMB_RADIUS[kind] * L
    return np.pi * r * r * L


def size_scale(weight: float, volume_px: float, cls: str) -> float:
    """Metres per frame px so the body volume × density equals ``weight`` (kg)."""
    return float((weight / (density(cls) * max(volume_px, 1e-30))) ** (1.0 / 3.0))


def box_inertia(mass: NDArray, size: NDArray) -> NDArray[np.float64]:
    """Principal moments ``(n, 3)`` (kg m²) of solid boxes of ``size (n, 3)`` about their
    centres, in the box axes."""
    s2 = np.asarray(size, float) ** 2
    m = np.asarray(mass, float)[:, None]
    return (
        m / 12.0 * np.stack([s2[:, 1] + s2[:, 2], s2[:, 0] + s2[:, 2], s2[:, 0] + s2[:, 1]], axis=1)
    )
