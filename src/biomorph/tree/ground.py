"""Ground removal, so the ground is never skeletonised (a known weakness of the thesis).

Two methods, both returning ``(vegetation_cloud, ground_mask)``:

``"csf"``
    Cloth simulation filter (Zhang et al. 2016, "An Easy-to-Use Airborne LiDAR Data
    Filtering Method Based on Cloth Simulation") via the ``cloth-simulation-filter`` package:
    the cloud is turned upside down, a cloth of given resolution and rigidness drops onto it,
    points within ``class_threshold`` of the cloth are ground.
``"grid"``
    Grid minimum + robust surface (implemented here): the lowest point of each XY cell is a
    ground candidate; candidates far above the local lower envelope (a minimum filter over a
    window of cells, i.e. tree parts over cells without visible ground) are rejected, a plane
    is fitted robustly (iteratively trimmed least squares, 3·MAD) to reject the remaining
    outliers, and the inliers are triangulated (TIN, linear interpolation; nearest candidate
    outside their hull). Points less than ``threshold`` above the TIN are ground.

The default (:data:`DEFAULT_METHOD`) was chosen by measured quality on synthetic scans with
known ground labels and on the TreeLS pine plot; the numbers are in ``docs/tree_voxel.md``
and ``bench/tree_voxel.py``.
"""

from __future__ import annotations

import contextlib
import os
import sys
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError

__all__ = [
    "remove_ground",
    "ground_surface_grid",
    "robust_plane",
    "DEFAULT_METHOD",
    "METHODS",
    "LAS_GROUND",
    "PLANE_FLOOR",
]

METHODS = ("grid", "csf", "classified")
#: ASPRS LAS class of ground points (``"classified"``: the file's own ground)
LAS_GROUND = 2
#: chosen by measurement (see module docstring)
DEFAULT_METHOD = "grid"


@contextlib.contextmanager
def _quiet_stdout():
    """Silence C-level stdout (the CSF library prints progress)."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), fd)
            yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


def _csf_mask(
    xyz: NDArray[np.float64],
    cloth_resolution: float = 0.3,
    rigidness: int = 1,
    class_threshold: float = 0.2,
    iterations: int = 500,
    time_step: float = 0.65,
    slope_smooth: bool = True,
) -> NDArray[np.bool_]:
    # defaults tuned on the synthetic tilted/hilly scans of bench/tree_voxel.py: the
    # package's flat-terrain defaults (rigidness 2-3, resolution 0.5) missed up to 56 % of
    # the ground on ±1 m hills
    import CSF  # lazy: optional C extension

    csf = CSF.CSF()
    csf.params.bSloopSmooth = slope_smooth
    csf.params.cloth_resolution = float(cloth_resolution)
    csf.params.rigidness = int(rigidness)
    csf.params.class_threshold = float(class_threshold)
    csf.params.interations = int(iterations)
    csf.params.time_step = float(time_step)
    # CSF works in float; shift to the local origin first
    local = xyz - xyz.min(axis=0)
    csf.setPointCloud(local)
    ground, non_ground = CSF.VecInt(), CSF.VecInt()
    with _quiet_stdout():
        csf.do_filtering(ground, non_ground, False)
    mask = np.zeros(xyz.shape[0], dtype=bool)
    mask[np.asarray(list(ground), dtype=np.int64)] = True
    return mask


#: :func:`robust_plane` rejects a ground point only this far (m) or three robust scatters
#: off the plane, whichever is more: plane residuals are large on real, curved terrain, and
#: only gross outliers (low vegetation left in the ground class) should go
PLANE_FLOOR = 0.3


def robust_plane(
    pts: NDArray[np.float64], floor: float = PLANE_FLOOR
) -> tuple[NDArray[np.float64] | None, NDArray[np.bool_]]:
    """``z = a x + b y + c`` through ground points by least squares, refitted without the
    points more than ``max(3 robust scatters, floor)`` off it until the kept set stops
    changing (10 rounds at most). Returns ``(a, b, c)`` (None under three points) and the
    mask of the points kept."""
    keep = np.ones(pts.shape[0], dtype=bool)
    coef = None
    for _ in range(10):
        if keep.sum() < 3:
            break
        a = np.c_[pts[keep, :2], np.ones(keep.sum())]
        coef = np.linalg.lstsq(a, pts[keep, 2], rcond=None)[0]
        res = pts[:, 2] - np.c_[pts[:, :2], np.ones(pts.shape[0])] @ coef
        mad = np.median(np.abs(res[keep] - np.median(res[keep]))) * 1.4826
        new = np.abs(res - np.median(res[keep])) <= max(3 * mad, floor)
        if np.array_equal(new, keep):
            break
        keep = new
    return coef, keep


def ground_surface_grid(
    xyz: NDArray[np.float64],
    cell: float = 0.5,
    window: float = 3.0,
    max_step: float = 0.5,
    slope: float = 0.3,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Ground candidates (``float[m, 3]``) and the terrain height under every point.

    ``cell``: XY cell (m); ``window``: width (m) of the lower-envelope minimum filter;
    ``max_step``: a cell minimum more than ``max_step + slope * window / 2`` above the
    envelope is not ground; ``slope``: tolerated terrain slope (rise over run).
    """
    if cell <= 0 or window <= 0:
        raise ParameterError(
            f"grid ground filter needs cell > 0 and window > 0 (metres); "
            f"got cell={cell}, window={window}"
        )
    lo = xyz.min(axis=0)
    ij = np.floor((xyz[:, :2] - lo[:2]) / cell).astype(np.int64)
    shape = ij.max(axis=0) + 1
    flat = ij[:, 0] * shape[1] + ij[:, 1]
    zmin = np.full(int(shape[0] * shape[1]), np.inf)
    np.minimum.at(zmin, flat, xyz[:, 2])
    # index of the minimum point per cell
    order = np.lexsort((xyz[:, 2], flat))
    fs = flat[order]
    first = order[np.r_[True, fs[1:] != fs[:-1]]]
    zgrid = zmin.reshape(shape)
    w = max(3, int(round(window / cell)) | 1)
    env = ndimage.minimum_filter(zgrid, size=w, mode="nearest")
    # empty cells are +inf in both grids; compare only occupied cells (inf - inf is NaN)
    occupied = np.isfinite(zgrid)
    ok_cell = np.zeros_like(occupied)
    ok_cell[occupied] = zgrid[occupied] - env[occupied] <= max_step + slope * window / 2
    cand = first[ok_cell.reshape(-1)[flat[first]]]
    pts = xyz[cand]
    _, keep = robust_plane(pts)
    pts = pts[keep] if keep.sum() >= 3 else pts
    if pts.shape[0] >= 3 and np.ptp(pts[:, 0]) > 0 and np.ptp(pts[:, 1]) > 0:
        try:
            lin = LinearNDInterpolator(pts[:, :2], pts[:, 2])
            h = lin(xyz[:, :2])
        except Exception:  # noqa: BLE001 - degenerate triangulation (collinear candidates)
            h = np.full(xyz.shape[0], np.nan)
        bad = ~np.isfinite(h)
        if bad.any():
            h[bad] = NearestNDInterpolator(pts[:, :2], pts[:, 2])(xyz[bad, :2])
    else:
        h = np.full(xyz.shape[0], float(pts[:, 2].min()) if pts.size else float(lo[2]))
    return pts, h


