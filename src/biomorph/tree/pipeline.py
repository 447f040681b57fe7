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
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.core.jsonable import to_jsonable
from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError
from biomorph.tree.options import (
    METHODS,
    MIN_CYLINDER_RADIUS,
    TIP_LENGTH,
    TIP_SUPPORT_LENGTH,
    SkeletonizeOptions,
)

if TYPE_CHECKING:
    from biomorph.tree.metrics import SegmentCandidates

__all__ = [
    "TreeSkeleton",
    "skeletonize",
    "METHODS",
    "PHASES",
    "load_cloud",
    "remove_sparse",
    "SkeletonizeOptions",
    "TIP_LENGTH",
    "MIN_CYLINDER_RADIUS",
    "TIP_SUPPORT_LENGTH",
    "prepare_phase",
    "graph_phase",
    "voxel_phase",
    "radius_phase",
    "residual_phase",
    "limbs_phase",
    "empty_tips_phase",
    "twig_phase",
    "order_phase",
    "metrics_phase",
]

#: the tree pipeline's phases, in order; ``progress(1, …)`` is called as each ends (the
#: skeleton method's sub-phases call ``progress(0, name)``)
PHASES = ("prepare", "skeleton", "radii", "order", "metrics")


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
    quality : per node, the radius fit's quality: ``reliable`` (the radius is the fit's,
        not the taper model's), ``mad`` (m), ``coverage`` (0–1), ``fitted_radius`` (m, -1 =
        no fit), ``segment`` (the radius follows the cylinder of its run of nodes,
        :mod:`biomorph.tree.run_cylinders`); None for allometric radii.
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
    quality: dict[str, NDArray] | None = None

    def world_graph(self) -> BranchGraph:
        """The skeleton in the original coordinates (positions + offset)."""
        return self.graph.with_(position=self.graph.position + self.offset)

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary: method, metrics, parameters, timings, info, offset."""
        return to_jsonable(
            {
                "method": self.method,
                "metrics": self.metrics,
                "params": self.params,
                "timings": self.timings,
                "info": self.info,
                "offset": self.offset,
            }
        )


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


def remove_sparse(
    cloud: PointCloud, ratio: float, k: int = 16, *, return_mask: bool = False
) -> PointCloud | tuple[PointCloud, NDArray[np.bool_]]:
    """Points whose mean distance to their ``k`` nearest neighbours is at most ``ratio``
    times the median of that distance (a density filter for clutter; metres-free). With
    ``return_mask`` the boolean mask of the kept points is returned as well."""
    from scipy.spatial import cKDTree

    from biomorph.tree.neighbours import query_blocks

    if ratio <= 1:
        raise ParameterError(
            f"sparse_filter must be > 1 (a multiple of the median neighbour distance), got {ratio}"
        )
    n = cloud.n_points
    if n <= k:
        return (cloud, np.ones(n, dtype=bool)) if return_mask else cloud
    md = np.empty(n)
    for rows, d, _ in query_blocks(cKDTree(cloud.xyz), None, k + 1):
        md[rows] = d[:, 1:].mean(axis=1)
    keep = md <= ratio * np.median(md)
    return (cloud.select(keep), keep) if return_mask else cloud.select(keep)


def _height_above_ground(xyz: NDArray, ground: PointCloud | None) -> NDArray | None:
    if ground is None or ground.n_points == 0:
        return None
    from scipy.spatial import cKDTree

    _, i = cKDTree(ground.xyz[:, :2]).query(xyz[:, :2], k=min(4, ground.n_points), workers=-1)
    gz = ground.xyz[:, 2][np.atleast_2d(i.T).T].reshape(xyz.shape[0], -1).mean(axis=1)
    return xyz[:, 2] - gz


Progress = Callable[..., Any] | None


@dataclass
class _Run:
    """State handed from phase to phase of one :func:`skeletonize` run."""

    opts: SkeletonizeOptions
    progress: Progress
    raw: PointCloud
    timings: dict[str, float] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)
    cloud: PointCloud | None = None
    ground: PointCloud | None = None
    graph: BranchGraph | None = None
    segment: NDArray[np.int64] | None = None
    metrics: dict[str, Any] = field(default_factory=dict)
    fit: Any = None
    quality: dict[str, NDArray] | None = None
    #: the skeleton as it entered the radius stage (the residual stage grows this one)
    skeleton: BranchGraph | None = None
    #: the outlier filter's neighbour lists of ``cloud`` until the neighbour graph uses them
    knn: Any = None
    #: (positions, parents, ``metrics.segment_candidates`` of ``cloud``) as the twig phase
    #: searched them: the metrics phase reuses them while the skeleton's axes stay these
    candidates: Any = None
    #: ``(cloud, its PointIndex)`` once :meth:`point_index` built it
    index: Any = field(default=None, repr=False)
    #: the skeleton changed since the radius stage last ran (tips pruned): the next phase
    #: that re-fits anyway does it once for both, or :func:`detour_phase` does
    radii_pending: bool = False
    #: positions (skeleton frame, as the radius stage receives them) of the nodes of limbs
    #: turned round (:func:`limbs_phase`): their circle fits are their radii. Positions, not
    #: indices: the empty-tip pruning and the detours' densifying renumber the nodes after
    #: the turn but move none of these
    limb_points: NDArray[np.float64] | None = None
    #: :meth:`limb_mask` of the skeleton the radius stage last fitted (node for node with
    #: ``graph`` after it)
    limb_nodes: NDArray[np.bool_] | None = None
    #: the stems followed through ``cloud`` so far (:func:`biomorph.tree.stem.stem_tracks`'
    #: cache: the points do not change between the radius passes)
    stem_tracks: list = field(default_factory=list)

    def limb_mask(self, graph: BranchGraph) -> NDArray[np.bool_] | None:
        """The nodes of ``graph`` at :attr:`limb_points` (None: no limb turned)."""
        if self.limb_points is None or graph.n_nodes == 0:
            return None
        from scipy.spatial import cKDTree

        d, _ = cKDTree(self.limb_points).query(graph.position)
        return np.asarray(d <= 1e-9)

    def point_index(self) -> Any:
        """The k-d tree of ``cloud`` (a :class:`~biomorph.tree.neighbours.PointIndex`,
        with the grid the radius stage's cross-sections search), built once and handed to
        every stage that searches the cloud's points (the radius stage runs up to three
        times, the twig phase queries in its leaf order)."""
        if self.index is None or self.index[0] is not self.cloud:
            from biomorph.tree.neighbours import PointIndex

            assert self.cloud is not None
            self.index = (self.cloud, PointIndex(self.cloud.xyz))
        return self.index[1]

    def point_spacing(self) -> float:
        """The cloud's point spacing: as the graph method measured it, else measured here
        once (the voxel method does not) and recorded in ``info``."""
        ps = float(self.info.get("point_spacing") or 0.0)
        if ps <= 0 and self.cloud is not None and self.cloud.n_points >= 2:
            from biomorph.tree.neighbours import estimate_spacing

            ps = float(estimate_spacing(self.cloud.xyz, kdtree=self.point_index()))
            self.info["point_spacing"] = ps
        return ps

    def take_knn(self) -> Any:
        """The neighbour lists, released here (their 10⁶ × 17 arrays live no longer than
        the neighbour graph that consumes them)."""
        knn, self.knn = self.knn, None
        return knn

    @property
    def source(self) -> str:
        return self.raw.source or "point cloud"

    def tick(self, description: str) -> None:
        """A phase of :data:`PHASES` ended."""
        if self.progress is not None:
            self.progress(1, description)

    def sub_progress(self) -> Progress:
        """The callback for the skeleton method's sub-phases: named, no step of the bar."""
        progress = self.progress
        if progress is None:
            return None
        return lambda _n=1, description=None: progress(0, description)


