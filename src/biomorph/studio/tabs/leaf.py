"""Leaf tab (waits for the leaf pillar's API)."""

from __future__ import annotations

import importlib

from biomorph.studio.base import StudioTab


class LeafTab(StudioTab):
    """Placeholder until the leaf pillar lands."""

    key = "leaf"
    label = "Leaf"

    def requirement(self) -> str | None:
        try:
            importlib.import_module("biomorph.leaf")
        except ImportError as exc:
            return f"the leaf pillar cannot be imported ({exc})"
        return "the leaf tab is being built"
