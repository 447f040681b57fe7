"""Array helpers shared by the glTF writers: unit rows, float32 checks, Z-up to Y-up, id
attributes, joint nodes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.errors import InputError

#: rotation taking Z-up data into glTF's Y-up frame: (x, y, z) -> (x, z, -y)
_Z_TO_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_Z_TO_Y_QUAT = np.array([-np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])


def _unit_rows(v: NDArray, fallback: NDArray | None = None) -> NDArray:
    """Rows of ``v`` scaled to unit length; zero rows take ``fallback`` (default +y)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    out = np.divide(v, n, out=np.zeros_like(v), where=n > 1e-12)
    bad = n[..., 0] <= 1e-12
    if bad.any():
        out[bad] = np.array([0.0, 1.0, 0.0]) if fallback is None else fallback[bad]
    return out


def _float32(name: str, arr: ArrayLike) -> NDArray[np.float32]:
    a = np.asarray(arr, dtype=np.float64)
    if a.size:  # min and max propagate NaN and show inf: two passes, no temporaries
        lo, hi = float(a.min()), float(a.max())
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise InputError(f"{name} holds NaN or inf; expected finite values")
        if max(-lo, hi) > 3.0e38:
            raise InputError(f"{name} exceeds the float32 range; expected |value| < 3e38")
    return a.astype(np.float32)


def _y_up(v: ArrayLike, y_up: bool, scale: float = 1.0) -> NDArray[np.float64]:
    """``(n, 3)`` rows times ``scale``, turned from Z-up to Y-up unless ``y_up``:
    ``(x, y, z) -> (x, z, -y)`` by moving columns (exact, no matrix product)."""
    a = np.asarray(v, dtype=np.float64)
    if scale != 1.0:
        a = a * scale
    if y_up:
        return a
    out = np.empty_like(a)
    out[:, 0] = a[:, 0]
    out[:, 1] = a[:, 2]
    np.negative(a[:, 1], out=out[:, 2])
    return out


def _id_attribute_name(key: str) -> str:
    base = "".join(ch if ch.isalnum() else "_" for ch in str(key)).upper().strip("_") or "FACE"
    if not base.endswith("_ID") and base != "ID":
        base += "_ID"
    return "_" + base


def _id_array(name: str, ids: NDArray[np.int64]) -> NDArray:
    """Per-vertex ids as unsigned short (0..65535) or float32 (exact up to 2**24)."""
    if ids.size == 0 or (ids.min() >= 0 and ids.max() <= 65535):
        return ids.astype(np.uint16)
    if np.abs(ids).max() > 2**24:
        raise InputError(
            f"face id {name!r} holds {int(np.abs(ids).max())}; glTF custom "
            "attributes store ids exactly only up to 16777216"
        )
    return ids.astype(np.float32)


def _joint_nodes(
    names: Sequence[str], translation: NDArray, rotation: NDArray
) -> list[dict[str, Any]]:
    """One node per joint with its local TRS; zero translations and identity rotations
    (``|xyz| <= 1e-8``, ``w > 0``) are left out."""
    has_t = np.any(translation != 0, axis=1).tolist()
    has_r = (~(np.all(np.abs(rotation[:, :3]) <= 1e-8, axis=1) & (rotation[:, 3] > 0))).tolist()
    t_list, r_list = translation.tolist(), rotation.tolist()
    nodes = []
    for i, nm in enumerate(names):
        node: dict[str, Any] = {"name": nm}
        if has_t[i]:
            node["translation"] = t_list[i]
        if has_r[i]:
            node["rotation"] = r_list[i]
        nodes.append(node)
    return nodes