def skeletonize(
    cloud: PointCloud | str | os.PathLike | NDArray,
    method: str | None = None,
    *,
    options: SkeletonizeOptions | None = None,
    progress: Progress = None,
    **kwargs: Any,
) -> TreeSkeleton:
    """Skeletonise a tree (or a plot of trees) with the graph or the voxel method.

    Parameters
    ----------
    cloud : PointCloud, path or ``(n, 3)`` array.
    method : ``"graph"`` (Livny et al. 2010, :mod:`~biomorph.tree.livny`) or ``"voxel"``
        (Gorte & Pfeifer 2004, :mod:`~biomorph.tree.voxel`); overrides ``options.method``.
    options : :class:`~biomorph.tree.options.SkeletonizeOptions`, one typed options object
        per stage (prepare, graph, voxel, cleanup, radius, order; see
        :mod:`biomorph.tree.options` for every field, its unit and where its default comes
        from). Default: all defaults.
    progress : optional ``advance(n=1, description=None)`` callback (see
        :func:`biomorph.progress.task`): ``n = 1`` as each phase of :data:`PHASES` ends
        (a bar of ``len(PHASES)`` steps ends at its total), ``n = 0`` naming each
        sub-phase of the skeleton method; raising from it stops the run.
    **kwargs : the flat keywords of the pre-options API (``k=12``, ``order_angle=…``,
        ``voxel={"cell_size": 0.05}``, …), applied on top of ``options``
        (:meth:`SkeletonizeOptions.from_kwargs`); kept for compatibility.

    The phases: :func:`prepare_phase` (centring, filter, downsampling, outliers, ground,
    foliage, clutter), :func:`graph_phase` or :func:`voxel_phase` (skeleton + cleanup),
    :func:`radius_phase`, :func:`order_phase`, :func:`metrics_phase`.
    """
    opts = options or SkeletonizeOptions()
    if method is not None or kwargs:
        opts = SkeletonizeOptions.from_kwargs(
            method or opts.method, kwargs.pop("seed", opts.seed), base=opts, **kwargs
        )
    t_all = time.perf_counter()
    run = _Run(opts, progress, load_cloud(cloud))
    prepare_phase(run)
    (graph_phase if opts.method == "graph" else voxel_phase)(run)
    ground_base_phase(run)
    radius_phase(run)
    residual_phase(run)
    limbs_phase(run)
    empty_tips_phase(run)
    detour_phase(run)
    segment_phase(run)
    twig_phase(run)
    order_phase(run)
    metrics_phase(run)
    run.timings["total"] = time.perf_counter() - t_all
    assert run.cloud is not None and run.graph is not None
    return TreeSkeleton(
        graph=run.graph,
        method=opts.method,
        timings=run.timings,
        params=run.params,
        metrics=run.metrics,
        offset=np.asarray(run.cloud.offset, dtype=float).copy(),
        cloud=run.cloud,
        ground=run.ground,
        segment=run.segment,
        info=run.info,
        quality=run.quality,
    )


