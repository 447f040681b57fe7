"""Point clouds as NumPy ``.npy`` arrays.

Reading accepts a plain numeric array ``(n, 3+)`` — columns 0..2 are x y z (metres), extra
columns become attributes ``column_<k>`` — or a structured array with fields ``x y z`` plus
any other numeric fields (kept under their names). Pickled object arrays are refused.

Writing produces a plain ``float64[n, 3]`` array when the cloud has no attributes and a
structured array (``x y z`` float64 + each attribute with its dtype) otherwise, so the file
round-trips exactly.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from biomorph.core.pointcloud import PointCloud
from biomorph.core.types import PathLike
from biomorph.errors import FormatError, InputError
from biomorph.io.atomic import atomic_path


def read_points(path: PathLike) -> PointCloud:
    """Read an ``.npy`` point array (plain ``(n, 3+)`` numbers or structured ``x y z ...``)."""
    p = Path(path)
    if p.stat().st_size == 0:
        raise FormatError(path, "file is empty; expected a .npy array")
    try:
        arr = np.load(p, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - numpy's header parser raises many types
        msg = str(exc).strip().splitlines()[0][:160] if str(exc).strip() else type(exc).__name__
        raise FormatError(path, f"not a readable .npy array ({msg})") from None
    if not isinstance(arr, np.ndarray):
        raise FormatError(path, "holds several arrays (.npz); expected one (n, 3) array")
    attrs: dict[str, np.ndarray] = {}
    if arr.dtype.names:
        names = arr.dtype.names
        missing = [c for c in "xyz" if c not in names]
        if missing or arr.ndim != 1:
            raise FormatError(
                path,
                f"structured array with fields {', '.join(names)} and shape "
                f"{arr.shape}; expected 1-D with fields x, y, z",
            )
        try:
            xyz = np.stack([arr[c].astype(np.float64) for c in "xyz"], axis=1)
        except (TypeError, ValueError) as exc:
            raise FormatError(path, f"fields x/y/z are not numbers ({exc})") from None
        for name in names:
            if name not in "xyz" and arr[name].dtype.kind in "biuf" and arr[name].ndim == 1:
                attrs[name] = np.array(arr[name])
    else:
        if arr.dtype.kind not in "biuf":
            raise FormatError(path, f"array dtype {arr.dtype} is not numeric; expected floats")
        if arr.ndim != 2 or arr.shape[1] < 3:
            raise FormatError(path, f"array has shape {arr.shape}; expected (n, 3) or wider")
        xyz = arr[:, :3].astype(np.float64)
        for k in range(3, arr.shape[1]):
            attrs[f"column_{k}"] = np.array(arr[:, k])
    if xyz.shape[0] == 0:
        raise FormatError(path, "array holds no points; expected at least one row")
    bad = ~np.isfinite(xyz).all(axis=1)
    if bad.any():
        raise FormatError(
            path,
            f"row {int(np.flatnonzero(bad)[0])} has a NaN or inf "
            "coordinate; expected finite numbers",
        )
    return PointCloud(
        np.ascontiguousarray(xyz), attrs, meta={"format": "npy"}, source=os.fspath(path)
    )


def write_points(path: PathLike, cloud: PointCloud) -> Path:
    """Write ``cloud.world_xyz`` (and attributes, as a structured array) to ``.npy``."""
    if not isinstance(cloud, PointCloud):
        cloud = PointCloud(np.asarray(cloud, dtype=float))
    xyz = cloud.world_xyz
    if not np.isfinite(xyz).all():
        raise InputError(f"{os.fspath(path)}: cloud has NaN or inf coordinates; cannot write")
    if not cloud.attributes:
        out: Any = np.ascontiguousarray(xyz)
    else:
        fields: list[Any] = [("x", np.float64), ("y", np.float64), ("z", np.float64)]
        for k, v in cloud.attributes.items():
            a = np.asarray(v)
            if a.dtype.kind not in "biuf":
                raise InputError(
                    f"{os.fspath(path)}: attribute {k!r} has dtype {a.dtype}; expected numbers"
                )
            fields.append((str(k), a.dtype, a.shape[1:]) if a.ndim > 1 else (str(k), a.dtype))
        out = np.empty(xyz.shape[0], dtype=fields)
        for i, c in enumerate("xyz"):
            out[c] = xyz[:, i]
        for k, v in cloud.attributes.items():
            out[str(k)] = v
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, out, allow_pickle=False)
    return Path(path)


__all__ = ["read_points", "write_points"]
