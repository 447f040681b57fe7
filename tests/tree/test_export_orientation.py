"""Exported tube GLB stands upright in glTF's Y-up frame; grid ground filter is NaN-free."""

from __future__ import annotations

import warnings

import numpy as np
import pygltflib

from biomorph.core.pointcloud import PointCloud
from biomorph.tree.export import export_skeleton
from biomorph.tree.ground import remove_ground
from biomorph.tree.pipeline import skeletonize
from tests.tree.test_livny import make_cloud


def test_tube_glb_is_y_up(tmp_path) -> None:
    skel = skeletonize(make_cloud(n=3000, seed=5), ground=None)
    files = export_skeleton(skel, tmp_path, formats=("glb",))
    doc = pygltflib.GLTF2().load(str(files["glb"]))
    accessor = doc.accessors[doc.meshes[0].primitives[0].attributes.POSITION]
    extent = np.asarray(accessor.max) - np.asarray(accessor.min)
    # the tree is taller (cloud Z) than wide; in glTF that height must be along +Y
    assert extent[1] == max(extent)
    z = skel.graph.position[:, 2]
    assert extent[1] > 0.9 * (z.max() - z.min())


def test_grid_ground_filter_with_empty_cells_has_no_nan_warning() -> None:
    rng = np.random.default_rng(0)
    # two ground strips 14 m apart: the grid between them has windows with no cell at all
    strip = np.c_[
        rng.uniform(0, 3, (2000, 1)), rng.uniform(0, 10, (2000, 1)), rng.normal(0, 0.01, 2000)
    ]
    ground = np.vstack([strip, strip + [17.0, 0.0, 0.0]])
    stem = np.c_[1.5 + 0.1 * rng.normal(size=(800, 2)) + [0.0, 3.5], rng.uniform(0, 8, 800)]
    cloud = PointCloud(np.vstack([ground, stem]))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        vegetation, mask = remove_ground(cloud, method="grid")
    assert mask[: len(ground)].mean() > 0.9
    assert vegetation.xyz[:, 2].max() > 7.0