def prepare_phase(run: _Run) -> None:
    """Centre, filter, downsample, de-noise, remove ground, foliage and clutter."""
    from biomorph.tree.cloud import check_units, prepare, to_metres, to_z_up

    po = run.opts.prepare
    go = run.opts.graph
    t0 = time.perf_counter()
    if po.up is not None:  # turned Z-up first: the height the units check reads is z
        run.raw = to_z_up(run.raw, po.up)
    if po.units is None:  # metres, unless the cloud is taller than any tree
        check_units(run.raw)
    else:
        run.raw = to_metres(run.raw, po.units)
    check = po.memory_check
    if check and po.downsample_voxel is None:  # the points the skeleton stage will hold
        from biomorph.tree.memory import check_memory

        n = round(run.raw.n_points * (po.downsample or 1.0))
        check_memory(run.raw.xyz, run.source, n_points=n)
    prep = prepare(
        run.raw,
        centre=po.centre,
        filter=None if po.filter is None else po.filter.as_kwargs(),
        downsample=po.downsample_arg(),
        outliers=po.outliers_arg(),
        ground=po.ground,
        seed=run.opts.seed,
        # the outlier filter's k + 1 neighbours serve the kNN graph's (one query, not two)
        neighbours=run.opts.method == "graph" and go.search_radius is None and go.k <= po.outlier_k,
    )
    pc, knn, ground, steps = prep.cloud, prep.neighbours, prep.ground, prep.steps
    del prep  # ``knn`` alone holds the neighbour lists until the graph
    if check and po.downsample_voxel is not None:  # as many as the voxels kept
        from biomorph.tree.memory import check_memory

        check_memory(pc.xyz, run.source)
    foliage, foliage_info = _foliage(run, pc, knn)
    if foliage_info:
        wood = foliage_info.pop("_wood")
        kd = foliage_info.pop("_kdtree")
        if not wood.all():  # nothing removed (no foliage detected): no copies
            pc = pc.select(wood)
            knn = None if knn is None else knn.select(wood)
        elif knn is not None:
            knn.tree = kd  # the foliage pass's k-d tree of these points, for the graph
    if po.sparse_filter is not None:
        pc, dense = remove_sparse(pc, po.sparse_filter, return_mask=True)
        knn = None if knn is None else knn.select(dense)
    run.knn = knn
    del knn
    if pc.n_points < 10:
        raise InputError(
            f"{run.source}: only {pc.n_points} points remain above the ground; expected a tree"
        )
    run.cloud, run.ground = pc, ground
    run.timings["prepare"] = time.perf_counter() - t0
    run.info.update(
        {
            "points_in": run.raw.n_points,
            "points": pc.n_points,
            "prepare": steps,
            **foliage_info,
        }
    )
    run.params.update(
        {
            "method": run.opts.method,
            "seed": run.opts.seed,
            "units": po.units or "m",
            "up": po.up or "z",
            "sparse_filter": po.sparse_filter,
            "foliage": foliage,
            "foliage_passes": po.foliage_passes,
        }
    )
    run.tick("prepared")


def _foliage(run: _Run, pc: PointCloud, knn: Any = None) -> tuple[float | None, dict[str, Any]]:
    """Resolved foliage factor and the separation's record (``_wood`` = mask to keep,
    ``_kdtree`` = the k-d tree of ``pc`` if one was built). ``knn``: the outlier filter's
    neighbour lists of ``pc``, which spare the separation its own query."""
    foliage = run.opts.prepare.foliage
    detect = False
    if isinstance(foliage, str):
        foliage, detect = (3.0, True) if run.opts.method == "graph" else (None, False)
    if foliage is None or pc.n_points < 100:
        return foliage, {}
    from biomorph.tree.foliage import separate_foliage

    split = separate_foliage(
        pc.xyz,
        factor=foliage,
        passes=run.opts.prepare.foliage_passes,
        detect=detect,
        neighbours=knn,
    )
    return foliage, {
        "foliage_removed": int((~split.wood).sum()),
        "foliage_threshold": [float(x) for x in split.threshold],
        "foliage_detected": split.detected,
        "foliage_share": split.foliage_share,
        "_wood": split.wood,
        "_kdtree": split.kdtree,
    }


def graph_phase(run: _Run) -> None:
    """Livny's graph skeleton, then cleanup, tip support, tip extension and densifying."""
    from biomorph.tree import livny

    go = run.opts.graph
    assert run.cloud is not None
    xyz = run.cloud.xyz
    height = _height_above_ground(xyz, run.ground)
    res = livny.skeletonize_graph(
        xyz,
        n_trees=go.n_trees,
        k=go.k,
        search_radius=go.search_radius,
        node_spacing=go.node_spacing,
        max_iter=go.max_iter,
        reweight=go.reweight,
        height=height,
        root_slice=go.root_slice,
        min_tree_distance=go.min_tree_distance,
        allometry_exponent=go.allometry_exponent,
        edge_weights=go.edge_weights,
        crown_partition=go.crown_partition,
        seed=run.opts.seed,
        progress=run.sub_progress(),
        neighbours=run.take_knn(),
        source=run.source,
    )
    spacing = float(res.info["node_spacing"])
    run.timings.update(dict(res.timings.items()))
    run.info.update(res.info)
    run.params.update(
        n_trees=go.n_trees,
        k=go.k,
        search_radius=go.search_radius,
        node_spacing=spacing,
        max_iter=go.max_iter,
        reweight=go.reweight,
        root_slice=go.root_slice,
        min_tree_distance=go.min_tree_distance,
        allometry_exponent=go.allometry_exponent,
        edge_weights=go.edge_weights,
        crown_partition=go.crown_partition,
    )
    t0 = time.perf_counter()
    graph = _graph_cleanup(run, res.graph, spacing)
    # the k-d tree of step ii holds the same points: no second 10⁶-point build
    graph = livny.extend_tips(graph, xyz, 2.0 * spacing, kdtree=res.kdtree)
    del res
    run.graph = livny.densify(graph, spacing)
    run.timings["t4"] = time.perf_counter() - t0
    run.timings["cleanup"] = run.timings["t4"]
    _check_skeleton(run)


def _graph_cleanup(run: _Run, graph: BranchGraph, spacing: float) -> BranchGraph:
    from biomorph.tree import cleanup as tclean

    co = run.opts.cleanup
    if co.enabled:
        mbl = TIP_LENGTH * spacing if co.min_branch_length is None else co.min_branch_length
        graph = tclean.cleanup(
            graph,
            radius_ratio=co.radius_ratio,
            length_factor=co.length_factor,
            min_length=mbl,
            overlap=co.overlap,
            min_radius=co.min_cylinder_radius,
        )
        graph = tclean.prune_small_trees(graph, 2 * spacing)
        run.params.update(
            cleanup=True,
            radius_ratio=co.radius_ratio,
            length_factor=co.length_factor,
            overlap=co.overlap,
            min_branch_length=mbl,
            min_cylinder_radius=co.min_cylinder_radius,
        )
    if co.tip_support is not None:
        assert run.cloud is not None
        graph = tclean.prune_unsupported_tips(
            graph, run.cloud.xyz, co.tip_support, TIP_SUPPORT_LENGTH * spacing
        )
        run.params.update(tip_support=co.tip_support)
    return graph


