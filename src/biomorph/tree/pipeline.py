"""``skeletonize``: cloud → prepared cloud → skeleton → radii → branch order → cleanup → metrics.

>>> import biomorph as bm
>>> skel = bm.tree.skeletonize("scan.laz", method="graph")        # doctest: +SKIP
>>> skel.graph.n_nodes, skel.metrics["nob"], skel.timings["total"]  # doctest: +SKIP

Everything runs in the *centred cloud frame* (bottom centre of the bbox at the origin,
metres, Z up); ``TreeSkeleton.offset`` adds back to the original (e.g. georeferenced)
coordinates, see :meth:`TreeSkeleton.world_graph`. Parameters that depend on the data
(point spacing, node spacing, search radii, trunk radius) are derived from the cloud.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError

__all__ = ["TreeSkeleton", "skeletonize", "METHODS", "load_cloud", "remove_sparse"]

METHODS = ("graph", "voxel")
#: default shortest side tip kept by the graph method's cleanup, in node spacings: shorter
#: tips are range-noise spurs or foliage remnants. Measured on the synthetic presets (clean
#: and noisy leafy scans at 60,000 points, foliage separation, chain smoothing): NOB 93–109 %
#: of the truth at 3 (median of two seeds); 1.5 gave up to 159 % (bench/tree.py, docs/tree.md)
TIP_LENGTH = 3.0
#: default floor (m) of the cylinder radius in the fork rule of the overlap collapse: two branches
#: whose axes run within 1 cm of each other are one branch seen through range noise. At
#: 240,000 points with 8 mm noise and leaf clutter, the Dijkstra tree of each noisy twig
#: sprouts side spurs lying 1–2 cm off its axis, outside its ~4 mm allometric cylinder:
#: the floor takes the leafy maple's NOB from 188 to 130 % and the conifer's from 127 to
#: 114 %; at 60,000 points it changes NOB by −6 to +0 % (−10 % on the noisy conifer, which
#: had 109 %) and F1 by < 0.01 (docs/tree.md "Denser scans").
MIN_CYLINDER_RADIUS = 0.01
#: ``tip_support`` only judges tip chains shorter than this many node spacings: long chains
#: are real branches however sparsely the scan sampled them
TIP_SUPPORT_LENGTH = 8.0


@dataclass
class TreeSkeleton:
    """Result of :func:`skeletonize`.

    graph : skeleton in the centred cloud frame (positions m, ``radius`` m, ``depth`` =
        branch order, ``weight`` = subtree length, ``tree_id``).
    method : ``"graph"`` or ``"voxel"``.
    timings : seconds: ``t1``..``t4`` as in the thesis (graph: roots, initial skeleton,
        global optimisation, cleanup; voxel: voxelisation, preprocessing, thinning,
        extraction) plus ``prepare``, ``radius_fit``, ``order``, ``metrics``, ``total`` and
        method sub-phases.
    params : the parameters actually used (defaults resolved from the data).
    metrics : NOB, TBL, MSE (per tree too), trunk radius and DBH per tree.
    offset : add to positions for original coordinates.
    cloud : the prepared (centred, cleaned, ground-free) cloud; ``ground`` the ground points.
    segment : branch (segment) id per node.
    """

    graph: BranchGraph
    method: str
    timings: dict[str, float]
    params: dict[str, Any]
    metrics: dict[str, Any]
    offset: NDArray[np.float64]
    cloud: PointCloud | None = None
    ground: PointCloud | None = None
    segment: NDArray[np.int64] | None = None
    info: dict[str, Any] = field(default_factory=dict)

    def world_graph(self) -> BranchGraph:
        """The skeleton in the original coordinates (positions + offset)."""
        return self.graph.with_(position=self.graph.position + self.offset)

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary: method, metrics, parameters, timings, info, offset."""
        return _jsonable({"method": self.method, "metrics": self.metrics,
                          "params": self.params, "timings": self.timings, "info": self.info,
                          "offset": self.offset})


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def load_cloud(cloud: PointCloud | str | os.PathLike | NDArray) -> PointCloud:
    """A PointCloud from a PointCloud, a file path (any ``bm.io`` format) or an ``(n, 3)`` array."""
    if isinstance(cloud, PointCloud):
        return cloud
    if isinstance(cloud, (str, os.PathLike)):
        from biomorph.io import read_points

        return read_points(cloud)
    arr = np.asarray(cloud, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"point array has shape {arr.shape}; expected (n, 3)")
    return PointCloud(arr)


