"""LAS / LAZ point clouds via laspy (LAZ through the lazrs backend).

Reading gives float64 world coordinates (``scale * X + offset``) in ``PointCloud.xyz`` with a
zero ``PointCloud.offset``. Every other dimension of the point record — standard ones such as
``intensity``, ``return_number``, ``classification``, ``red``/``green``/``blue``,
``gps_time`` and extra-bytes dimensions such as ``Deviation`` — becomes an attribute under
its laspy name. ``PointCloud.meta`` keeps ``las_version``, ``point_format``, ``scales``,
``offsets``, the names of the extra dimensions and the header's VLRs, so writing the cloud
back reproduces the record layout and the integer grid of the coordinates.

Writing uses the kept layout when present, else the smallest standard point format that
holds the standard-named attributes (0, 1 for ``gps_time``, 2 for colour, 3 for both); other
numeric attributes become extra-bytes dimensions of their own dtype. Default scale is
0.1 mm; default offsets are the floor of the minimum coordinates, so any cloud up to about
200 km across fits the int32 grid. Output is compressed when the extension is ``.laz``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import FormatError, InputError
from biomorph.io.atomic import atomic_path

PathLike = str | os.PathLike[str]

_COORD_DIMS = {"X", "Y", "Z", "x", "y", "z"}


def read_points(path: PathLike) -> PointCloud:
    """Read a LAS/LAZ file into a :class:`PointCloud` (all dimensions kept as attributes)."""
    import laspy

    p = Path(path)
    if p.stat().st_size == 0:
        raise FormatError(path, "file is empty; expected a LAS/LAZ header")
    try:
        las = laspy.read(p)
        header = las.header
        pf = las.point_format
        xyz = np.stack([np.asarray(las.x, dtype=np.float64), np.asarray(las.y, dtype=np.float64),
                        np.asarray(las.z, dtype=np.float64)], axis=1)
        attrs: dict[str, NDArray] = {}
        for name in pf.dimension_names:
            if name in _COORD_DIMS:
                continue
            attrs[name] = np.array(las[name])
        extra = list(pf.extra_dimension_names)
        meta = {
            "format": "laz" if p.suffix.lower() == ".laz" else "las",
            "las_version": str(header.version),
            "point_format": int(pf.id),
            "scales": np.asarray(header.scales, dtype=np.float64).copy(),
            "offsets": np.asarray(header.offsets, dtype=np.float64).copy(),
            "extra_dimensions": extra,
            "vlrs": [v for v in header.vlrs if type(v).__name__ != "ExtraBytesVlr"],
            "point_count_header": int(header.point_count),
        }
    except FormatError:
        raise
    except (laspy.errors.LaspyException, ValueError, OSError, EOFError, KeyError, IndexError,
            TypeError, AttributeError, RuntimeError, OverflowError, MemoryError,
            UnicodeDecodeError) as exc:
        raise FormatError(path, f"not a readable LAS/LAZ file ({_short(exc)})") from None
    except Exception as exc:  # lazrs raises its own (pyo3) exception types
        raise FormatError(path, f"not a readable LAS/LAZ file ({_short(exc)})") from None
    if xyz.shape[0] == 0:
        raise FormatError(path, "holds no points; expected at least one")
    if not np.isfinite(xyz).all():
        row = int(np.flatnonzero(~np.isfinite(xyz).all(axis=1))[0])
        raise FormatError(path, f"point {row} has a NaN or inf coordinate (bad scale/offset "
                                "in the header); expected finite numbers")
    return PointCloud(xyz, attrs, meta=meta, source=os.fspath(path))


def _short(exc: BaseException) -> str:
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return msg[:160]


def _standard_format_for(names: set[str]) -> int:
    has_time = "gps_time" in names
    has_rgb = bool({"red", "green", "blue"} & names)
    if has_time and has_rgb:
        return 3
    if has_rgb:
        return 2
    if has_time:
        return 1
    return 0


def write_points(path: PathLike, cloud: PointCloud, scale: float | None = None,
                 point_format: int | None = None, version: str | None = None) -> Path:
    """Write ``cloud`` as LAS or LAZ (by extension), keeping every attribute.

    ``scale`` (metres per integer step) overrides the kept/ default 0.0001; ``point_format``
    and ``version`` override the kept layout. Coordinates written are ``cloud.world_xyz``.
    """
    import laspy

    if not isinstance(cloud, PointCloud):
        cloud = PointCloud(np.asarray(cloud, dtype=float))
    xyz = cloud.world_xyz
    if xyz.shape[0] and not np.isfinite(xyz).all():
        raise InputError(f"{os.fspath(path)}: cloud has NaN or inf coordinates; cannot write")
    meta = cloud.meta or {}
    attrs = {k: np.asarray(v) for k, v in cloud.attributes.items()}
    for k, v in attrs.items():
        if v.ndim != 1 or not (np.issubdtype(v.dtype, np.number) or v.dtype == bool):
            raise InputError(f"{os.fspath(path)}: attribute {k!r} of dtype {v.dtype} and shape "
                             f"{v.shape} cannot be a LAS dimension; expected 1-D numbers")
    fmt_id = point_format if point_format is not None else meta.get("point_format")
    if fmt_id is None:
        fmt_id = _standard_format_for(set(attrs))
    ver = version or meta.get("las_version") or ("1.4" if int(fmt_id) > 5 else "1.2")
    try:
        header = laspy.LasHeader(point_format=int(fmt_id), version=str(ver))
    except laspy.errors.LaspyException as exc:
        raise InputError(f"{os.fspath(path)}: LAS point format {fmt_id} / version {ver} "
                         f"not writable ({_short(exc)})") from None
    standard = set(header.point_format.dimension_names)
    kept_scales = meta.get("scales")
    kept_offsets = meta.get("offsets")
    if scale is not None:
        scales = np.full(3, float(scale))
    elif kept_scales is not None:
        scales = np.asarray(kept_scales, dtype=np.float64).reshape(3)
    else:
        scales = np.full(3, 1e-4)
    lo = xyz.min(axis=0) if xyz.shape[0] else np.zeros(3)
    hi = xyz.max(axis=0) if xyz.shape[0] else np.zeros(3)
    if kept_offsets is not None:
        offsets = np.asarray(kept_offsets, dtype=np.float64).reshape(3)
    else:
        offsets = np.floor(lo)
    limit = 2**31 - 1
    if np.any(np.abs((lo - offsets) / scales) > limit) or \
            np.any(np.abs((hi - offsets) / scales) > limit):
        offsets = np.floor(lo)  # kept offsets do not fit the moved cloud: re-anchor
        if np.any((hi - offsets) / scales > limit):
            raise InputError(f"{os.fspath(path)}: extent {np.max(hi - lo):.1f} m does not fit "
                             f"LAS int32 coordinates at scale {scales.min()}; pass a larger "
                             "scale")
    header.scales = scales
    header.offsets = offsets
    for name, arr in attrs.items():
        if name in standard or name in _COORD_DIMS:
            continue
        dtype = arr.dtype if arr.dtype != bool else np.dtype(np.uint8)
        if dtype.kind not in "iuf":
            raise InputError(f"{os.fspath(path)}: attribute {name!r} has dtype {dtype}; "
                             "expected integers or floats")
        header.add_extra_dim(laspy.ExtraBytesParams(name=name, type=dtype))
    for vlr in meta.get("vlrs", []) or []:
        try:
            header.vlrs.append(vlr)
        except Exception:  # pragma: no cover - a foreign VLR object; skip, coordinates matter
            pass
    las = laspy.LasData(header)
    las.x = xyz[:, 0]
    las.y = xyz[:, 1]
    las.z = xyz[:, 2]
    for name, arr in attrs.items():
        if name in _COORD_DIMS:
            continue
        try:
            las[name] = arr.astype(np.uint8) if arr.dtype == bool else arr
        except (ValueError, OverflowError, TypeError) as exc:
            raise InputError(f"{os.fspath(path)}: attribute {name!r} does not fit its LAS "
                             f"dimension ({_short(exc)})") from None
    compress = Path(path).suffix.lower() == ".laz"
    with atomic_path(path) as tmp:
        las.write(tmp, do_compress=compress)
    return Path(path)


__all__ = ["read_points", "write_points"]
