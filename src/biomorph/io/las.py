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


def check_header(path: PathLike) -> dict[str, int]:
    """Validate the LAS public header block against the file size before laspy reads it.

    A corrupted count (VLRs, EVLRs, points) would otherwise make a reader loop or allocate
    for a very long time. Returns the raw fields read."""
    import struct

    p = Path(path)
    size = p.stat().st_size
    if size == 0:
        raise FormatError(path, "file is empty; expected a LAS/LAZ header")
    with open(p, "rb") as fh:
        head = fh.read(375)
    if len(head) < 227 or head[:4] != b"LASF":
        raise FormatError(path, "not a LAS/LAZ file: expected the 'LASF' signature and a "
                                "227-byte or longer header")
    major, minor = head[24], head[25]
    header_size, = struct.unpack_from("<H", head, 94)
    offset_points, n_vlrs = struct.unpack_from("<II", head, 96)
    fmt_id, record_len, legacy_count = struct.unpack_from("<BHI", head, 104)
    if major != 1 or minor > 4:
        raise FormatError(path, f"LAS version {major}.{minor}; expected 1.0 to 1.4")
    if header_size < 227 or header_size > size or offset_points < header_size or \
            offset_points > size:
        raise FormatError(path, f"header size {header_size} / point data offset {offset_points} "
                                f"do not fit the file of {size} bytes; truncated or corrupt")
    if n_vlrs * 54 > offset_points - header_size:
        raise FormatError(path, f"header announces {n_vlrs} VLRs but only "
                                f"{offset_points - header_size} bytes precede the points; "
                                "corrupt header")
    count = legacy_count
    if minor >= 4 and len(head) >= 255:
        start_evlr, n_evlr = struct.unpack_from("<QI", head, 235)
        count = struct.unpack_from("<Q", head, 247)[0] or legacy_count
        if n_evlr and (start_evlr > size or n_evlr * 60 > size - start_evlr):
            raise FormatError(path, f"header announces {n_evlr} extended VLRs that do not fit "
                                    "the file; corrupt header")
    compressed = bool(fmt_id & 0x80) or bool(fmt_id & 0x40)
    if not compressed and count * record_len > size - offset_points:
        raise FormatError(path, f"header announces {count} points of {record_len} bytes but "
                                f"the file holds {size - offset_points} bytes of point data; "
                                "truncated")
    if compressed and count > 0 and size - offset_points < 8:
        raise FormatError(path, "compressed point data is missing; truncated")
    return {"point_count": int(count), "record_length": int(record_len),
            "point_format": int(fmt_id & 0x3F)}


def read_points(path: PathLike) -> PointCloud:
    """Read a LAS/LAZ file into a :class:`PointCloud` (all dimensions kept as attributes)."""
    import laspy

    p = Path(path)
    check_header(p)
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


def read_head(path: PathLike, max_points: int = 1_000_000) -> tuple[PointCloud, dict]:
    """The first ``max_points`` points and the header summary (point count, header bbox,
    layout) without reading the whole file — for ``biomorph info`` on very large scans."""
    import laspy

    p = Path(path)
    check_header(p)
    try:
        with laspy.open(p) as reader:
            header = reader.header
            pts = reader.read_points(int(max_points))
            xyz = np.stack([np.asarray(pts.x, np.float64), np.asarray(pts.y, np.float64),
                            np.asarray(pts.z, np.float64)], axis=1)
            attrs = {name: np.array(pts[name]) for name in pts.point_format.dimension_names
                     if name not in _COORD_DIMS}
            summary = {
                "point_count": int(header.point_count),
                "bbox_min": np.asarray(header.mins, dtype=np.float64).copy(),
                "bbox_max": np.asarray(header.maxs, dtype=np.float64).copy(),
                "las_version": str(header.version),
                "point_format": int(header.point_format.id),
                "scales": np.asarray(header.scales, dtype=np.float64).copy(),
                "offsets": np.asarray(header.offsets, dtype=np.float64).copy(),
                "extra_dimensions": list(header.point_format.extra_dimension_names),
            }
    except FormatError:
        raise
    except Exception as exc:  # noqa: BLE001 - laspy/lazrs raise many types
        raise FormatError(path, f"not a readable LAS/LAZ file ({_short(exc)})") from None
    if xyz.shape[0] == 0:
        raise FormatError(path, "holds no points; expected at least one")
    if not np.isfinite(xyz).all():
        raise FormatError(path, "a point has a NaN or inf coordinate; expected finite numbers")
    return PointCloud(xyz, attrs, meta=summary, source=os.fspath(path)), summary


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


__all__ = ["read_points", "write_points", "read_head", "check_header"]
