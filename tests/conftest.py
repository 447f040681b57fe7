"""Shared fixtures: the real-data folder (skipped with a reason when absent), tmp outputs."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

#: Real data (trees, motion, leaves) lives beside the project, never inside it.
SHARED_DATA = Path(
    os.environ.get("BIOMORPH_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)


def shared_file(*parts: str) -> Path:
    """Path to a file in ``../shared/data``; skips the test with a clear reason if absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(
            f"real data not available: {path} is absent "
            "(set BIOMORPH_SHARED_DATA to the shared data folder)"
        )
    return path


@pytest.fixture
def shared_data() -> Path:
    """The shared real-data folder; skips when absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder {SHARED_DATA} is absent")
    return SHARED_DATA
