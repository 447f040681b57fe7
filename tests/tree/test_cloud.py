"""Cloud preparation: validation, centring, filtering, downsampling, outliers, prepare."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError
from biomorph.tree.cloud import (
    canonical_order,
    centre,
    coordinate_lattice,
    downsample,
    filter_attribute,
    has_ground,
    point_spacing,
    prepare,
    remove_outliers,
    validate_cloud,
)
from biomorph.tree.synthetic import generate_tree, simulate_scan


def _blob(n=500, seed=0, offset=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(seed)
    return PointCloud(
        rng.normal(size=(n, 3)) + np.asarray(offset),
        source="blob.xyz",
        attributes={"dev": rng.uniform(0, 10, n)},
    )


@pytest.mark.parametrize(
    "xyz, word",
    [
        (np.zeros((0, 3)), "empty"),
        (np.ones((1, 3)), "1 point"),
        (np.random.default_rng(0).normal(size=(5, 3)), "5 points"),
        (np.c_[np.random.default_rng(0).normal(size=(50, 2)), np.zeros(50)], "coplanar"),
        (np.outer(np.arange(50.0), [1, 2, 3]), "one line"),
        (np.ones((50, 3)), "one line"),
    ],
)
def test_validate_rejects_bad_clouds(xyz, word):
    with pytest.raises(InputError, match=word) as e:
        validate_cloud(PointCloud(xyz, source="bad.laz"))
    assert "bad.laz" in str(e.value)


def test_validate_rejects_nan():
    xyz = np.random.default_rng(0).normal(size=(50, 3))
    xyz[7, 1] = np.nan
    with pytest.raises(InputError, match="point 7 .*non-finite"):
        validate_cloud(PointCloud(xyz, source="nan.xyz"))


def test_centre_keeps_world_coordinates_georeferenced():
    c = _blob(offset=(512345.678, 5401234.567, 300.0))
    c2 = centre(c)
    lo, hi = c2.bounds()
    assert abs(lo[2]) < 1e-12 and abs(lo[0] + hi[0]) < 1e-5 and abs(lo[1] + hi[1]) < 1e-5
    np.testing.assert_allclose(c2.world_xyz, c.world_xyz, rtol=0, atol=1e-9)
    c3 = centre(c2)  # idempotent-ish, offsets accumulate
    np.testing.assert_allclose(c3.world_xyz, c.world_xyz, rtol=0, atol=1e-9)
    assert c.offset.sum() == 0  # input untouched


def test_a_grid_snapped_cloud_centres_to_the_same_coordinates_wherever_it_lies():
    """A scan stored in millimetres (a LAS scale of 0.001, three decimals in a text file)
    lies on a lattice; the same scan moved by a georeferencing offset centres to the very
    same coordinates (float subtraction left 1e-9 m of round-off, which broke exact ties
    between grid-snapped distances differently)."""
    rng = np.random.default_rng(3)
    local = np.round(rng.uniform(-2, 2, (2000, 3)) + (0, 0, 2), 3)
    a = PointCloud(local)
    b = PointCloud(local + (512345.678, 5401234.567, 300.0))  # rounded where it lands
    assert not np.array_equal(b.xyz - b.xyz.min(0), a.xyz - a.xyz.min(0))
    np.testing.assert_array_equal(coordinate_lattice(a), [1e-3] * 3)
    np.testing.assert_array_equal(coordinate_lattice(b), [1e-3] * 3)
    ca, cb = centre(a), centre(b)
    np.testing.assert_array_equal(ca.xyz, cb.xyz)  # bit for bit
    steps = prepare(b, outliers=False, ground=None).steps
    assert steps["centre"]["lattice"] == [1e-3] * 3 and "order" in steps
    np.testing.assert_allclose(cb.world_xyz, b.xyz, rtol=0, atol=1e-8)
    lo, hi = ca.bounds()
    assert lo[2] == 0 and abs(lo[0] + hi[0]) <= 1e-3 and abs(lo[1] + hi[1]) <= 1e-3
    # off any lattice (a float32 export, a simulated scan): per axis NaN, plain centring
    assert np.isnan(coordinate_lattice(_blob())).all()
    mixed = PointCloud(np.c_[local[:, :2], rng.normal(size=2000)])
    lat = coordinate_lattice(mixed)
    assert lat[0] == lat[1] == 1e-3 and np.isnan(lat[2])


def test_the_canonical_order_is_the_same_for_any_order_of_the_file():
    c = _blob(n=3000)
    a = canonical_order(c)
    b = canonical_order(c.select(np.random.default_rng(1).permutation(c.n_points)))
    np.testing.assert_array_equal(a.xyz, b.xyz)
    np.testing.assert_array_equal(a.attributes["dev"], b.attributes["dev"])
    assert not np.array_equal(a.xyz, c.xyz)  # reordered, attributes along
    i = int(np.flatnonzero((c.xyz == a.xyz[0]).all(axis=1))[0])
    assert a.attributes["dev"][0] == c.attributes["dev"][i]
    # spatially coherent (a Z-order curve): consecutive points are neighbours, not a shuffle
    step = np.linalg.norm(np.diff(a.xyz, axis=0), axis=1)
    assert np.median(step) < 0.25 * np.median(np.linalg.norm(np.diff(c.xyz, axis=0), axis=1))
    assert canonical_order(c.select(np.arange(1))).n_points == 1


def test_filter_attribute():
    c = _blob()
    f = filter_attribute(c, "dev", max_value=5)
    assert (f.attributes["dev"] <= 5).all() and 0 < f.n_points < c.n_points
    with pytest.raises(ParameterError, match="no attribute 'Deviation'"):
        filter_attribute(c, "Deviation", max_value=1)


@pytest.mark.parametrize("method", ["ratio", "voxel", "centroid"])
def test_downsample_methods_deterministic(method):
    c = _blob(5000)
    kw = {"ratio": 0.3} if method == "ratio" else {"voxel_size": 0.5, "ratio": 0.3}
    a = downsample(c, method, seed=3, **kw)
    b = downsample(c, method, seed=3, **kw)
    assert np.array_equal(a.xyz, b.xyz)
    assert 0 < a.n_points < c.n_points
    if method == "ratio":
        assert a.n_points == 1500
    if method == "centroid":  # one point per occupied voxel
        keys = np.unique(np.floor((c.xyz - c.xyz.min(0)) / 0.5), axis=0)
        assert a.n_points == keys.shape[0]


def test_downsample_bad_parameters():
    c = _blob()
    with pytest.raises(ParameterError, match="ratio"):
        downsample(c, "ratio", ratio=1.5)
    with pytest.raises(ParameterError, match="voxel_size"):
        downsample(c, "voxel")
    with pytest.raises(ParameterError, match="method"):
        downsample(c, "nope", ratio=0.5)


def test_remove_outliers_drops_far_points():
    c = _blob(2000)
    xyz = np.vstack([c.xyz, [[50, 50, 50], [-40, 10, 0]]])
    out, keep = remove_outliers(PointCloud(xyz), return_mask=True)
    assert not keep[-1] and not keep[-2] and keep[:-2].mean() > 0.9


def test_remove_outliers_keeps_a_sparsely_sampled_twig():
    """A twig sampled every 5 cm beside a stem sampled every 1 cm fails the global
    statistic but is as sparse as its own neighbours: kept. Isolated returns are not."""
    rng = np.random.default_rng(0)
    th, z = rng.uniform(0, 2 * np.pi, 6000), rng.uniform(0, 2, 6000)
    stem = np.column_stack([0.08 * np.cos(th), 0.08 * np.sin(th), z])
    s = np.arange(1, 25) * 0.05
    twig = np.column_stack([0.08 + s, np.zeros_like(s), 1.0 + 0.5 * s])
    stray = np.array([[0.5, 0.5, 0.3], [-0.6, 0.2, 1.7], [0.3, -0.7, 0.9]])
    xyz = np.vstack([stem, twig, stray])
    _, keep = remove_outliers(PointCloud(xyz), return_mask=True, local_ratio=2.0)
    assert keep[6000:6024].mean() >= 0.9
    assert not keep[-3:].any()
    _, keep = remove_outliers(PointCloud(xyz), return_mask=True)  # default: global only
    assert keep[6000:6024].mean() < 0.5


def test_point_spacing_grid():
    g = np.stack(np.meshgrid(*[np.arange(10) * 0.02] * 3), -1).reshape(-1, 3)
    assert point_spacing(PointCloud(g)) == pytest.approx(0.02)


def test_has_ground_and_prepare_removes_ground():
    truth = generate_tree("aspen", seed=1)
    scan = simulate_scan(truth, n_points=6000, seed=1)
    nog = scan.select(~scan.attributes["is_ground"])
    assert has_ground(scan) and not has_ground(nog)
    p = prepare(scan, outliers=False)
    assert p.ground is not None and "ground" in p.steps
    # almost all true ground removed, almost all wood kept
    assert p.cloud.attributes["is_ground"].mean() < 0.02
    assert p.cloud.n_points > 0.9 * nog.n_points
    p2 = prepare(nog, downsample=0.5)
    assert p2.ground is None and p2.steps["downsample"]["points_out"] == nog.n_points // 2
    assert list(p2.steps) == [
        "centre",
        "order",
        "duplicates",
        "downsample",
        "outliers",
        "ground",
    ]


def test_prepare_georeferenced_filter_and_no_tree():
    truth = generate_tree("aspen", seed=0)
    scan = simulate_scan(truth, n_points=5000, seed=0)
    geo = scan.with_(
        offset=np.array([512345.0, 5401234.0, 250.0]),
        attributes={**scan.attributes, "Deviation": np.random.default_rng(0).integers(0, 60, 5000)},
    )
    p = prepare(geo, filter={"name": "Deviation", "max_value": 40}, outliers=False)
    assert (p.cloud.attributes["Deviation"] <= 40).all()
    np.testing.assert_allclose(
        p.cloud.world_xyz.min(axis=0)[:2],
        geo.world_xyz[~geo.attributes["is_ground"]].min(axis=0)[:2],
        atol=0.5,
    )
    assert abs(p.cloud.offset[0] - 512345.0) < 20  # the offset carries the georeference
    rng = np.random.default_rng(1)
    lawn = PointCloud(
        np.c_[rng.uniform(0, 10, (4000, 2)), 0.02 * rng.normal(size=4000)], source="lawn.las"
    )
    with pytest.raises(InputError, match="no tree above the ground"):
        prepare(lawn)


def test_exact_duplicates_are_dropped_before_any_density_is_measured():
    from biomorph.tree.cloud import duplicate_points

    rng = np.random.default_rng(3)
    xyz = rng.normal(size=(500, 3))
    twice = np.vstack([xyz, xyz[::-1], xyz[:10]])  # merged scans writing their overlap again
    dup = duplicate_points(twice)
    # the first of each copy stays, every later one goes; near-duplicates are not copies
    assert not dup[:500].any() and dup[500:].all()
    near = xyz.copy()
    near[:, 0] = np.nextafter(near[:, 0], np.inf)
    assert not duplicate_points(np.vstack([xyz, near])).any()
    assert not duplicate_points(xyz[:1]).any() and duplicate_points(np.zeros((0, 3))).size == 0
    p = prepare(PointCloud(twice), outliers=False, ground=None)
    assert p.cloud.n_points == 500 and p.steps["duplicates"]["points_out"] == 500
    # a hash collision is compared coordinate by coordinate, never taken for a copy
    from biomorph.tree import cloud as cloud_mod

    orig = cloud_mod._HASH
    try:
        cloud_mod._HASH = np.zeros(3, dtype=np.uint64)  # every point the same key
        dup = duplicate_points(np.vstack([xyz[:50], xyz[:50]]))
        assert not dup[:50].any() and dup[50:].all()
    finally:
        cloud_mod._HASH = orig


def test_a_cloud_written_twice_gives_the_same_model(tmp_path):
    from biomorph.tree.pipeline import skeletonize
    from tests.tree.test_livny import make_cloud

    cloud = make_cloud(n=3000, seed=4)
    one = skeletonize(cloud, ground=None)
    two = skeletonize(np.vstack([cloud, cloud]), ground=None)
    assert two.info["prepare"]["duplicates"]["points_out"] == len(cloud)
    assert two.info["point_spacing"] == pytest.approx(one.info["point_spacing"])
    assert two.graph.n_nodes == one.graph.n_nodes
    assert np.allclose(two.graph.radius, one.graph.radius)


def test_the_spacing_of_a_cloud_on_a_grid_does_not_jump_between_grid_steps():
    from biomorph.tree.neighbours import smooth_median

    # nearest-neighbour distances of a cloud snapped to a 1 cm grid (lidR's
    # voxelize_points, the TreeLS spruce): 1, sqrt 2 and sqrt 3 cm only, the median on a step
    steps = np.array([0.01, np.sqrt(2) * 0.01, np.sqrt(3) * 0.01])
    rng = np.random.default_rng(0)

    def grid(shares):
        return rng.permutation(np.repeat(steps, (np.asarray(shares) * 10_000).astype(int)))

    a, b = grid([0.30, 0.19, 0.51]), grid([0.30, 0.21, 0.49])  # 2 % of the points moved
    assert np.median(a) == pytest.approx(steps[2]) and np.median(b) == pytest.approx(steps[1])
    assert abs(smooth_median(a) - smooth_median(b)) < 0.1 * (steps[2] - steps[1])
    assert steps[1] < smooth_median(a) < steps[2]
    # a continuous spread: the median itself
    d = rng.rayleigh(0.01, 5000)
    assert smooth_median(d) == float(np.median(d)) and smooth_median(np.array([])) == 0.0


def test_the_files_own_classes_are_read_noise_dropped_and_ground_used():
    # a scan classified by a processing chain (lidR, PDAL, LAStools): ground class 2,
    # noise classes 7 / 18, and withheld points
    from biomorph.tree.cloud import flagged_points

    truth = generate_tree("aspen", seed=1)
    scan = simulate_scan(truth, n_points=6000, seed=1)
    is_ground = scan.attributes["is_ground"].astype(bool)
    rng = np.random.default_rng(2)
    far = rng.uniform([-20, -20, 10], [20, 20, 40], (60, 3))  # birds, multipath: far off
    xyz = np.vstack([scan.xyz, far])
    cls = np.r_[np.where(is_ground, 2, 1), np.full(30, 7), np.full(30, 18)].astype(np.uint8)
    held = np.zeros(len(xyz), dtype=bool)
    held[:5] = True
    cloud = PointCloud(xyz, {"classification": cls, "withheld": held})
    flagged = flagged_points(cloud)
    assert flagged[-60:].all() and flagged[:5].all() and flagged.sum() == 65
    p = prepare(cloud, outliers=False)
    assert p.steps["flagged"]["points_out"] == len(xyz) - 65
    assert p.steps["ground"]["method"] == "classified"
    # the ground is the file's: every class-2 point (not withheld), nothing else
    assert p.ground.n_points == int(is_ground[5:].sum())
    assert (p.cloud.attributes["classification"] == 1).all()
    # without a classification: the detected ground, as before
    plain = prepare(PointCloud(scan.xyz), outliers=False)
    assert plain.steps["ground"]["method"] == "grid" and "flagged" not in plain.steps
    # "classified" asked of a file without classes: a clear error
    from biomorph.tree.ground import remove_ground

    with pytest.raises(InputError, match="needs a classification per point"):
        remove_ground(PointCloud(scan.xyz, source="x.xyz"), method="classified")
    # a file of noise only: nothing left, said so
    with pytest.raises(InputError, match="classified as noise"):
        prepare(PointCloud(far, {"classification": np.full(60, 7, np.uint8)}))
