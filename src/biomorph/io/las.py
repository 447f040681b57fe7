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

import contextlib
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.pointcloud import PointCloud
from biomorph.core.types import PathLike
from biomorph.errors import FormatError, InputError
from biomorph.io.atomic import atomic_path

_COORD_DIMS = {"X", "Y", "Z", "x", "y", "z"}


#: bytes of one VLR header and of one EVLR header (LAS 1.4 R15, tables 6 and 9)
VLR_HEADER, EVLR_HEADER = 54, 60
LASZIP_USER, LASZIP_RECORD = b"laszip encoded", 22204
#: chunk size LASzip writes for variable-size chunks
VARIABLE_CHUNK = 0xFFFFFFFF


def check_header(path: PathLike) -> dict[str, int]:
    """Validate the LAS public header block, the VLRs and (LAZ) the LASzip VLR and chunk
    table against the file size before laspy or the decompressor read anything.

    A corrupted count (VLRs, EVLRs, points, chunks) would otherwise make a reader loop,
    allocate tens of GB or crash the process inside the native decompressor. Every refusal
    is a :class:`FormatError` naming the field (VLR number, chunk, point record). Returns the
    raw fields read."""
    import struct

    p = Path(path)
    size = p.stat().st_size
    if size == 0:
        raise FormatError(path, "file is empty; expected a LAS/LAZ header")
    with open(p, "rb") as fh:
        head = fh.read(375)
    if len(head) < 227 or head[:4] != b"LASF":
        raise FormatError(
            path,
            "not a LAS/LAZ file: expected the 'LASF' signature and a 227-byte or longer header",
        )
    major, minor = head[24], head[25]
    (header_size,) = struct.unpack_from("<H", head, 94)
    offset_points, n_vlrs = struct.unpack_from("<II", head, 96)
    fmt_id, record_len, legacy_count = struct.unpack_from("<BHI", head, 104)
    if major != 1 or minor > 4:
        raise FormatError(path, f"LAS version {major}.{minor}; expected 1.0 to 1.4")
    if (
        header_size < 227
        or header_size > size
        or offset_points < header_size
        or offset_points > size
    ):
        raise FormatError(
            path,
            f"header size {header_size} / point data offset {offset_points} "
            f"do not fit the file of {size} bytes; truncated or corrupt",
        )
    if n_vlrs * VLR_HEADER > offset_points - header_size:
        raise FormatError(
            path,
            f"header announces {n_vlrs} VLRs but only "
            f"{offset_points - header_size} bytes precede the points; "
            "corrupt header",
        )
    count = legacy_count
    if minor >= 4 and len(head) >= 255:
        start_evlr, n_evlr = struct.unpack_from("<QI", head, 235)
        count = struct.unpack_from("<Q", head, 247)[0] or legacy_count
        if n_evlr and (start_evlr > size or n_evlr * EVLR_HEADER > size - start_evlr):
            raise FormatError(
                path,
                f"header announces {n_evlr} extended VLRs that do not fit the file; corrupt header",
            )
    _check_scales(path, head)
    laszip = _read_vlrs(path, p, header_size, offset_points, n_vlrs)
    compressed = bool(fmt_id & 0x80) or bool(fmt_id & 0x40)
    if not compressed and count * record_len > size - offset_points:
        raise FormatError(
            path,
            f"header announces {count} points of {record_len} bytes but "
            f"the file holds {size - offset_points} bytes of point data; "
            "truncated",
        )
    if compressed and count > 0:
        if laszip is None:
            raise FormatError(
                path,
                "compressed point format but no LASzip VLR "
                "('laszip encoded', 22204); corrupt header",
            )
        _check_chunks(path, p, size, offset_points, count, record_len, laszip)
    return {
        "point_count": int(count),
        "record_length": int(record_len),
        "point_format": int(fmt_id & 0x3F),
    }


def _check_scales(path: PathLike, head: bytes) -> None:
    """Scale factors must be finite and non-zero, offsets finite (else every coordinate is
    0, NaN or inf)."""
    import math
    import struct

    scales = struct.unpack_from("<3d", head, 131)
    offsets = struct.unpack_from("<3d", head, 155)
    for axis, sc, off in zip("xyz", scales, offsets, strict=True):
        if not math.isfinite(sc) or sc == 0:
            raise FormatError(
                path,
                f"header {axis} scale factor is {sc!r}; expected a finite "
                "non-zero number (e.g. 0.001)",
            )
        if not math.isfinite(off):
            raise FormatError(path, f"header {axis} offset is {off!r}; expected a finite number")


