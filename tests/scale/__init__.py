"""Tests of biomorph.scale. The tiny work functions live here (an importable module) so
dask worker processes can unpickle them by reference."""

from __future__ import annotations

import time

import numpy as np


def square_stats(seed: int) -> dict[str, float]:
    """A small deterministic job: statistics of seeded random numbers."""
    x = np.random.default_rng(seed).normal(size=200)
    return {"seed": seed, "mean": float(x.mean()), "sumsq": float((x**2).sum())}


def fail_on_three(seed: int) -> int:
    """Raises for item 3, squares the others."""
    if seed == 3:
        raise ValueError(f"item {seed} is cursed")
    return seed * seed


def slow(seed: int) -> int:
    """Sleeps half a second (to be interrupted)."""
    time.sleep(0.5)
    return seed


def die_on_two(seed: int) -> int:
    """Kills its worker process for item 2 (a segfault stand-in); returns the seed otherwise."""
    if seed == 2:
        import os

        os._exit(13)
    return seed


def staged_outputs(item: tuple[str, int]) -> int:
    """Writes two files per item, atomically, with pauses before, between and inside the
    writes (a stand-in for summary.json then preview.png) so a SIGKILL can land anywhere."""
    from pathlib import Path

    from biomorph.io.atomic import atomic_path

    out, i = item
    for name in ("first", "second"):
        with atomic_path(Path(out) / f"{i}.{name}") as tmp:
            tmp.write_bytes(bytes([i]) * 1000)
            time.sleep(0.1)
        time.sleep(0.1)
    return i