def voxel_phase(run: _Run) -> None:
    """Gorte & Pfeifer's voxel skeleton, then the false-branch rule of the cleanup."""
    from biomorph.tree import livny
    from biomorph.tree.cleanup import prune_small_trees, remove_false_branches
    from biomorph.tree.voxel import skeletonize_voxel

    assert run.cloud is not None
    vkw = run.opts.voxel.as_kwargs()
    progress = run.progress
    stems, point_tree = _stem_bases(run)
    vres = skeletonize_voxel(
        run.cloud,
        **vkw,
        stems=stems,
        stem_reach=run.opts.graph.min_tree_distance,
        point_tree=point_tree,
        progress=None if progress is None else lambda s: progress(0, s),
    )
    graph = vres.graph
    run.timings.update(
        {k: float(v) for k, v in vres.timings.items() if isinstance(v, (int, float))}
    )
    el = graph.edge_length
    spacing = float(np.median(el[el > 0])) if (el > 0).any() else 0.05
    run.params.update(voxel=vkw, node_spacing=spacing)
    if graph.tree_id is None:
        graph = graph.with_(tree_id=graph.trees)
    graph = prune_small_trees(graph, 2 * spacing)
    co = run.opts.cleanup
    if co.enabled and graph.n_nodes:
        # the voxel skeleton has no allometric radii: give it one from the points so the
        # false-branch rule can run; cylinder collapse is Livny-specific, skip it
        t0 = time.perf_counter()
        xyz = run.cloud.xyz
        d, _ = livny.skeleton_distance(xyz, graph.parent, graph.position)
        r = livny.allometric_radii(
            graph.parent,
            graph.position,
            graph.subtree_length(),
            float(np.mean(d)),
            tree=graph.trees,
            exponent=run.opts.graph.allometry_exponent,
            order=graph.order,
        )
        mbl = 1.5 * spacing if co.min_branch_length is None else co.min_branch_length
        graph = remove_false_branches(
            graph.with_(radius=r),
            radius_ratio=co.radius_ratio,
            length_factor=co.length_factor,
            min_length=mbl,
        )
        run.timings["cleanup"] = time.perf_counter() - t0
    run.graph = graph
    _check_skeleton(run)


def _stem_bases(run: _Run) -> tuple[NDArray | None, NDArray | None]:
    """XY of each stem base the graph method's step i finds in the points
    (:func:`biomorph.tree.roots.find_roots`: stems at breast height standing on the ground
    where a ground was removed), for the voxel method's trees, and with two stems or more
    the tree of each point by the graph method's crown partition (step ii's kNN graph,
    :func:`biomorph.tree.crowns.partition_trees`; stem ``i`` is tree ``i``); None where
    there is none. The graph method's checks run first: a trunk must reach the ground, and
    a one-tree run (``n_trees=1``) must hold one stem (:class:`~biomorph.errors.InputError`
    otherwise)."""
    from biomorph.tree.crowns import partition_trees
    from biomorph.tree.neighbours import (
        GAP_SHORT,
        default_node_spacing,
        neighbour_graph,
        segment_trees,
    )
    from biomorph.tree.roots import (
        check_single_tree,
        check_trunk_reaches_ground,
        find_roots,
        root_centres,
    )

    assert run.cloud is not None
    go = run.opts.graph
    xyz = run.cloud.xyz
    if xyz.shape[0] < 3:
        return None, None
    height = _height_above_ground(xyz, run.ground)
    # the graph method's bad-input rules: no trunk reaching the ground, two stems in a
    # one-tree run -- one line, not a silent wrong model
    check_trunk_reaches_ground(height, source=run.source)
    if go.n_trees == 1:
        check_single_tree(
            xyz,
            height=height,
            root_slice=go.root_slice,
            min_tree_distance=go.min_tree_distance,
            source=run.source,
        )
    pts, tree = find_roots(
        xyz,
        n_trees=go.n_trees,
        height=height,
        root_slice=go.root_slice,
        min_tree_distance=go.min_tree_distance,
        seed=run.opts.seed,
    )
    # find_roots' trees, not stem_bases' (which drops small stems for the one-tree check):
    # the voxel method gets the graph method's trees
    if not pts.size:
        return None, None
    _, tree = np.unique(tree, return_inverse=True)  # stem i is tree i
    tree = tree.reshape(-1)
    stems = root_centres(xyz, pts, tree)
    if stems.shape[0] < 2:
        return stems, None
    # the graph method's crown partition (biomorph.tree.crowns), its gap from this cloud
    gap = GAP_SHORT * default_node_spacing(run.point_spacing(), float(np.ptp(xyz[:, 2])))
    graph = neighbour_graph(xyz, k=go.k, tree=run.point_index())
    if not go.crown_partition:
        return stems, segment_trees(graph, pts, tree)
    return stems, partition_trees(xyz, graph, pts, tree, gap)[0]


def ground_base_phase(run: _Run) -> None:
    """Each stem carried down to the ground the prepare stage removed
    (:func:`biomorph.tree.roots.extend_to_ground`), node spacing the skeleton's median
    edge; ``info["ground_base"]``: trees extended, metres added."""
    from biomorph.tree.roots import extend_to_ground

    graph = run.graph
    if graph is None or run.ground is None or run.ground.n_points == 0:
        return
    el = graph.edge_length[graph.parent >= 0]
    spacing = float(np.median(el)) if el.size else 0.0
    run.graph, info = extend_to_ground(graph, run.ground.xyz, spacing)
    run.info["ground_base"] = info