def remove_sparse(cloud: PointCloud, ratio: float, k: int = 16) -> PointCloud:
    """Points whose mean distance to their ``k`` nearest neighbours is at most ``ratio``
    times the median of that distance (a density filter for clutter; metres-free)."""
    from scipy.spatial import cKDTree

    if ratio <= 1:
        raise ParameterError(f"sparse_filter must be > 1 (a multiple of the median "
                             f"neighbour distance), got {ratio}")
    n = cloud.n_points
    if n <= k:
        return cloud
    d, _ = cKDTree(cloud.xyz).query(cloud.xyz, k=k + 1, workers=-1)
    md = d[:, 1:].mean(axis=1)
    return cloud.select(md <= ratio * np.median(md))


def _height_above_ground(xyz: NDArray, ground: PointCloud | None) -> NDArray | None:
    if ground is None or ground.n_points == 0:
        return None
    from scipy.spatial import cKDTree

    _, i = cKDTree(ground.xyz[:, :2]).query(xyz[:, :2], k=min(4, ground.n_points), workers=-1)
    gz = ground.xyz[:, 2][np.atleast_2d(i.T).T].reshape(xyz.shape[0], -1).mean(axis=1)
    return xyz[:, 2] - gz


def skeletonize(cloud: PointCloud | str | os.PathLike | NDArray, method: str = "graph", *,
                # preparation (tree.cloud.prepare)
                centre: bool = True, filter: dict | tuple | None = None,  # noqa: A002
                downsample: dict | float | None = None, outliers: bool | dict = True,
                ground: str | None = "auto", seed: int = 0,
                # graph method
                n_trees: int | None = None, k: int = 10, search_radius: float | None = None,
                node_spacing: float | None = None, max_iter: int = 5, reweight: float = 0.5,
                root_slice: float = 0.5, min_tree_distance: float = 0.6,
                allometry_exponent: float = 2.5, edge_weights: str = "livny",
                # cleanup
                cleanup: bool = True, radius_ratio: float = 0.5, length_factor: float = 3.0,
                overlap: float = 0.5, min_branch_length: float | None = None,
                min_cylinder_radius: float = MIN_CYLINDER_RADIUS,
                tip_support: float | None = None,
                # voxel method
                voxel: dict | None = None,
                sparse_filter: float | None = None,
                foliage: float | str | None = "auto", foliage_passes: int = 2,
                # extensions
                radius: str = "fit", recentre: bool = True, search_factor: float = 1.5,
                smooth: int = 2,
                order_share: float = 0.5, order_angle: float = np.radians(45.0),
                progress: Any = None) -> TreeSkeleton:
    """Skeletonise a tree (or a plot of trees) with the graph or the voxel method.

    Parameters (metres, radians)
    ----------------------------
    cloud : PointCloud, path or ``(n, 3)`` array.
    method : ``"graph"`` (Livny et al. 2010, :mod:`~biomorph.tree.livny`) or ``"voxel"``
        (Gorte & Pfeifer 2004, :mod:`~biomorph.tree.voxel`).
    centre, filter, downsample, outliers, ground, seed : :func:`biomorph.tree.cloud.prepare`
        (ground removal runs when a ground surface is detected, ``ground="auto"``).
    n_trees … allometry_exponent, edge_weights : :func:`biomorph.tree.livny.skeletonize_graph`.
    cleanup, radius_ratio, length_factor, overlap, min_branch_length :
        :func:`biomorph.tree.cleanup.cleanup` (``min_branch_length`` defaults to
        ``TIP_LENGTH`` = 3 node spacings for the graph method, 1.5 voxels for the voxel
        method: side tips shorter than that are scan noise or foliage).
    min_cylinder_radius : floor (m) of the cylinder radius in the fork rule of the overlap
        collapse (``MIN_CYLINDER_RADIUS``, 1 cm: branches closer than that are range noise;
        0 = the allometric radius alone, as in the thesis).
    tip_support : prune side tip chains shorter than ``TIP_SUPPORT_LENGTH`` node spacings
        holding fewer points per node than this share of the median tip chain (points go to
        their nearest node; :func:`biomorph.tree.cleanup.prune_unsupported_tips`). ``None``
        (default) keeps them. 0.3 fixes dense leafy scans (240,000 points: NOB 94–111 %)
        but removes real sparsely sampled twigs at 60,000 points (NOB down to 83 %).
    foliage, foliage_passes : leaf/wood separation before skeletonising
        (:func:`biomorph.tree.foliage.separate_foliage`): points whose neighbourhood is
        thicker than ``foliage`` × the median are dropped; ``None`` keeps every point;
        ``"auto"`` (default): for the graph method 3.0 when foliage is detected (more than
        0.3 % of the points thicker than 6 × the median), else nothing is removed; off for
        the voxel method (without the graph's bridging, the holes it leaves split voxel
        skeletons: aspen NOB 113 → 133 %). A number always splits.
    sparse_filter : drop points whose mean distance to their 16 nearest neighbours exceeds
        this multiple of the median (leaf clutter, stray returns); ``None`` (default) keeps
        them. 4.0 roughly halves the spurious twigs of an 8 mm-noise scan with 5 % leaf
        clutter but also thins real sparse tips (docs/tree.md).
    voxel : keyword arguments of ``skeletonize_voxel`` (e.g. ``{"cell_size": 0.05}``).
    radius : ``"fit"`` (RANSAC circles, :mod:`~biomorph.tree.radius`) or ``"allometric"``.
    recentre : move nodes to the fitted circle centres.
    smooth : sweeps of :func:`biomorph.tree.cleanup.smooth_chains` after the radii (0 = off).
    order_share, order_angle : branch-order rule (:mod:`~biomorph.tree.order`).
    progress : optional ``advance(n=1, description=None)`` callback (see
        :func:`biomorph.progress.task`).
    """
    import importlib

    tcloud = importlib.import_module("biomorph.tree.cloud")
    tclean = importlib.import_module("biomorph.tree.cleanup")
    livny = importlib.import_module("biomorph.tree.livny")
    order = importlib.import_module("biomorph.tree.order")
    tradius = importlib.import_module("biomorph.tree.radius")
    from biomorph.tree.metrics import dbh_per_tree, skeleton_metrics

    if method not in METHODS:
        raise ParameterError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    if radius not in ("fit", "allometric"):
        raise ParameterError(f"radius must be 'fit' or 'allometric', got {radius!r}")
    timings: dict[str, float] = {}
    t_all = time.perf_counter()

    def tick(description: str) -> None:
        if progress is not None:
            progress(1, description)

    raw = load_cloud(cloud)
    t0 = time.perf_counter()
    prep = tcloud.prepare(raw, centre=centre, filter=filter, downsample=downsample,
                          outliers=outliers, ground=ground, seed=seed)
    pc = prep.cloud
    foliage_info: dict[str, Any] = {}
    detect = False
    if isinstance(foliage, str):
        if foliage != "auto":
            raise ParameterError(f"foliage {foliage!r}; expected 'auto', None or a factor > 1")
        foliage, detect = (3.0, True) if method == "graph" else (None, False)
    if foliage is not None and pc.n_points >= 100:
        from biomorph.tree.foliage import separate_foliage

        split = separate_foliage(pc.xyz, factor=foliage, passes=foliage_passes, detect=detect)
        foliage_info = {"foliage_removed": int((~split.wood).sum()),
                        "foliage_threshold": [float(x) for x in split.threshold],
                        "foliage_detected": split.detected,
                        "foliage_share": split.foliage_share}
        pc = pc.select(split.wood)
    if sparse_filter is not None:
        pc = remove_sparse(pc, sparse_filter)
    if pc.n_points < 10:
        raise InputError(f"{raw.source or 'point cloud'}: only {pc.n_points} points remain "
                         "above the ground; expected a tree")
    timings["prepare"] = time.perf_counter() - t0
    tick("prepared")
    xyz = pc.xyz
    info: dict[str, Any] = {"points_in": raw.n_points, "points": pc.n_points,
                            "prepare": prep.steps, **foliage_info}
    params: dict[str, Any] = {"method": method, "seed": seed, "sparse_filter": sparse_filter,
                              "foliage": foliage, "foliage_passes": foliage_passes}
    if method == "graph":
        height = _height_above_ground(xyz, prep.ground)
        res = livny.skeletonize_graph(
            xyz, n_trees=n_trees, k=k, search_radius=search_radius, node_spacing=node_spacing,
            max_iter=max_iter, reweight=reweight, height=height, root_slice=root_slice,
            min_tree_distance=min_tree_distance, allometry_exponent=allometry_exponent,
            edge_weights=edge_weights, seed=seed, progress=progress)
        graph = res.graph
        spacing = float(res.info["node_spacing"])
        timings.update({k_: v for k_, v in res.timings.items()})
        info.update(res.info)
        params.update(n_trees=n_trees, k=k, search_radius=search_radius,
                      node_spacing=spacing, max_iter=max_iter, reweight=reweight,
                      root_slice=root_slice, min_tree_distance=min_tree_distance,
                      allometry_exponent=allometry_exponent, edge_weights=edge_weights)
        t0 = time.perf_counter()
        if cleanup:
            mbl = TIP_LENGTH * spacing if min_branch_length is None else min_branch_length
            graph = tclean.cleanup(graph, radius_ratio=radius_ratio,
                                   length_factor=length_factor, min_length=mbl,
                                   overlap=overlap, min_radius=min_cylinder_radius)
            graph = tclean.prune_small_trees(graph, 2 * spacing)
            params.update(cleanup=True, radius_ratio=radius_ratio, length_factor=length_factor,
                          overlap=overlap, min_branch_length=mbl,
                          min_cylinder_radius=min_cylinder_radius)
        if tip_support is not None:
            graph = tclean.prune_unsupported_tips(graph, xyz, tip_support,
                                                 TIP_SUPPORT_LENGTH * spacing)
            params.update(tip_support=tip_support)
        graph = livny.extend_tips(graph, xyz, 2.0 * spacing)
        graph = livny.densify(graph, spacing)
        timings["t4"] = time.perf_counter() - t0
        timings["cleanup"] = timings["t4"]
    else:
        try:
            from biomorph.tree.voxel import skeletonize_voxel
        except ImportError as exc:  # pragma: no cover - during parallel development
            raise ParameterError("the voxel method is not available in this build") from exc
        vres = skeletonize_voxel(pc, **(voxel or {}))
        graph = vres.graph
        timings.update({k_: float(v) for k_, v in vres.timings.items()
                        if isinstance(v, (int, float))})
        el = graph.edge_length
        spacing = float(np.median(el[el > 0])) if (el > 0).any() else 0.05
        params.update(voxel=dict(voxel or {}), node_spacing=spacing)
        if graph.tree_id is None:
            graph = graph.with_(tree_id=graph.trees)
        graph = tclean.prune_small_trees(graph, 2 * spacing)
        if cleanup and graph.n_nodes:
            # the voxel skeleton has no allometric radii: give it one from the points so
            # the false-branch rule can run; cylinder collapse is Livny-specific, skip it
            t0 = time.perf_counter()
            d, _ = livny.skeleton_distance(xyz, graph.parent, graph.position)
            r = livny.allometric_radii(graph.parent, graph.position, graph.subtree_length(),
                                       float(np.mean(d)), tree=graph.trees,
                                       exponent=allometry_exponent, order=graph.order)
            mbl = 1.5 * spacing if min_branch_length is None else min_branch_length
            graph = tclean.remove_false_branches(graph.with_(radius=r),
                                                 radius_ratio=radius_ratio,
                                                 length_factor=length_factor, min_length=mbl)
            timings["cleanup"] = time.perf_counter() - t0
    if graph.n_nodes == 0:
        raise InputError(f"{raw.source or 'point cloud'}: no skeleton could be built "
                         "(no tree found above the ground)")
    tick("skeleton")

    # ---- radii
    t0 = time.perf_counter()
    if radius == "fit":
        graph, fit = tradius.fit_radii(graph, xyz, recentre=recentre,
                                       search_factor=search_factor,
                                       allometry_exponent=allometry_exponent, seed=seed)
        info["radius_fit_ok"] = float(fit.ok.mean()) if fit.ok.size else 0.0
    elif graph.radius is None:
        d, _ = livny.skeleton_distance(xyz, graph.parent, graph.position)
        graph = graph.with_(radius=livny.allometric_radii(
            graph.parent, graph.position, graph.subtree_length(), float(np.mean(d)),
            tree=graph.trees, exponent=allometry_exponent, order=graph.order))
    graph = tclean.smooth_chains(graph, smooth)
    params.update(radius=radius, recentre=recentre, search_factor=search_factor, smooth=smooth)
    timings["radius_fit"] = time.perf_counter() - t0
    tick("radii")

    # ---- branch order and segments
    t0 = time.perf_counter()
    graph = order.with_order(graph, order_share, order_angle)
    seg = order.segments(graph, order_share, order_angle)
    if graph.weight is None:
        graph = graph.with_(weight=graph.subtree_length())
    if graph.tree_id is None:
        graph = graph.with_(tree_id=graph.trees)
    params.update(order_share=order_share, order_angle_deg=float(np.degrees(order_angle)))
    timings["order"] = time.perf_counter() - t0
    tick("order")

    # ---- metrics
    t0 = time.perf_counter()
    # MSE on at most 200,000 points (seeded sample): the mean converges long before that
    mse_cloud = pc
    if pc.n_points > 200_000:
        pick = np.random.default_rng(seed).choice(pc.n_points, 200_000, replace=False)
        mse_cloud = pc.select(np.sort(pick))
    metrics = skeleton_metrics(graph, mse_cloud)
    metrics["mse_points"] = mse_cloud.n_points
    try:
        dbhs = dbh_per_tree(graph)
        metrics["dbh"] = [None if not np.isfinite(v) else float(v) for v in np.atleast_1d(dbhs)]
    except Exception:  # noqa: BLE001 - a tree shorter than 1.3 m has no DBH
        metrics["dbh"] = None
    roots = graph.roots
    metrics["trunk_radius"] = [float(graph.radius[r]) for r in roots]
    metrics["max_order"] = int(graph.depth.max()) if graph.n_nodes else 0
    metrics["n_segments"] = int(seg.max() + 1) if seg.size else 0
    timings["metrics"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    return TreeSkeleton(graph=graph, method=method, timings=timings, params=params,
                        metrics=metrics, offset=np.asarray(pc.offset, dtype=float).copy(),
                        cloud=pc, ground=prep.ground, segment=seg, info=info)
