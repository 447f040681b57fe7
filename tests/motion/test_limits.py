"""Sizes and values the motion commands refuse up front (issue 18 items 2-3)."""

from __future__ import annotations

import pytest

from biomorph.cli import run
from biomorph.io import read_bvh, write_bvh
from biomorph.motion.synthetic import walk


@pytest.fixture
def walk_bvh(tmp_path):
    return write_bvh(tmp_path / "walk.bvh", walk(120, 60))


@pytest.mark.parametrize("speed", ["1e-300", "0:1,60:1e-300", "0:1,60:nan"])
def test_speed_that_would_explode_the_clip_is_refused(walk_bvh, tmp_path, capsys, speed):
    out = tmp_path / "o.bvh"
    assert run(["motion", "speed", str(walk_bvh), "-o", str(out), "--speed", speed]) == 2
    err = capsys.readouterr().err
    assert "--speed" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("curve", ["nan", "1.5", "0:0,60:nan"])
def test_blend_weight_outside_0_1_is_refused(walk_bvh, tmp_path, capsys, curve):
    out = tmp_path / "o.bvh"
    assert (
        run(["motion", "blend", str(walk_bvh), str(walk_bvh), "-o", str(out), "--curve", curve])
        == 2
    )
    assert "--curve" in capsys.readouterr().err
    assert not out.exists()


def test_frames_header_beyond_the_file_is_never_allocated(walk_bvh, capsys):
    text = walk_bvh.read_text()
    head, _, rest = text.partition("Frames:")
    walk_bvh.write_text(head + "Frames: 99999999999" + rest[rest.index("\n") :])
    with pytest.warns(Warning):
        mo = read_bvh(walk_bvh)  # tolerant: the rows that are there
    assert mo.n_frames == 120
    assert run(["motion", "info", str(walk_bvh), "--strict"]) == 2
    assert "hold at most" in capsys.readouterr().err
