"""Shaded 3-D renders: PNGs with shading, skin changes the picture, CLI and bad input."""

from __future__ import annotations

import numpy as np
import pytest

import biomorph.creature as bc
from biomorph.creature.render import Layer, _camera, _shade, render_creature


def _png(path):
    from matplotlib.image import imread

    return imread(str(path))


def test_lambert_shading_follows_the_light():
    # a face turned to the light is brighter than one turned away
    right, up, back = _camera("side")
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0], [0, 1, 0], [0, 0.5, 1.0]], float)
    f = np.array([[0, 1, 2], [3, 4, 5]])
    _, rgba, _ = _shade(Layer(v, f, np.ones(3), cull=False), right, up, back)
    assert rgba[0, :3].mean() != pytest.approx(rgba[1, :3].mean())
    with pytest.raises(Exception, match="view"):
        _camera("sideways")


def test_render_skeleton_and_skin(tmp_path):
    c = bc.generate(seed=3)
    bones = render_creature(c, tmp_path / "b.png", skin=False, lod=0)
    img = _png(bones)
    assert img.shape[1] > img.shape[0]  # two views side by side
    grey = img[..., :3].mean(axis=2)
    drawn = grey < 0.97
    assert 0.01 < drawn.mean() < 0.6
    assert np.std(grey[drawn]) > 0.03  # shaded, not flat
    full = _png(render_creature(c, tmp_path / "s.png", skin=True, lod=0, views=("three_quarter",)))
    assert full.shape[0] > 2 * full.shape[1] * 0.9  # three rows: bones, x-ray, skin
    red = (full[..., 0] - full[..., 2]) > 0.2
    assert red.mean() > 0.005  # muscles and skin tones appear


def test_render_cli(tmp_path, capsys):
    from biomorph.cli import run

    out = tmp_path / "c.png"
    assert (
        run(["creature", "render", "--seed", "1", "--no-skin", "--lod", "0", "-o", str(out)]) == 0
    )
    assert out.stat().st_size > 10_000
    assert run(["creature", "render", "-o", str(tmp_path / "c.jpg")]) == 2
    assert run(["creature", "render", "--view", "up", "-o", str(tmp_path / "d.png")]) == 2
    err = capsys.readouterr().err
    assert "expected one of .png" in err and "--view 'up'" in err
    assert not (tmp_path / "c.jpg").exists() and not (tmp_path / "d.png").exists()
