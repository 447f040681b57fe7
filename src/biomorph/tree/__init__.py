"""Tree skeletons from LiDAR point clouds (seed 001: graph and voxel methods, extensions).

>>> import biomorph as bm
>>> skel = bm.tree.skeletonize("scan.laz", method="graph")    # doctest: +SKIP
>>> bm.tree.export_skeleton(skel, "out/")                      # doctest: +SKIP

Modules: :mod:`~biomorph.tree.cloud` (preparation), :mod:`~biomorph.tree.ground`,
:mod:`~biomorph.tree.livny` (graph method), :mod:`~biomorph.tree.voxel` /
:mod:`~biomorph.tree.thinning` (voxel method), :mod:`~biomorph.tree.radius`,
:mod:`~biomorph.tree.order`, :mod:`~biomorph.tree.cleanup`, :mod:`~biomorph.tree.metrics`,
:mod:`~biomorph.tree.synthetic`, :mod:`~biomorph.tree.export`,
:mod:`~biomorph.tree.reference`, :mod:`~biomorph.tree.pipeline`,
:mod:`~biomorph.tree.options` (one typed options dataclass per stage),
:mod:`~biomorph.tree.qsm` (TreeQSM tables), :mod:`~biomorph.tree.models` (several models
of one cloud). Names are imported lazily.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    # pipeline
    "skeletonize": "pipeline",
    "TreeSkeleton": "pipeline",
    "load_cloud": "pipeline",
    # one typed options object per stage
    "SkeletonizeOptions": "options",
    "PrepareOptions": "options",
    "GraphOptions": "options",
    "VoxelOptions": "options",
    "CleanupOptions": "options",
    "RadiusOptions": "options",
    "OrderOptions": "options",
    "AttributeFilter": "options",
    # QSM tables and measures
    "branch_table": "qsm",
    "treedata_table": "qsm",
    "taper_radii": "radius",
    "volume_by_class": "metrics",
    "volume_by_order": "metrics",
    "tree_attributes": "metrics",
    "cylinder_fit": "metrics",
    "qsm_report": "metrics",
    # several models of one cloud: the volume's spread, the nearest model
    "reconstruct_models": "models",
    "Models": "models",
    # graph method and extensions
    "skeletonize_graph": "livny",
    "LivnyResult": "livny",
    "allometric_radii": "livny",
    "cleanup_skeleton": "cleanup",
    "collapse_overlaps": "cleanup",
    "remove_false_branches": "cleanup",
    "fit_radii": "radius",
    "branch_order": "order",
    "segments": "order",
    # exports and references
    "export_skeleton": "export",
    "tube_mesh": "export",
    "cylinder_table": "export",
    "read_qsm_csv": "reference",
    "compare_to_reference": "reference",
    # tree A: preparation, ground, voxel method, synthetic trees, metrics
    "prepare": "cloud",
    "PreparedCloud": "cloud",
    "validate_cloud": "cloud",
    "centre": "cloud",
    "downsample": "cloud",
    "remove_outliers": "cloud",
    "point_spacing": "cloud",
    "filter_attribute": "cloud",
    "remove_ground": "ground",
    "skeletonize_voxel": "voxel",
    "VoxelSkeleton": "voxel",
    "generate_tree": "synthetic",
    "simulate_scan": "synthetic",
    "PRESETS": "synthetic",
    "skeleton_metrics": "metrics",
    "compare_to_truth": "metrics",
    "dbh": "metrics",
    "volume": "metrics",
}


def __getattr__(name: str) -> Any:
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module 'biomorph.tree' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"biomorph.tree.{mod}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


__all__ = sorted(_EXPORTS)
