"""Dataset and PCA: the seed's scheme, scaling, conditioning and reparametrisation."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.creature import pca as pc
from biomorph.creature.dataset import load_species
from biomorph.errors import FormatError, ParameterError


def test_dataset_has_the_seeds_44_species():
    t = load_species()
    assert len(t) == 44
    assert t.points.shape == (44, 10, 2) and t.lengths.shape == (44, 6)
    w = dict(zip(t.name, t.weight, strict=True))
    assert w["blue_whale"] == 120000 and w["frog"] == 0.01 and w["rock_hyrax"] == 4
    assert set(t.legs) <= {0.0, 2.0, 4.0} and set(t.wings) <= {0.0, 1.0}
    # every winged animal is a bird; the non-bird bipeds are the seed's four
    assert all(c == "bird" for c, wg in zip(t.cls, t.wings, strict=True) if wg)
    bipeds = {n for n, c, lg in zip(t.name, t.cls, t.legs, strict=True) if lg == 2 and c != "bird"}
    assert bipeds == {"sea_lion", "harbour_seal", "tyrannosaurus", "kangaroo"}
    assert np.all((t.points >= 0) & (t.points <= 1000))
    # missing neck repeats the back's first point (snake, whales, fish)
    i = t.index("snake")
    assert np.all(t.points[i, :4] == t.points[i, 3]) and np.all(t.points[i, 6:] == t.points[i, 6])


def test_malformed_csv_names_line_and_column(tmp_path):
    src = load_species()
    rows = src.rows()
    import csv

    p = tmp_path / "bad.csv"
    with p.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows[:5]:
            w.writerow(r)
        bad = dict(rows[5], weight_kg="heavy")
        w.writerow(bad)
    with pytest.raises(FormatError, match=r"bad.csv:7: column 'weight_kg'"):
        load_species(p)


def test_encode_uses_the_seeds_exact_scaling():
    pts = np.arange(20.0).reshape(1, 10, 2) * 10
    x = pc.encode(pts, [[100, 200, 300, 400, 500, 600]], [1], [2], [120000.0])[0]
    assert x[0] == 0.0 and x[19] == 0.19
    assert np.allclose(x[20:26], [0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    assert x[26] == 1 / 100 and x[27] == 2 / 4 / 100
    assert np.isclose(x[28], np.log(120001) / np.log(120001) / 100)
    back = pc.decode(x)
    assert np.allclose(back["weight"], 120000.0) and np.allclose(back["points"], pts)


def test_reparametrised_end_points_round_trip():
    t = load_species()
    x = pc.encode(t.points, t.lengths, t.wings, t.legs, t.weight, reparam=True)
    d = pc.decode(x, reparam=True)
    assert np.allclose(d["points"], t.points)
    i = t.index("giraffe")
    assert np.allclose(x[i, :2] * 1000, t.points[i, 0] - t.points[i, 3])


def test_pca_reconstruction_and_spectrum():
    p = pc.fit_dataset(reparam=False)
    assert np.all(np.diff(p.eigenvalues) <= 1e-12)
    t = load_species()
    x = pc.encode(t.points, t.lengths, t.wings, t.legs, t.weight)
    assert np.allclose(p.reconstruct(p.project(x)), x)
    s = pc.spectrum_summary(p)
    assert 0.3 < s["total"] < 0.9 and s["six_components"] > 0.85


def test_conditional_sampling_fixes_dims_within_jitter():
    p = pc.fit_dataset(reparam=True)
    rng = np.random.default_rng(1)
    legs = pc.DIM["legs"]
    for _ in range(20):
        x = p.sample_conditional(rng, {legs: 0.01, pc.DIM["weight"]: pc.weight_to_feature(50)})
        assert abs(x[legs] - 0.01) <= pc.jitter_halfwidth(legs) + 1e-9
    # without jitter the conditioned value is met exactly and others still vary
    xs = np.array([p.sample_conditional(rng, {legs: 0.005}, jitter=0.0) for _ in range(10)])
    assert np.allclose(xs[:, legs], 0.005, atol=1e-6)
    assert xs[:, 0].std() > 1e-4


def test_bad_pca_parameters():
    p = pc.fit_dataset()
    with pytest.raises(ParameterError):
        p.sample(np.random.default_rng(0), k=40)
    with pytest.raises(ParameterError, match="weight"):
        pc.weight_to_feature(-3)


def test_conditional_matches_textbook_gaussian_conditioning():
    p = pc.fit_dataset(reparam=True)
    cov = p.components @ np.diag(p.eigenvalues) @ p.components.T
    A = [pc.DIM["legs"], pc.DIM["weight"], 0, 1]
    a = p.mean[A] + np.array([0.003, -0.002, 0.05, -0.03])
    m, S = p.conditional(dict(zip(A, a, strict=True)))
    x_mean = p.mean + p.components @ m
    B = [i for i in range(pc.N_DIMS) if i not in A]
    gain = cov[np.ix_(B, A)] @ np.linalg.inv(cov[np.ix_(A, A)])
    expect = p.mean[B] + gain @ (a - p.mean[A])
    assert np.allclose(x_mean[B], expect, atol=1e-6)
    assert np.allclose(x_mean[A], a, atol=1e-6)
    cond_cov = p.components @ S @ p.components.T
    expect_cov = cov[np.ix_(B, B)] - gain @ cov[np.ix_(A, B)]
    assert np.allclose(cond_cov[np.ix_(B, B)], expect_cov, atol=1e-8)
