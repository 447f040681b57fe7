"""PCA over the species annotations, Gaussian sampling and conditional sampling (seed §4).

Feature vector (29 dims, the seed's order and scaling):

====  ===========================  ================================================
dims  content                      scaling
====  ===========================  ================================================
0-19  ten spine control points     px / 1000 (x, y interleaved: p0x p0y … p9x p9y)
20-25 limb-segment lengths         px / 1000 (upper arm, lower arm, hand, thigh, shank, foot)
26    wings (0/1)                  / 1 / 100
27    legs with ground contact     / 4 / 100
28    weight w (kg)                log(w + 1) / log(120000 + 1) / 100
====  ===========================  ================================================

With ``reparam=True`` the neck's head end p0 is stored as the offset p0 − p3 and the tail tip
p9 as p9 − p6 (seed §4.5) so neck and tail extent are linear dims that can be conditioned.

Sampling draws latent scores ``z ~ N(0, T·Λ_k)`` for the top ``k`` components (temperature
``T``); conditioning on any subset of dims (or on PC scores) uses the Gaussian conditional of
``z`` given the linear constraints, i.e. conditional mean ``Λ Hᵀ (H Λ Hᵀ)⁻¹ h`` and Schur
complement covariance — for ``k = 29`` exactly the conditional of the full Gaussian in data
space. Fixed values are jittered uniformly within a small interval first (the seed's remedy
for the low variety of conditioned samples; the seed leaves the interval open — ours is
``JITTER`` below, scaled by ``jitter``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.errors import ParameterError

N_DIMS = 29
MAX_WEIGHT = 120000.0  # kg, blue whale (seed)
SMALL = 100.0  # extra divisor of weight, wings and legs (seed)
LOG_MAX = float(np.log(MAX_WEIGHT + 1.0))

DIM_NAMES: tuple[str, ...] = tuple(f"p{i}{c}" for i in range(10) for c in "xy") + (
    "upper_arm",
    "lower_arm",
    "hand",
    "upper_leg",
    "lower_leg",
    "foot",
    "wings",
    "legs",
    "weight",
)
DIM = {n: i for i, n in enumerate(DIM_NAMES)}
NECK_OFFSET = (0, 1)  # p0 - p3 when reparametrised
TAIL_OFFSET = (18, 19)  # p9 - p6 when reparametrised

#: Half-widths of the uniform jitter on conditioned values, in raw units
#: (px for coordinates/lengths, 0/1 for wings, legs count, relative for weight).
JITTER = {"px": 10.0, "wings": 0.2, "legs": 0.4, "weight": 0.15}


def encode(
    points: ArrayLike,
    lengths: ArrayLike,
    wings: ArrayLike,
    legs: ArrayLike,
    weight: ArrayLike,
    reparam: bool = False,
) -> NDArray[np.float64]:
    """Scaled feature vectors ``(n, 29)`` from raw annotations (px, 0/1, count, kg)."""
    pts = np.array(points, dtype=float).reshape(-1, 10, 2)
    if reparam:
        pts[:, 0] -= pts[:, 3]
        pts[:, 9] -= pts[:, 6]
    n = pts.shape[0]
    w = np.asarray(weight, dtype=float).reshape(n)
    if np.any(w < 0):
        raise ParameterError(f"weight {w.min()} kg is negative; expected > 0 kg")
    x = np.empty((n, N_DIMS))
    x[:, :20] = pts.reshape(n, 20) / 1000.0
    x[:, 20:26] = np.asarray(lengths, dtype=float).reshape(n, 6) / 1000.0
    x[:, 26] = np.asarray(wings, dtype=float).reshape(n) / SMALL
    x[:, 27] = np.asarray(legs, dtype=float).reshape(n) / 4.0 / SMALL
    x[:, 28] = np.log(w + 1.0) / LOG_MAX / SMALL
    return x


def decode(x: ArrayLike, reparam: bool = False) -> dict[str, NDArray[np.float64]]:
    """Raw annotations from feature vectors: points (n,10,2) px, lengths (n,6) px, wings,
    legs (continuous; read as probabilities by the generator), weight kg."""
    x = np.asarray(x, dtype=float).reshape(-1, N_DIMS)
    n = x.shape[0]
    pts = (x[:, :20] * 1000.0).reshape(n, 10, 2)
    if reparam:
        pts[:, 0] += pts[:, 3]
        pts[:, 9] += pts[:, 6]
    return {
        "points": pts,
        "lengths": x[:, 20:26] * 1000.0,
        "wings": x[:, 26] * SMALL,
        "legs": x[:, 27] * SMALL * 4.0,
        "weight": np.expm1(np.clip(x[:, 28] * SMALL, -1.0, 2.0) * LOG_MAX),
    }


def weight_to_feature(weight: float) -> float:
    """Scaled PCA value of a weight in kg (raises on negative weight)."""
    if not np.isfinite(weight) or weight <= 0:
        raise ParameterError(f"weight {weight} kg is not positive; expected a weight > 0 kg")
    return float(np.log(weight + 1.0) / LOG_MAX / SMALL)


def jitter_halfwidth(dim: int) -> float:
    """Half-width of the conditioning jitter for ``dim`` in scaled units."""
    if dim < 26:
        return JITTER["px"] / 1000.0
    if dim == 26:
        return JITTER["wings"] / SMALL
    if dim == 27:
        return JITTER["legs"] / 4.0 / SMALL
    return float(np.log1p(JITTER["weight"])) / LOG_MAX / SMALL


@dataclass(frozen=True, eq=False)
class PCA:
    """Principal components of scaled feature vectors.

    Attributes: ``mean (29,)``, ``eigenvalues (29,)`` descending, ``components (29, 29)``
    with eigenvectors in columns, ``scores (n, 29)`` of the training data, ``reparam``.
    """

    mean: NDArray[np.float64]
    eigenvalues: NDArray[np.float64]
    components: NDArray[np.float64]
    scores: NDArray[np.float64]
    reparam: bool = False

    @classmethod
    def fit(cls, x: ArrayLike, reparam: bool = False) -> PCA:
        """Eigen-decomposition of the sample covariance (``ddof = 1``) of ``x (n, d)``."""
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[0] < 3:
            raise ParameterError(f"PCA needs at least 3 samples of shape (n, d); got {x.shape}")
        mean = x.mean(axis=0)
        cov = np.cov(x, rowvar=False)
        vals, vecs = np.linalg.eigh(cov)
        order = np.argsort(vals)[::-1]
        vals = np.clip(vals[order], 0.0, None)
        vecs = vecs[:, order]
        # deterministic sign: largest-magnitude entry of each eigenvector positive
        sign = np.sign(vecs[np.argmax(np.abs(vecs), axis=0), np.arange(vecs.shape[1])])
        vecs = vecs * np.where(sign == 0, 1.0, sign)
        scores = (x - mean) @ vecs
        return cls(mean, vals, vecs, scores, reparam)

    @property
    def n_dims(self) -> int:
        return int(self.mean.shape[0])

    def _k(self, k: int | None) -> int:
        if k is None:
            return self.n_dims
        if not 1 <= k <= self.n_dims:
            raise ParameterError(f"number of components k={k} outside 1..{self.n_dims}")
        return int(k)

    def explained(self) -> NDArray[np.float64]:
        """Cumulative fraction of variance explained by the first 1..d components."""
        return np.cumsum(self.eigenvalues) / self.eigenvalues.sum()

    def project(self, x: ArrayLike, k: int | None = None) -> NDArray[np.float64]:
        """Scores ``(n, k)`` of feature vectors on the top ``k`` components."""
        k = self._k(k)
        return (np.asarray(x, dtype=float) - self.mean) @ self.components[:, :k]

    def reconstruct(self, z: ArrayLike) -> NDArray[np.float64]:
        """Feature vectors from scores on the first ``z.shape[-1]`` components."""
        z = np.asarray(z, dtype=float)
        k = z.shape[-1]
        return self.mean + z @ self.components[:, :k].T

    def sample(
        self, rng: np.random.Generator, n: int = 1, k: int | None = None, temperature: float = 1.0
    ) -> NDArray[np.float64]:
        """``n`` feature vectors from the Gaussian on the top ``k`` components."""
        k = self._k(k)
        if not temperature >= 0:
            raise ParameterError(f"temperature {temperature} must be >= 0")
        z = rng.standard_normal((n, k)) * np.sqrt(temperature * self.eigenvalues[:k])
        return self.reconstruct(z)

    @cached_property
    def _score_std(self) -> NDArray[np.float64]:
        return np.sqrt(np.maximum(self.eigenvalues, 1e-12))

    def nearest(
        self, x: ArrayLike, n_neighbours: int = 3, k: int = 6
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Indices and inverse-distance weights of the training samples nearest to ``x`` in
        whitened top-``k`` score space (used to inherit class, stance, skull, counts)."""
        k = min(self._k(k), self.n_dims)
        z = self.project(np.atleast_2d(x), k)[0] / self._score_std[:k]
        d = np.linalg.norm(self.scores[:, :k] / self._score_std[:k] - z, axis=1)
        idx = np.argsort(d)[:n_neighbours]
        w = 1.0 / (d[idx] + 1e-6)
        return idx, w / w.sum()

    def conditional(
        self,
        fixed: Mapping[int, float] | None = None,
        scores: Mapping[int, float] | None = None,
        k: int | None = None,
        temperature: float = 1.0,
        rng: np.random.Generator | None = None,
        jitter: float = 1.0,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Mean and covariance of the latent scores ``z (k,)`` given fixed feature dims
        (``{dim: scaled value}``) and/or fixed PC scores (``{component: score}``).

        With ``rng`` the fixed feature values are first jittered uniformly by
        ``± jitter × jitter_halfwidth(dim)``.
        """
        dims, comps, vals, k = self._conditions(fixed, scores, k, rng, jitter)
        lam = temperature * self.eigenvalues[:k]
        if not vals:
            return np.zeros(k), np.diag(lam)
        gain, cov, _, _ = self._factor(dims, comps, k, float(temperature))
        return gain @ np.array(vals), np.array(cov)

    def _conditions(self, fixed, scores, k, rng, jitter) -> tuple[tuple, tuple, list, int]:
        """Checked conditioned dims / components and their (jittered) values, in order."""
        k = self._k(k)
        dims, comps, vals = [], [], []
        for dim, val in (fixed or {}).items():
            if not 0 <= dim < self.n_dims:
                raise ParameterError(f"conditioned dim {dim} outside 0..{self.n_dims - 1}")
            v = float(val)
            if rng is not None and jitter > 0:
                h = jitter * jitter_halfwidth(dim)
                v += rng.uniform(-h, h)
            dims.append(int(dim))
            vals.append(v - self.mean[dim])
        for comp, val in (scores or {}).items():
            if not 0 <= comp < k:
                raise ParameterError(f"conditioned component {comp} outside 0..{k - 1}")
            comps.append(int(comp))
            vals.append(float(val))
        return tuple(dims), tuple(comps), vals, k

    @lru_cache(maxsize=64)  # noqa: B019 - keyed by the (immutable) model and which dims
    def _factor(self, dims: tuple, comps: tuple, k: int, temperature: float):
        """Gain ``Λ Hᵀ S⁻¹``, conditional covariance and its eigen-decomposition for the
        conditioned dims/components — they do not depend on the conditioned values, so one
        decomposition serves every sample with the same conditions (the generator's
        ``--legs``/``--class``/``--weight`` runs)."""
        lam = temperature * self.eigenvalues[:k]
        rows = [self.components[d, :k] for d in dims]
        for c in comps:
            e = np.zeros(k)
            e[c] = 1.0
            rows.append(e)
        if not rows:
            cov = np.diag(lam)
            gain = np.zeros((k, 0))
        else:
            h_mat = np.array(rows)
            lh = lam[:, None] * h_mat.T  # Λ Hᵀ  (k, m)
            s = h_mat @ lh  # H Λ Hᵀ (m, m)
            s = s + np.eye(len(rows)) * (1e-9 * max(float(np.trace(s)) / len(rows), 1e-12))
            gain = np.linalg.solve(s, lh.T).T  # Λ Hᵀ S⁻¹ (k, m)
            cov = np.diag(lam) - gain @ lh.T
            cov = 0.5 * (cov + cov.T)
        ev, vecs = np.linalg.eigh(cov)
        for a in (gain, cov, ev, vecs):
            a.flags.writeable = False
        return gain, cov, ev, vecs

    def sample_conditional(
        self,
        rng: np.random.Generator,
        fixed: Mapping[int, float] | None = None,
        scores: Mapping[int, float] | None = None,
        k: int | None = None,
        temperature: float = 1.0,
        jitter: float = 1.0,
    ) -> NDArray[np.float64]:
        """One feature vector ``(29,)`` from the conditional Gaussian (jittered fixed values)."""
        dims, comps, vals, k = self._conditions(fixed, scores, k, rng, jitter)
        gain, _, ev, vecs = self._factor(dims, comps, k, float(temperature))
        mean = gain @ np.array(vals) if vals else np.zeros(k)
        z = mean + vecs @ (np.sqrt(np.clip(ev, 0.0, None)) * rng.standard_normal(len(mean)))
        return self.reconstruct(z)


def fit_dataset(table=None, reparam: bool = True) -> PCA:
    """PCA of a :class:`~biomorph.creature.dataset.SpeciesTable` (default: built-in)."""
    from biomorph.creature.dataset import load_species

    t = load_species() if table is None else table
    return PCA.fit(encode(t.points, t.lengths, t.wings, t.legs, t.weight, reparam), reparam)


#: The seed's reported spectrum (thesis §4.4 / issue): first eigenvalue, total, 6-comp share.
SEED_SPECTRUM = {
    "first": 0.349,
    "total": 0.583,
    "six_components": 0.922,
    "above_0.01": 7,
    "smallest": 0.000024,
}


def spectrum_summary(pca: PCA) -> dict[str, float]:
    """Our spectrum in the seed's terms (to print beside :data:`SEED_SPECTRUM`)."""
    ev = pca.eigenvalues
    return {
        "first": float(ev[0]),
        "total": float(ev.sum()),
        "six_components": float(pca.explained()[5]),
        "above_0.01": int((ev > 0.01).sum()),
        "smallest": float(ev[-1]),
    }
