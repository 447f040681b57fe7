"""Tree tab (waits for the tree pillar's API)."""

from __future__ import annotations

import importlib

from biomorph.studio.base import StudioTab


class TreeTab(StudioTab):
    """Placeholder until the tree pillar lands."""

    key = "tree"
    label = "Tree"

    def requirement(self) -> str | None:
        try:
            importlib.import_module("biomorph.tree")
        except ImportError as exc:
            return f"the tree pillar cannot be imported ({exc})"
        return "the tree tab is being built"