def _read_vlrs(
    path: PathLike, p: Path, header_size: int, offset_points: int, n_vlrs: int
) -> bytes | None:
    """Walk the VLRs between the header and the points; return the LASzip VLR's payload."""
    import struct

    laszip = None
    with open(p, "rb") as fh:
        fh.seek(header_size)
        block = fh.read(offset_points - header_size)
    pos = 0
    for i in range(n_vlrs):
        if pos + VLR_HEADER > len(block):
            raise FormatError(
                path,
                f"VLR {i} of {n_vlrs} starts at byte {header_size + pos} "
                f"but the point data begin at {offset_points}; corrupt "
                "VLR lengths",
            )
        user = block[pos + 2 : pos + 18].rstrip(b"\0")
        record_id, length = struct.unpack_from("<HH", block, pos + 18)
        end = pos + VLR_HEADER + length
        if end > len(block):
            raise FormatError(
                path,
                f"VLR {i} ({user.decode('latin-1')!r} {record_id}) "
                f"announces {length} bytes that run past the start of the "
                f"point data at byte {offset_points}; corrupt VLR",
            )
        if user == LASZIP_USER and record_id == LASZIP_RECORD:
            laszip = block[pos + VLR_HEADER : end]
        pos = end
    return laszip


def _check_chunks(
    path: PathLike,
    p: Path,
    size: int,
    offset_points: int,
    count: int,
    record_len: int,
    laszip: bytes,
) -> None:
    """Check the LASzip VLR (items cover the record) and the chunk table (it fits the file,
    its chunks hold ``count`` points and exactly the compressed bytes) without decoding a
    single point."""
    import struct

    if len(laszip) < 34:
        raise FormatError(path, f"LASzip VLR holds {len(laszip)} bytes; expected at least 34")
    (chunk_size,) = struct.unpack_from("<I", laszip, 12)
    (n_items,) = struct.unpack_from("<H", laszip, 32)
    if n_items == 0 or len(laszip) < 34 + 6 * n_items:
        raise FormatError(
            path, f"LASzip VLR announces {n_items} items in {len(laszip)} bytes; corrupt VLR"
        )
    item_bytes = sum(struct.unpack_from("<H", laszip, 34 + 6 * k + 2)[0] for k in range(n_items))
    if item_bytes != record_len:
        raise FormatError(
            path,
            f"LASzip items cover {item_bytes} bytes of the {record_len}-byte "
            "point record; corrupt VLR or header",
        )
    if chunk_size == 0:
        raise FormatError(path, "LASzip chunk size is 0; corrupt VLR")
    with open(p, "rb") as fh:
        fh.seek(offset_points)
        raw = fh.read(8)
        if len(raw) < 8:
            raise FormatError(path, "compressed point data is missing; truncated")
        (table_at,) = struct.unpack("<q", raw)
        if table_at == -1:  # written by a streaming compressor: the offset is at the end
            fh.seek(size - 8)
            (table_at,) = struct.unpack("<q", fh.read(8))
        if not offset_points + 8 <= table_at <= size - 8:
            raise FormatError(
                path,
                f"LAZ chunk table offset {table_at} lies outside the "
                f"compressed data (bytes {offset_points + 8} to "
                f"{size - 8}); truncated or corrupt",
            )
        fh.seek(table_at)
        version, n_chunks = struct.unpack("<II", fh.read(8))
    if version != 0:
        raise FormatError(
            path,
            f"LAZ chunk table version {version} at byte {table_at}; "
            "expected 0 (corrupt chunk table)",
        )
    if chunk_size != VARIABLE_CHUNK:
        expected = -(-count // chunk_size)
        if n_chunks != expected:
            raise FormatError(
                path,
                f"LAZ chunk table lists {n_chunks} chunks; {count} points "
                f"in chunks of {chunk_size} need {expected} (corrupt chunk "
                "table or point count)",
            )
    elif not 1 <= n_chunks <= count:
        raise FormatError(
            path, f"LAZ chunk table lists {n_chunks} chunks for {count} points; corrupt chunk table"
        )
    if n_chunks > (size - table_at) * 8:  # an entry takes at least a bit or so
        raise FormatError(
            path,
            f"LAZ chunk table lists {n_chunks} chunks but only "
            f"{size - table_at} bytes follow it; truncated",
        )
    _check_chunk_sizes(path, p, offset_points, table_at, count, chunk_size, laszip)


def _check_chunk_sizes(
    path: PathLike,
    p: Path,
    offset_points: int,
    table_at: int,
    count: int,
    chunk_size: int,
    laszip: bytes,
) -> None:
    import lazrs

    try:
        vlr = lazrs.LazVlr(laszip)
        with open(p, "rb") as fh:
            fh.seek(offset_points)
            table = lazrs.read_chunk_table(fh, vlr)
    except Exception as exc:  # noqa: BLE001 - lazrs raises its own (pyo3) types
        raise FormatError(
            path, f"LAZ chunk table at byte {table_at} is unreadable ({_short(exc)})"
        ) from None
    start = offset_points + 8
    first_point = 0
    for i, (n_points, n_bytes) in enumerate(table):
        points_here = (
            min(chunk_size, count - first_point) if chunk_size != VARIABLE_CHUNK else n_points
        )
        if n_bytes <= 0 or start + n_bytes > table_at or points_here <= 0:
            raise FormatError(
                path,
                f"LAZ chunk {i} (points {first_point} to "
                f"{first_point + max(points_here, 1) - 1}, {n_bytes} bytes "
                f"from byte {start}) does not fit before the chunk table "
                f"at byte {table_at}; truncated or corrupt",
            )
        start += n_bytes
        first_point += points_here
    if start != table_at or first_point != count:
        held = start - offset_points - 8
        raise FormatError(
            path,
            f"LAZ chunks hold {first_point} points in {held} bytes; the "
            f"header announces {count} points and "
            f"{table_at - offset_points - 8} bytes; corrupt chunk table",
        )


def read_points(path: PathLike) -> PointCloud:
    """Read a LAS/LAZ file into a :class:`PointCloud` (all dimensions kept as attributes)."""
    import laspy

    p = Path(path)
    check_header(p)
    try:
        las = laspy.read(p)
        header = las.header
        pf = las.point_format
        xyz = np.stack(
            [
                np.asarray(las.x, dtype=np.float64),
                np.asarray(las.y, dtype=np.float64),
                np.asarray(las.z, dtype=np.float64),
            ],
            axis=1,
        )
        attrs: dict[str, NDArray] = {}
        for name in pf.dimension_names:
            if name in _COORD_DIMS:
                continue
            attrs[name] = np.array(las[name])
        extra = list(pf.extra_dimension_names)
        meta: dict[str, object] = {
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
    except (
        laspy.errors.LaspyException,
        ValueError,
        OSError,
        EOFError,
        KeyError,
        IndexError,
        TypeError,
        AttributeError,
        RuntimeError,
        OverflowError,
        MemoryError,
        UnicodeDecodeError,
    ) as exc:
        raise FormatError(path, f"not a readable LAS/LAZ file ({_short(exc)}){_where(p)}") from None
    except Exception as exc:  # noqa: BLE001 - lazrs raises its own (pyo3) types
        raise FormatError(path, f"not a readable LAS/LAZ file ({_short(exc)}){_where(p)}") from None
    if xyz.shape[0] == 0:
        raise FormatError(path, "holds no points; expected at least one")
    if not np.isfinite(xyz).all():
        row = int(np.flatnonzero(~np.isfinite(xyz).all(axis=1))[0])
        raise FormatError(
            path,
            f"point {row} has a NaN or inf coordinate (bad scale/offset "
            "in the header); expected finite numbers",
        )
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
            xyz = np.stack(
                [
                    np.asarray(pts.x, np.float64),
                    np.asarray(pts.y, np.float64),
                    np.asarray(pts.z, np.float64),
                ],
                axis=1,
            )
            attrs = {
                name: np.array(pts[name])
                for name in pts.point_format.dimension_names
                if name not in _COORD_DIMS
            }
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


def _where(p: Path) -> str:
    """``"; chunk 3 (points 150000 to 199999) is corrupt"`` for a LAZ file whose compressed
    data fail to decode, found by decoding chunk after chunk; ``""`` when not found."""
    import struct

    try:
        with open(p, "rb") as fh:
            head = fh.read(375)
            fmt_id, record_len, legacy = struct.unpack_from("<BHI", head, 104)
            if not fmt_id & 0xC0:
                return ""
            (header_size,) = struct.unpack_from("<H", head, 94)
            offset_points, n_vlrs = struct.unpack_from("<II", head, 96)
            count = legacy
            if head[25] >= 4 and len(head) >= 255:
                count = struct.unpack_from("<Q", head, 247)[0] or legacy
        laszip = _read_vlrs(p, p, header_size, offset_points, n_vlrs)
        if laszip is None:
            return ""
        import lazrs

        (chunk_size,) = struct.unpack_from("<I", laszip, 12)
        step = chunk_size if chunk_size != VARIABLE_CHUNK else count
        with open(p, "rb") as fh:
            fh.seek(offset_points)
            dec = lazrs.LasZipDecompressor(fh, laszip)
            first = 0
            while first < count:
                n = min(step, count - first)
                try:
                    dec.decompress_many(bytearray(n * record_len))
                except Exception:  # noqa: BLE001 - the chunk that fails is the answer
                    chunk = first // step
                    return f"; chunk {chunk} (points {first} to {first + n - 1}) is corrupt"
                first += n
    except Exception:  # noqa: BLE001 - best effort: the main message stands alone
        return ""
    return ""


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


def write_points(
    path: PathLike,
    cloud: PointCloud,
    scale: float | None = None,
    point_format: int | None = None,
    version: str | None = None,
) -> Path:
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
    meta: dict[str, Any] = dict(cloud.meta or {})
    attrs = {k: np.asarray(v) for k, v in cloud.attributes.items()}
    for k, v in attrs.items():
        if v.ndim != 1 or not (np.issubdtype(v.dtype, np.number) or v.dtype == bool):
            raise InputError(
                f"{os.fspath(path)}: attribute {k!r} of dtype {v.dtype} and shape "
                f"{v.shape} cannot be a LAS dimension; expected 1-D numbers"
            )
    fmt_id = point_format if point_format is not None else meta.get("point_format")
    if fmt_id is None:
        fmt_id = _standard_format_for(set(attrs))
    ver = version or meta.get("las_version") or ("1.4" if int(fmt_id) > 5 else "1.2")
    try:
        header = laspy.LasHeader(point_format=int(fmt_id), version=str(ver))
    except laspy.errors.LaspyException as exc:
        raise InputError(
            f"{os.fspath(path)}: LAS point format {fmt_id} / version {ver} "
            f"not writable ({_short(exc)})"
        ) from None
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
    if np.any(np.abs((lo - offsets) / scales) > limit) or np.any(
        np.abs((hi - offsets) / scales) > limit
    ):
        offsets = np.floor(lo)  # kept offsets do not fit the moved cloud: re-anchor
        if np.any((hi - offsets) / scales > limit):
            raise InputError(
                f"{os.fspath(path)}: extent {np.max(hi - lo):.1f} m does not fit "
                f"LAS int32 coordinates at scale {scales.min()}; pass a larger "
                "scale"
            )
    header.scales = scales
    header.offsets = offsets
    for name, arr in attrs.items():
        if name in standard or name in _COORD_DIMS:
            continue
        dtype = arr.dtype if arr.dtype != bool else np.dtype(np.uint8)
        if dtype.kind not in "iuf":
            raise InputError(
                f"{os.fspath(path)}: attribute {name!r} has dtype {dtype}; "
                "expected integers or floats"
            )
        header.add_extra_dim(laspy.ExtraBytesParams(name=name, type=dtype))
    for vlr in meta.get("vlrs", []) or []:
        # a foreign VLR object is skipped: the coordinates are what matters
        with contextlib.suppress(Exception):
            header.vlrs.append(vlr)
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
            raise InputError(
                f"{os.fspath(path)}: attribute {name!r} does not fit its LAS "
                f"dimension ({_short(exc)})"
            ) from None
    compress = Path(path).suffix.lower() == ".laz"
    with atomic_path(path) as tmp:
        las.write(tmp, do_compress=compress)
    return Path(path)


__all__ = ["read_points", "write_points", "read_head", "check_header"]