def _check_skeleton(run: _Run) -> None:
    if run.graph is None or run.graph.n_nodes == 0:
        raise InputError(
            f"{run.source}: no skeleton could be built (no tree found above the ground)"
        )
    run.tick("skeleton")


def _stem_tracker(run: _Run):
    """The taper model's stem anchor: the stem followed through the points
    (:func:`biomorph.tree.stem.stem_tracks`)."""
    import functools

    from biomorph.tree.stem import stem_tracks

    assert run.cloud is not None
    spacing = run.point_spacing()
    if not spacing:
        return None
    return functools.partial(
        stem_tracks,
        xyz=run.cloud.xyz,
        spacing=spacing,
        kdtree=run.point_index(),
        seed=run.opts.seed,
        cache=run.stem_tracks,
    )


def radius_phase(run: _Run, tick: bool = True) -> None:
    """Radii from circle fits (or the allometric model), then chain smoothing."""
    from biomorph.tree import livny
    from biomorph.tree.cleanup import smooth_chains
    from biomorph.tree.radius import fit_radii

    ro = run.opts.radius
    graph, xyz = run.graph, run.cloud.xyz  # type: ignore[union-attr]
    assert graph is not None
    run.skeleton = graph
    run.radii_pending = False
    t0 = time.perf_counter()
    exponent = run.opts.graph.allometry_exponent
    if ro.method == "fit":
        run.limb_nodes = run.limb_mask(graph)
        graph, fit = fit_radii(
            graph,
            xyz,
            trusted=run.limb_nodes,
            recentre=ro.recentre,
            search_factor=ro.search_factor,
            allometry_exponent=exponent,
            taper=ro.taper,
            min_radius=ro.min_radius,
            taper_exponent=ro.taper_exponent,
            seed=run.opts.seed,
            spacing=run.point_spacing() or None,
            kdtree=run.point_index(),
            stems=_stem_tracker(run),
        )
        run.fit = fit
        run.quality = {
            "reliable": fit.reliable if fit.reliable is not None else fit.ok,
            "mad": fit.mad if fit.mad is not None else np.zeros(fit.ok.size),
            "coverage": fit.coverage,
            "fitted_radius": fit.radius,
            "segment": fit.segment if fit.segment is not None else np.zeros(fit.ok.size, bool),
        }
        run.info["radius_fit_ok"] = float(fit.ok.mean()) if fit.ok.size else 0.0
        if fit.reliable is not None:
            run.info["radius_reliable"] = float(fit.reliable.mean()) if fit.ok.size else 0.0
            run.info["taper_model"] = fit.model
    elif graph.radius is None:
        d, _ = livny.skeleton_distance(xyz, graph.parent, graph.position)
        graph = graph.with_(
            radius=livny.allometric_radii(
                graph.parent,
                graph.position,
                graph.subtree_length(),
                float(np.mean(d)),
                tree=graph.trees,
                exponent=exponent,
                order=graph.order,
            )
        )
    run.graph = smooth_chains(graph, ro.smooth)
    run.params.update(
        radius=ro.method,
        recentre=ro.recentre,
        search_factor=ro.search_factor,
        smooth=ro.smooth,
        taper=ro.taper,
        min_radius=ro.min_radius,
        taper_exponent=ro.taper_exponent,
    )
    run.timings["radius_fit"] = run.timings.get("radius_fit", 0.0) + time.perf_counter() - t0
    if tick:
        run.tick("radii")


def residual_phase(run: _Run) -> None:
    """Residual branches (:mod:`biomorph.tree.residual`): the skeleton grows into the
    pieces of wood its cylinders leave unexplained, then the radius stage runs again on
    the grown skeleton. Off with ``CleanupOptions.residual = False``
    (``--no-residual``)."""
    from biomorph.tree.residual import (
        RESIDUAL_MIN_LENGTH,
        RESIDUAL_THRESHOLD,
        residual_branches,
    )

    co = run.opts.cleanup
    run.params.update(residual=co.residual, residual_threshold=co.residual_threshold)
    if not co.residual or run.graph is None or run.graph.radius is None:
        return
    assert run.cloud is not None and run.skeleton is not None
    t0 = time.perf_counter()
    xyz = run.cloud.xyz
    ps = run.point_spacing()
    ns = float(run.params.get("node_spacing") or 0.0)
    if not (ps > 0 and ns > 0):
        return
    # --residual-threshold scales both of the module's lengths (node spacings); auto
    # (None): from the scan, finer where its twigs present a surface
    from biomorph.tree.metrics import segment_candidates

    cand = segment_candidates(run.graph, xyz, order=run.point_index().indices)
    f = co.residual_threshold
    if f is None:
        f = _residual_factor(run, ps, ns, cand)
    run.params["residual_factor"] = f
    grown, rec = residual_branches(
        run.graph,
        xyz,
        ps,
        ns,
        base=run.skeleton,
        threshold=f * RESIDUAL_THRESHOLD * ns,
        min_length=f * RESIDUAL_MIN_LENGTH * ns,
        candidates=cand,
    )
    run.info.update({f"residual_{k}": v for k, v in rec.items()})
    run.timings["residual"] = time.perf_counter() - t0
    if rec["nodes_added"]:
        run.graph = grown
        radius_phase(run, tick=False)


