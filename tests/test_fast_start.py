"""``biomorph --help`` and ``biomorph <pillar> --help`` load no numeric stack (fast start).

The CLI modules import only typer, rich and ``biomorph._cli`` at import time; each command
imports its pillar inside the function. Timings are in ``bench/cli.py``; this test checks the
cause (which modules load), which does not depend on the machine's load.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

HEAVY = (
    "numpy",
    "scipy",
    "numba",
    "matplotlib",
    "trimesh",
    "dask",
    "distributed",
    "viser",
    "laspy",
    "pygltflib",
    "mujoco",
)

PROBE = """
import sys
from biomorph.cli import run
try:
    run({argv!r})
except SystemExit:
    pass
heavy = sorted({{m.split('.')[0] for m in sys.modules}} & set({heavy!r}))
print('HEAVY=' + ','.join(heavy))
"""


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["creature", "--help"],
        ["tree", "--help"],
        ["motion", "--help"],
        ["leaf", "--help"],
        ["studio", "--help"],
    ],
)
def test_help_loads_no_numeric_stack(argv):
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(argv=argv, heavy=HEAVY)],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    marks = [ln for ln in out.stdout.splitlines() if ln.startswith("HEAVY=")]
    assert marks, out.stdout + out.stderr
    heavy = marks[-1].removeprefix("HEAVY=")
    assert heavy == "", f"biomorph {' '.join(argv)} imported {heavy}"


@pytest.mark.parametrize(
    "argv,group",
    [
        (["motion", "info", "x.bvh"], "motion"),
        (["studio", "--help"], "studio"),
        (["info", "x.bvh"], ""),
        (["--help"], None),
        (["--help", "info"], None),
        ([], None),
        (["nope"], None),
    ],
)
def test_a_call_builds_only_the_group_it_runs(argv, group):
    from biomorph.cli import _selected_group

    assert _selected_group(argv) == group
