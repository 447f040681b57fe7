"""Motion tab (waits for the motion pillar's API)."""

from __future__ import annotations

import importlib

from biomorph.studio.base import StudioTab


class MotionTab(StudioTab):
    """Placeholder until the motion pillar lands."""

    key = "motion"
    label = "Motion"

    def requirement(self) -> str | None:
        try:
            importlib.import_module("biomorph.motion")
        except ImportError as exc:
            return f"the motion pillar cannot be imported ({exc})"
        return "the motion tab is being built"