def _residual_factor(
    run: _Run, spacing: float, node_spacing: float, candidates: SegmentCandidates
) -> float:
    """``--residual-threshold auto``: :func:`biomorph.tree.residual.residual_factor` from
    the twig offset's surface test on the model so far and the scan's scatter about its
    stem circles (1 without circle fits or the taper model)."""
    from biomorph.tree import radius as rd
    from biomorph.tree.residual import RESIDUAL_THRESHOLD, residual_factor

    graph, fit, ro = run.graph, run.fit, run.opts.radius
    if (
        graph is None
        or fit is None
        or fit.ok.size != graph.n_nodes
        or not (ro.method == "fit" and ro.taper)
    ):
        return RESIDUAL_THRESHOLD
    assert run.cloud is not None
    measured = fit.reliable if fit.reliable is not None else fit.ok
    surface, _ = rd.twig_surface(graph, run.cloud.xyz, measured, spacing, candidates=candidates)
    scatter = rd.NOISE_PER_MAD * rd.surface_scatter(graph, fit)
    run.info["residual_surface"] = surface
    run.info["residual_scatter"] = scatter
    return residual_factor(surface, scatter, node_spacing)


def limbs_phase(run: _Run) -> None:
    """Limbs the skeleton hung the wrong way round, entered from a thin branch above and
    running down to a base that ends against the stem, turned round
    (:func:`biomorph.tree.limbs.reversed_limbs`), and stems and limbs broken by a gap in the
    scan joined across it (:func:`biomorph.tree.limbs.broken_ends`); the radius stage runs
    once more after
    :func:`detour_phase`. Needs the circle fits (``--radius fit``);
    ``CleanupOptions.reversed_limbs`` (``--reversed-limbs/--no-reversed-limbs``; on for both
    methods, the voxel one since session 27)."""
    from biomorph.tree.limbs import mend_limbs

    co = run.opts.cleanup
    on = co.reversed_limbs
    run.params.update(reversed_limbs=on)
    graph, fit, skel = run.graph, run.fit, run.skeleton
    if not on or graph is None or fit is None or skel is None:
        return
    if not (fit.radius.size == graph.n_nodes == skel.n_nodes):
        return
    t0 = time.perf_counter()
    parent, limbs, joined = mend_limbs(graph, fit)
    run.info["reversed_limbs"] = len(limbs)
    run.info["broken_ends"] = len(joined)
    run.timings["cleanup"] = run.timings.get("cleanup", 0.0) + time.perf_counter() - t0
    if limbs or joined:
        g = graph.with_(parent=parent)
        run.graph = g.with_(weight=g.subtree_length())
        s = skel.with_(parent=parent)
        run.skeleton = s.with_(weight=s.subtree_length())
        run.radii_pending = True
    if limbs:
        turned = np.concatenate([limb["nodes"] for limb in limbs])
        run.limb_points = skel.position[turned]


def empty_tips_phase(run: _Run) -> None:
    """Side tip chains through empty space (:func:`biomorph.tree.cleanup.empty_tips`,
    chains shorter than ``TIP_SUPPORT_LENGTH`` node spacings) and side branches inside
    thicker wood (:func:`biomorph.tree.cleanup.inside_wood`) pruned from the finished
    skeleton; the radius stage runs once more after :func:`detour_phase` if any went.
    Graph method only; off with ``CleanupOptions.empty_tips = False``
    (``--no-empty-tips``) and ``CleanupOptions.inside_wood = False``
    (``--no-inside-wood``)."""
    from biomorph.tree.cleanup import empty_tips, inside_wood

    co = run.opts.cleanup
    run.params.update(empty_tips=co.empty_tips, inside_wood=co.inside_wood)
    if not (co.empty_tips or co.inside_wood) or run.opts.method != "graph" or run.graph is None:
        return
    assert run.cloud is not None and run.skeleton is not None
    spacing = run.point_spacing()
    ns = float(run.params.get("node_spacing") or 0.0)
    if spacing <= 0 or ns <= 0 or run.skeleton.n_nodes != run.graph.n_nodes:
        return
    t0 = time.perf_counter()
    # judged where the radius stage put the nodes; removed from the skeleton it started
    # from (same nodes), which the radius stage then fits once more
    drop = np.zeros(run.graph.n_nodes, dtype=bool)
    if co.empty_tips:
        drop = empty_tips(
            run.graph, run.cloud.xyz, spacing, TIP_SUPPORT_LENGTH * ns, kdtree=run.point_index()
        )
        run.info["empty_tips_removed"] = int(drop[run.graph.leaves].sum())  # a tip per chain
    if co.inside_wood:
        inside = inside_wood(run.graph, spacing) & ~drop
        run.info["inside_wood_removed_m"] = float(run.graph.edge_length[inside].sum())
        drop |= inside
    removed = int(drop.sum())
    run.timings["cleanup"] = run.timings.get("cleanup", 0.0) + time.perf_counter() - t0
    if removed:
        # the radius stage runs once more after the detour search, which reads the
        # fitted skeleton less the pruned chains (its trunk, where the detours are, keeps
        # its fits; a separate pass here cost 8 % of a 10⁶-point run)
        g = run.skeleton.subgraph(~drop)
        run.skeleton = g.with_(weight=g.subtree_length())
        fitted = run.graph.subgraph(~drop)
        run.graph = fitted.with_(weight=fitted.subtree_length())
        run.radii_pending = True


def detour_phase(run: _Run) -> None:
    """Trunk detours out along a branch and back taken out of the trunk
    (:func:`biomorph.tree.cleanup.reroute_detours`: the straight way must be covered by the
    stem's points; for the graph method in slabs half the stem's radius thick, where a stem
    seen through a crown leaves a few points per point spacing) and, opt-in, hooks at
    forks straightened (:func:`biomorph.tree.cleanup.fork_hooks`,
    ``CleanupOptions.fork_hooks = True``, ``--fork-hooks``), then the radius stage once
    more if any was. Off with ``CleanupOptions.detours = False`` (``--no-detours``). The
    radius stage also runs here when :func:`empty_tips_phase` pruned chains (once for
    both)."""
    co = run.opts.cleanup
    run.params.update(detours=co.detours, fork_hooks=co.fork_hooks)
    rerouted = _detours(run, co.detours, co.fork_hooks)
    if run.radii_pending:
        if not rerouted:  # fitted again from the pruned skeleton as it entered the stage
            assert run.skeleton is not None
            run.graph = run.skeleton
        radius_phase(run, tick=False)


