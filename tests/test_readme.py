"""Every ``python`` code block of the README runs as written (in a temporary folder)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)


def test_readme_has_python_examples():
    assert BLOCKS


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_block_runs(index, tmp_path):
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        namespace: dict = {}
        exec(compile(BLOCKS[index], f"README.md block {index}", "exec"), namespace)
    finally:
        os.chdir(cwd)
    # every file or folder the block names in a string literal now exists
    named = re.findall(
        r"\"([\w./-]+\.(?:glb|laz|las|ply|bvh|obj|csv|png)|[\w-]+/)\"", BLOCKS[index]
    )
    missing = [n for n in named if not (tmp_path / n).exists()]
    assert not missing, f"README block {index} did not write {missing}"
