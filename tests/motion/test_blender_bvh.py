"""Our BVH outputs in Debian's Blender (headless): three operator outputs from the CLI —
mirror of the Rokoko rig, an in-place cycle of the Xia walk, a root-motion cycle of the same
walk — imported by Blender's own importer (``tools/blender_bvh_check.py``): each imports
with no importer message, no non-finite key or bone head, and its lowest foot where our
forward kinematics puts it. Skipped with the reason when ``blender`` is not installed (or the
shared captures are absent); one Blender process, a few seconds."""

from __future__ import annotations

import json
import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest

from biomorph.cli import run
from biomorph.io.bvh import read_bvh
from tests.conftest import shared_file

BLENDER = shutil.which("blender")
SCRIPT = Path(__file__).resolve().parents[2] / "tools" / "blender_bvh_check.py"
pytestmark = pytest.mark.skipif(
    BLENDER is None,
    reason="Debian's blender is not installed (apt-get install -y blender)",
)
FEET = ("foot", "toe", "ankle", "distal")


def _lowest_foot(path: Path) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = read_bvh(path)
    idx = [i for i, n in enumerate(m.names) if any(w in n.lower() for w in FEET)]
    step = max(1, -(-m.n_frames // 150))
    return float(m.world_positions()[::step, idx, 1].min())


def test_operator_outputs_import_in_blender(tmp_path):
    dance = shared_file("motion", "ad_rokoko_jesse_dance.bvh")
    walk = shared_file("motion", "xia_neutral_01_000_walk.bvh")
    jobs = {
        "mirror.bvh": ["mirror", str(dance)],
        "in_place.bvh": ["cycle", str(walk), "--auto", "--mode", "in-place", "--cycles", "2"],
        "root_motion.bvh": ["cycle", str(walk), "--auto", "--mode", "root-motion"],
    }
    paths = []
    for name, args in jobs.items():
        p = tmp_path / name
        assert run(["motion", *args, "-o", str(p)]) == 0
        paths.append(p)
    proc = subprocess.run(
        [BLENDER, "-b", "--factory-startup", "--python", str(SCRIPT), "--", *map(str, paths)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    recs = [
        json.loads(line.split(" ", 1)[1])
        for line in proc.stdout.splitlines()
        if line.startswith("BVHCHECK ")
    ]
    assert len(recs) == len(paths), proc.stdout[-2000:] + proc.stderr[-2000:]
    for p, rec in zip(paths, recs, strict=True):
        assert rec.get("result") == ["FINISHED"], rec
        assert rec["messages"] == [] and rec["nan_keys"] == 0 and rec["nonfinite_heads"] == 0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            n = read_bvh(p).n_frames
        assert rec["frames"] in (n, n + 1)  # Blender's scene range may add one frame
        assert rec["feet"] >= 2
        ours = _lowest_foot(p)
        scale = max(1.0, abs(rec["root_z_median"] or 0.0))
        # Blender samples frames from 1 (ours from 0): the sampled minimum agrees closely
        assert np.isclose(rec["min_foot_z"], ours, atol=0.02 * scale), (p.name, rec, ours)