def _detours(run: _Run, on: bool, hooks: bool = False) -> bool:
    """:func:`detour_phase`'s search (trunk detours, then hooks at forks with ``hooks``,
    :func:`biomorph.tree.cleanup.fork_hooks`); a changed skeleton (returns True) leaves
    the radius stage pending, on the straightened skeleton."""
    from biomorph.tree import livny
    from biomorph.tree.cleanup import fork_hooks, reroute_detours

    if not (on or hooks) or run.graph is None or run.skeleton is None:
        return False
    assert run.cloud is not None
    spacing = run.point_spacing()
    ns = float(run.params.get("node_spacing") or 0.0)
    if spacing <= 0 or ns <= 0 or run.skeleton.n_nodes != run.graph.n_nodes:
        return False
    t0 = time.perf_counter()
    g, sk = run.graph, run.skeleton
    n = 0
    if on:
        parent, keep, n = reroute_detours(
            g,
            run.cloud.xyz,
            spacing,
            kdtree=run.point_index(),
            sparse=run.opts.method == "graph",
        )
        run.info["trunk_detours"] = n
        if n:
            g = g.with_(parent=parent).subgraph(keep)
            sk = sk.with_(parent=parent).subgraph(keep)
    found: list = []
    if hooks:
        parent, keep, found = fork_hooks(g, run.cloud.xyz, spacing, ns, run.point_index())
        run.info["fork_hooks"] = len(found)
        if found:
            sk = sk.with_(parent=parent).subgraph(keep)
    run.timings["cleanup"] = run.timings.get("cleanup", 0.0) + time.perf_counter() - t0
    if n or found:
        g = livny.densify(sk, ns)
        run.graph = g.with_(weight=g.subtree_length())
        run.radii_pending = True
    return bool(n or found)


def segment_phase(run: _Run) -> None:
    """The final skeleton's radii again, with the cylinders of runs of nodes where no circle
    fit is reliable (:func:`biomorph.tree.radius.segment_radii`); the earlier radius passes,
    which the cleanup rules read, use circle fits alone. ``RadiusOptions.run_cylinders``
    (``--run-cylinders/--no-run-cylinders``; on for both methods, the voxel one since
    session 27); off without the taper model."""
    from biomorph.tree import radius as rd
    from biomorph.tree.cleanup import smooth_chains

    ro = run.opts.radius
    graph, fit = run.graph, run.fit
    on = ro.run_cylinders
    run.params.update(run_cylinders=on)
    if not (on and ro.method == "fit" and ro.taper) or graph is None or fit is None:
        return
    assert run.cloud is not None
    spacing = run.point_spacing()
    if spacing <= 0 or fit.ok.size != graph.n_nodes or graph.n_nodes == 0:
        return
    t0 = time.perf_counter()
    limbs = run.limb_nodes
    radius, fit = rd.segment_radii(
        graph,
        run.cloud.xyz,
        fit,
        spacing,
        min_radius=ro.min_radius,
        exponent=ro.taper_exponent,
        kdtree=run.point_index(),
        trusted=limbs if limbs is not None and limbs.size == graph.n_nodes else None,
        stems=_stem_tracker(run),
    )
    graph_r = graph.with_(radius=radius)
    if ro.recentre and fit.segment_centre is not None:
        # the run-measured nodes onto their run's axis, as the circle fits recentre theirs
        move = np.isfinite(fit.segment_centre[:, 0])
        if move.any():
            pos = graph.position.copy()
            pos[move] = fit.segment_centre[move]
            graph_r = graph_r.with_(position=pos)
    new = smooth_chains(graph_r, ro.smooth)
    if fit.segment is not None and graph.radius is not None and new.radius is not None:
        # what the runs changed on the twigs they measured (radius within two point
        # spacings): the model's twig deficit where it could be measured, beside the
        # twig offset's estimate from every modelled twig (twig_phase)
        seg = fit.segment
        thin = seg & (graph.radius <= rd.CENTROID_MAX_RADIUS * spacing)
        shift = (new.radius - graph.radius)[thin]
        run.info["run_cylinders"] = {
            "nodes": int(seg.sum()),
            "twig_nodes": int(thin.sum()),
            "twig_shift": float(np.median(shift)) if shift.size else None,
        }
    run.graph = new
    run.fit = fit
    if run.quality is not None and fit.segment is not None:
        run.quality["segment"] = fit.segment
    run.info["taper_model"] = fit.model
    run.timings["radius_fit"] = run.timings.get("radius_fit", 0.0) + time.perf_counter() - t0


def twig_phase(run: _Run) -> None:
    """The modelled twigs' radii from their points (:func:`biomorph.tree.radius.twig_offset`),
    once the skeleton is complete (after the residual branches). Off with
    ``RadiusOptions.twig_scale = False`` (``--no-twig-scale``) or without the taper model."""
    from biomorph.tree import radius as rd
    from biomorph.tree.metrics import segment_candidates

    ro = run.opts.radius
    run.params.update(twig_scale=ro.twig_scale)
    graph, fit = run.graph, run.fit
    if not (ro.twig_scale and ro.method == "fit" and ro.taper) or graph is None or fit is None:
        return
    assert run.cloud is not None and graph.radius is not None
    t0 = time.perf_counter()
    spacing = run.point_spacing()
    if spacing <= 0 or fit.ok.size != graph.n_nodes or graph.n_nodes == 0:
        return
    measured = fit.reliable if fit.reliable is not None else fit.ok
    if fit.segment is not None:  # measured by its run's cylinder (--run-cylinders)
        measured = measured | fit.segment
    cand = segment_candidates(graph, run.cloud.xyz, order=run.point_index().indices)
    run.candidates = (graph.position, graph.parent, cand)
    # the scan's scatter, which the offset must not take for missing wood
    noise = rd.surface_scatter(graph, fit)
    radius, info = rd.twig_offset(
        graph, run.cloud.xyz, measured, spacing, candidates=cand, noise=noise
    )
    run.graph = graph.with_(radius=radius)
    run.info["twig_offset"] = info
    run.timings["radius_fit"] = run.timings.get("radius_fit", 0.0) + time.perf_counter() - t0


