"""Issue 12 seams of the creature pillar: typed step states, a read-only species model, the
dataset spectrum the generator samples from, plots without global matplotlib state."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from biomorph.cli import run
from biomorph.creature.generator import Generator, Options
from biomorph.creature.model import species_model
from biomorph.creature.pca import spectrum_summary
from biomorph.creature.states import LimbsState, SkullState, SpineState


def test_species_model_arrays_are_read_only():
    m = species_model(None)
    for arr in (
        m.pca.mean,
        m.pca.components,
        m.pca.eigenvalues,
        m.pca.scores,
        m.feats,
        m.region_len,
        m.table.points,
        m.table.weight,
        m.cls_scores["mammal"],
    ):
        with pytest.raises(ValueError):
            arr[...] = 0.0
    with pytest.raises(TypeError):
        m.cls_scores["mammal"] = None  # type: ignore[index]
    assert species_model(None) is m


def test_steps_return_typed_states():
    g = Generator(Options(seed=5, legs=4))
    for _ in range(4):
        g.step()
    assert isinstance(g.state("spine"), SpineState)
    assert isinstance(g.state("limbs"), LimbsState)
    assert isinstance(g.state("skull"), SkullState)
    assert g.state("spine").legs == 4 and np.shape(g.state("spine").points) == (10, 2)


def test_dataset_prints_the_spectrum_the_generator_samples_from(capsys):
    assert run(["creature", "dataset", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    want = spectrum_summary(species_model(None).pca)
    assert d["spectrum"]["first"] == pytest.approx(want["first"], rel=1e-12)
    assert d["spectrum"]["total"] == pytest.approx(want["total"], rel=1e-12)


def test_plots_leave_no_pyplot_or_backend_behind(tmp_path):
    code = (
        "import sys, matplotlib; b = matplotlib.get_backend();"
        "from biomorph.creature.plots import pca_plot;"
        f"pca_plot({str(tmp_path / 'p.png')!r});"
        "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot loaded';"
        "assert matplotlib.get_backend() == b"
    )
    r = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={"MPLBACKEND": "svg", "PATH": ""},
    )
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
