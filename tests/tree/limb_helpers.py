"""Builders shared by the limb tests (reversed limbs, broken ends): skeleton chains along
straight lines, circle fits that measured every node, and the noisy scan condition."""

from __future__ import annotations

import numpy as np

from biomorph.tree.radius import RadiusFit

STEP = 0.05
#: the truth table's "8 mm + occlusion" condition (bench/tree.py), for pipeline tests
NOISY = dict(noise=0.008, occlusion=True, scanners=2, leaves=0.05)


def line(a, b, step: float = STEP) -> np.ndarray:
    """Points every ``step`` (m) from ``a`` (excluded) to ``b`` (included)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    k = max(int(np.ceil(np.linalg.norm(b - a) / step)), 1)
    return a + (b - a) * (np.arange(1, k + 1) / k)[:, None]


def measured_fit(radius: np.ndarray, scatter: np.ndarray | None = None) -> RadiusFit:
    """Every node measured at ``radius`` (× ``scatter``): full coverage, tight circles; a
    radius ≤ 0 is a node without a circle."""
    r = radius * (1.0 if scatter is None else scatter)
    n = r.size
    pos = np.maximum(r, 1e-3)
    return RadiusFit(
        centre=np.zeros((n, 3)),
        radius=r,
        inliers=np.full(n, 40),
        coverage=np.ones(n),
        ok=np.ones(n, bool),
        search_radius=2 * pos,
        mad=0.02 * pos,
    )


def noisy_scan(preset: str, seed: int, n_points: int):
    """``(truth, cloud)``: the preset scanned with ground in the noisy condition."""
    from biomorph.tree.synthetic import generate_tree, simulate_scan

    truth = generate_tree(preset, seed=seed)
    return truth, simulate_scan(truth, n_points=n_points, seed=seed, ground=True, **NOISY)
