"""Typed states of the generator's steps (spine → girdles → limbs → skull → finish).

Each step returns one frozen dataclass (the girdles step a tuple of
:class:`~biomorph.creature.girdles.Girdle`); later steps read earlier states and never
mutate them, so :class:`~biomorph.creature.generator.Generator` can keep them for undo.
All lengths are in the seed's frame units (px of the 1000-px annotation frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.random.bit_generator import ISeedSequence
from numpy.typing import NDArray

from biomorph.creature.options import STEPS


@dataclass(frozen=True, eq=False)
class SpineState:
    """The sampled body plan: spine Bézier control points (frame px, head on the left),
    limb lengths, weight, discrete choices and what is inherited from the nearest species."""

    points: NDArray[np.float64]  # (10, 2) control points, frame px
    lengths: NDArray[np.float64]  # (6,) upper arm, lower arm, hand, thigh, shank, foot
    weight: float  # kg
    wings: bool
    legs: int
    cls: str
    stance: str  # plantigrade | digitigrade | unguligrade
    posture: str  # erect | crouched | sprawling
    skull: str  # skull library entry
    skull_length: float  # px
    girth: float
    counts: NDArray[np.int64]  # vertebrae per region (neck, back, tail)
    neighbours: list[str]
    features: NDArray[np.float64]  # the sampled 29-dim feature vector
    wings_value: float  # decoded (continuous) wings and legs values
    legs_value: float
    nearest: str
    hoof_digits: int = 0  # hoofed digits per foot (unguligrade: 1 horse, 2 cattle), else 0


@dataclass(frozen=True, eq=False)
class LimbsState:
    """Grounded legs and posed free limbs (creature px: x forward, y up, z right)."""

    points: NDArray[np.float64]  # (10, 2) spine control points, creature px
    ground: float  # ground height (px)
    places: list[tuple[str, int, Any, float]]  # (girdle, pair index, LimbSpec, arc length)
    attach: list[tuple[NDArray, NDArray]]  # (spine point, limb attachment) per pair
    lengths: list[NDArray[np.float64]]  # (3,) segment lengths per pair
    poses: list[Any]  # limbs.LimbPose per pair (right side)
    shifts: dict[str, float]  # balance-repair girdle shifts


@dataclass(frozen=True, eq=False)
class SkullState:
    """The chosen skull: library shape, length (px), pitch (rad) and origin (creature px)."""

    shape: str
    length: float
    angle: float
    origin: NDArray[np.float64]


def step_rng(seed: int, step: str, roll: int) -> np.random.Generator:
    """The random stream of one step (seed, step index, re-roll count): a fresh generator
    seeded like ``np.random.default_rng([seed, step, roll])`` (the seed sequence's state,
    whose hashing is most of the cost, is memoised; balance repair asks for the same stream
    again and again)."""
    return np.random.Generator(
        np.random.PCG64(_seed_sequence(int(seed) & 0xFFFFFFFF, STEPS.index(step), int(roll)))
    )


class _StateOf(ISeedSequence):
    """A seed sequence's generated state, memoised: :class:`numpy.random.PCG64` reads its
    four words (``generate_state(4, uint64)``) and nothing else, so the stream is the one
    ``SeedSequence([seed, step, roll])`` gives, without hashing it again per generator."""

    __slots__ = ("_ss", "_words")

    def __init__(self, ss: np.random.SeedSequence) -> None:
        self._ss = ss
        self._words = ss.generate_state(4, np.uint64)
        self._words.setflags(write=False)

    def generate_state(self, n_words: int, dtype=np.uint32) -> NDArray:
        if n_words == 4 and np.dtype(dtype) == np.uint64:
            return self._words.copy()
        return self._ss.generate_state(n_words, dtype)


@lru_cache(maxsize=1024)
def _seed_sequence(seed: int, step: int, roll: int) -> _StateOf:
    return _StateOf(np.random.SeedSequence([seed, step, roll]))