def remove_ground(
    cloud: PointCloud, method: str = DEFAULT_METHOD, min_height: float = 0.5, **params: Any
) -> tuple[PointCloud, NDArray[np.bool_]]:
    """Split ``cloud`` into vegetation and ground.

    Parameters
    ----------
    method : ``"classified"`` (the file's own ground: ASPRS class 2, :data:`LAS_GROUND`),
        ``"grid"`` (default, see :func:`ground_surface_grid`; extra parameters
        ``cell``, ``window``, ``max_step``, ``slope`` and ``threshold`` = height above the
        terrain below which a point is ground, default 0.15 m) or ``"csf"`` (parameters
        ``cloth_resolution``, ``rigidness``, ``class_threshold``, ``iterations``,
        ``time_step``, ``slope_smooth``).
    min_height : the vegetation must rise at least this far (m) above the ground, else
        :class:`InputError` "no tree above the ground".

    Returns
    -------
    ``(vegetation, ground_mask)`` -- the vegetation cloud (attributes kept) and a boolean
    mask over the input points, true on ground.
    """
    n = cloud.n_points
    name = cloud.source or "point cloud"
    if n == 0:
        raise InputError(f"{name} is empty; expected points")
    xyz = cloud.xyz
    if method == "grid":
        threshold = float(params.pop("threshold", 0.15))
        _, h = ground_surface_grid(xyz, **params)
        above = xyz[:, 2] - h
        mask = above < threshold
    elif method == "csf":
        mask = _csf_mask(xyz, **params)
        above = None
    elif method == "classified":
        cls = cloud.attributes.get("classification")
        if cls is None:
            raise InputError(
                f"{name}: ground 'classified' needs a classification per point (LAS); "
                "expected a classified file or another ground method"
            )
        mask = np.asarray(cls) == LAS_GROUND
        above = None
    else:
        raise ParameterError(
            f"ground removal method must be one of {', '.join(METHODS)}; got {method!r}"
        )
    veg = ~mask
    if above is None:
        # height above ground for the check: nearest ground point's z
        if mask.any():
            from scipy.spatial import cKDTree

            gi = cKDTree(xyz[mask, :2]).query(xyz[veg, :2])[1]
            above_v = xyz[veg, 2] - xyz[mask][gi, 2]
        else:
            above_v = xyz[veg, 2] - xyz[:, 2].min()
    else:
        above_v = above[veg]
    if veg.sum() < 10 or not (above_v.size and np.max(above_v) >= min_height):
        top = float(np.max(above_v)) if above_v.size else 0.0
        raise InputError(
            f"{name}: no tree above the ground ({int(veg.sum())} non-ground "
            f"points, highest {top:.2f} m above the terrain; expected a tree "
            f"rising at least {min_height} m)"
        )
    return cloud.select(veg), mask
