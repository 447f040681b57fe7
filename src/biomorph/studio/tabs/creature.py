"""Creature tab (waits for the creature pillar's API)."""

from __future__ import annotations

import importlib

from biomorph.studio.base import StudioTab


class CreatureTab(StudioTab):
    """Placeholder until the creature pillar lands."""

    key = "creature"
    label = "Creature"

    def requirement(self) -> str | None:
        try:
            importlib.import_module("biomorph.creature")
        except ImportError as exc:
            return f"the creature pillar cannot be imported ({exc})"
        return "the creature tab is being built"
