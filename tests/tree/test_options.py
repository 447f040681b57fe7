"""tree/options.py: one typed options object shared by API, CLI and batch (issue 12)."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from biomorph.cli import run
from biomorph.errors import ParameterError
from biomorph.tree.options import (
    AttributeFilter,
    GraphOptions,
    OrderOptions,
    SkeletonizeOptions,
    cli_fields,
)


def test_legacy_keywords_map_onto_the_stages():
    o = SkeletonizeOptions.from_kwargs(
        "voxel",
        seed=3,
        k=12,
        order_angle=1.0,
        cleanup=False,
        voxel={"cell_size": 0.05},
        filter={"name": "Deviation", "max_value": 50},
    )
    assert o.method == "voxel" and o.seed == 3 and o.graph.k == 12
    assert o.order.angle == 1.0 and o.cleanup.enabled is False
    assert o.voxel.as_kwargs() == {"cell_size": 0.05}
    assert o.prepare.filter == AttributeFilter("Deviation", max_value=50)
    with pytest.raises(ParameterError, match="unknown option 'kk'"):
        SkeletonizeOptions.from_kwargs(kk=3)
    with pytest.raises(ParameterError, match="unknown method"):
        SkeletonizeOptions(method="magic")
    with pytest.raises(ParameterError, match="order rule"):
        SkeletonizeOptions(order=OrderOptions(rule="tallest"))


def test_cli_values_convert_units_and_flags():
    o = SkeletonizeOptions.from_cli(
        {
            "order.angle": 90.0,
            "prepare.ground": False,
            "prepare.foliage": 0.0,
            "prepare.filter": "Dev:1:5",
            "graph.k": 7,
        },
        method="graph",
        seed=2,
    )
    assert o.order.angle == pytest.approx(math.pi / 2)
    assert o.prepare.ground is None and o.prepare.foliage is None and o.graph.k == 7
    assert o.prepare.filter == AttributeFilter("Dev", min_value=1.0, max_value=5.0)
    assert SkeletonizeOptions.from_cli({"prepare.foliage": None}).prepare.foliage == "auto"
    with pytest.raises(ParameterError, match="--filter"):
        AttributeFilter.parse("Deviation")
    flags = [spec.flag for _, _, spec in cli_fields()]
    assert len(flags) == len(set(flags)) and "--order-rule" in flags and "--taper" in flags


def test_defaults_are_one_object():
    o = SkeletonizeOptions()
    assert o.graph == GraphOptions() and o.replace(seed=4).seed == 4
    assert o.to_dict()["order"]["rule"] == "supported"


def test_options_module_loads_no_numeric_stack():
    code = (
        "import sys, biomorph.tree.options, biomorph.tree.cli; "
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'scipy', 'numba'}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "[]"


def test_batch_takes_every_skeletonize_option(tmp_path, capsys):
    import numpy as np

    from tests.tree.test_livny import make_cloud

    cloud = tmp_path / "t.xyz"
    np.savetxt(cloud, make_cloud(n=3000, seed=8), fmt="%.6f")
    out = tmp_path / "b"
    code = run(
        [
            "tree",
            "batch",
            str(cloud),
            "--out",
            str(out),
            "--workers",
            "0",
            "--json",
            "--no-ground",
            "--order-rule",
            "angle",
            "--order-angle",
            "60",
            "--k",
            "8",
        ]
    )
    assert code == 0, capsys.readouterr().err
    params = json.loads((out / "t" / "summary.json").read_text())["params"]
    assert params["order_rule"] == "angle" and params["order_angle_deg"] == pytest.approx(60)
    assert params["k"] == 8
    assert run(["tree", "batch", str(cloud), "--out", str(out), "--order-tie", "0"]) == 2