def order_phase(run: _Run) -> None:
    """Trunk and branch order (``depth``), segments, subtree weights and tree labels."""
    from biomorph.tree import order

    oo = run.opts.order
    graph = run.graph
    assert graph is not None
    t0 = time.perf_counter()
    run.segment = order.segments(graph, **oo.rule_kwargs())
    graph = graph.with_(depth=order.order_from_segments(graph, run.segment))
    if graph.weight is None:
        graph = graph.with_(weight=graph.subtree_length())
    if graph.tree_id is None:
        graph = graph.with_(tree_id=graph.trees)
    if oo.trunk_smooth:
        graph = order.smooth_trunk(graph, run.segment)
    if oo.trunk_taper:
        graph = order.taper_trunk(graph, run.segment)
    run.graph = graph
    run.params.update(
        trunk_smooth=oo.trunk_smooth,
        trunk_taper=oo.trunk_taper,
        order_rule=oo.rule,
        order_tie=oo.tie,
        order_share=oo.share,
        order_angle_deg=float(np.degrees(oo.angle)),
        trunk_angle_deg=float(np.degrees(oo.trunk_angle)),
    )
    run.timings["order"] = time.perf_counter() - t0
    run.tick("order")


#: the MSE is measured on at most this many points (a seeded sample): the mean converges
#: long before that
MSE_POINTS = 200_000


def metrics_phase(run: _Run) -> None:
    """NOB, TBL, MSE, DBH, trunk radius, max order, segment count, and the QSM measures
    (:func:`biomorph.tree.metrics.qsm_report`: ``classes`` volume/length per diameter
    class, ``orders`` per branch order, ``trees`` TreeQSM-style attributes, ``fit`` far
    share and signed residual per class on the MSE sample); each tree's ``kind``
    (:func:`biomorph.tree.metrics.tree_kinds`: a measured stem reaching breast height, or
    a fragment) and the counts ``n_stems`` / ``n_fragments``."""
    from biomorph.tree.metrics import (
        dbh_per_tree,
        qsm_report,
        segment_candidates,
        skeleton_metrics,
        tree_kinds,
    )

    graph, pc = run.graph, run.cloud
    assert graph is not None and pc is not None
    t0 = time.perf_counter()
    mse_cloud = pc
    if pc.n_points > MSE_POINTS:
        pick = np.random.default_rng(run.opts.seed).choice(pc.n_points, MSE_POINTS, replace=False)
        mse_cloud = pc.select(np.sort(pick))
    # the nearest skeleton edges of the sample, shared by the MSE and the cylinder fit
    # (the twig phase's, when it searched the same points on the same axes)
    pos, par, cand = run.candidates or (None, None, None)
    run.candidates = None
    same = pos is not None and np.array_equal(pos, graph.position)
    if not (mse_cloud is pc and same and np.array_equal(par, graph.parent)):
        cand = segment_candidates(graph, mse_cloud.xyz) if graph.n_nodes else None
    metrics = skeleton_metrics(graph, mse_cloud, candidates=cand)
    metrics["mse_points"] = mse_cloud.n_points
    try:
        dbhs = dbh_per_tree(graph)
        metrics["dbh"] = [None if not np.isfinite(v) else float(v) for v in np.atleast_1d(dbhs)]
    except Exception:  # noqa: BLE001 - a tree shorter than 1.3 m has no DBH
        metrics["dbh"] = None
    metrics["trunk_radius"] = [float(graph.radius[r]) for r in graph.roots]
    metrics["max_order"] = int(graph.depth.max()) if graph.n_nodes else 0
    qsm = qsm_report(graph, mse_cloud, candidates=cand)
    del cand
    attrs = {a["tree"]: a for a in qsm.pop("trees")}
    for rec in metrics["trees"]:
        rec.update(attrs.get(rec["tree"], {}))
    kinds = tree_kinds(
        graph,
        (run.quality or {}).get("reliable"),
        {int(r["tree"]): float(r.get("height", 0.0)) for r in metrics["trees"]},
    )
    for rec in metrics["trees"]:
        rec["kind"] = kinds.get(int(rec["tree"]), "tree")
    if run.fit is not None and run.fit.radius.size == graph.n_nodes:
        # the DBH as the stem's circles give it, beside the taper model's
        from biomorph.tree.radius import breast_height_fits

        bh = breast_height_fits(
            graph,
            pc.xyz,
            run.fit,
            spacing=run.point_spacing() or None,
            kdtree=run.point_index(),
            seed=run.opts.seed,
        )
        for rec in metrics["trees"]:
            b = bh.get(int(rec["tree"]))
            if b is not None:
                rec["dbh_fit"] = None if not np.isfinite(b["dbh"]) else b["dbh"]
                rec["dbh_fits"] = b["fits"]
                rec["dbh_fit_wider"] = b["wider"]
                rec["dbh_fit_band"] = b["band"]
    metrics["n_stems"] = sum(k == "tree" for k in kinds.values())
    metrics["n_fragments"] = len(kinds) - metrics["n_stems"]
    metrics.update(qsm)
    seg = run.segment
    metrics["n_segments"] = int(seg.max() + 1) if seg is not None and seg.size else 0
    run.metrics = metrics
    run.timings["metrics"] = time.perf_counter() - t0
    run.tick("metrics")
