"""``biomorph demo``: run every pillar on built-in data and write an HTML report."""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

from biomorph.errors import ParameterError
from biomorph.pillars import PILLARS, optional_module
from biomorph.report import Section, Table, write_report


def run_demo(out_dir: str | Path, only: Sequence[str] | None = None) -> Path:
    """Run each available pillar's ``run_demo(out_dir)``; write ``out_dir/report.html``."""
    unknown = sorted(set(only or ()) - set(PILLARS))
    if unknown:
        raise ParameterError(
            f"unknown pillar {', '.join(unknown)}; expected some of {', '.join(PILLARS)}"
        )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sections: list[Section] = []
    timings: list[tuple[str, str]] = []
    from biomorph.foundation_demo import run_demo as core_demo

    sections.extend(core_demo(out / "core"))
    for pillar in PILLARS:
        if only and pillar not in only:
            continue
        mod = optional_module(pillar, "demo")
        if mod is None:
            continue
        t0 = time.perf_counter()
        sections.extend(mod.run_demo(out / pillar))
        timings.append((pillar, f"{time.perf_counter() - t0:.2f}"))
    if timings:
        sections.append(Section("Run times", tables=[Table(["pillar", "seconds"], timings)]))
    return write_report(out / "report.html", sections, title="biomorph demo")
