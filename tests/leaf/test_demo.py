"""The leaf demo runs on built-in presets and produces its pictures and files."""

from __future__ import annotations

import pytest

from biomorph.leaf.demo import run_demo


@pytest.mark.slow
def test_demo_sections(tmp_path) -> None:
    sections = run_demo(tmp_path / "leaf")
    titles = " ".join(s.title for s in sections)
    for word in ("growing", "plastic", "levels of detail", "field", "light"):
        assert word in titles
    for sec in sections:
        for f in [*sec.images, *sec.files]:
            assert f.exists() and f.stat().st_size > 0
    lod = next(s for s in sections if "levels of detail" in s.title)
    budgets = [row[0] for row in lod.tables[0].rows]
    assert budgets == [row[1] for row in lod.tables[0].rows]  # triangle count = budget
