"""The four pillars and optional access to their per-pillar modules (CLI groups, demos)."""

from __future__ import annotations

import importlib
from types import ModuleType

PILLARS = ("creature", "tree", "motion", "leaf")


def optional_module(package: str, module: str) -> ModuleType | None:
    """``biomorph.<package>.<module>`` if that package and module exist, else ``None``.

    Only a missing package or module counts as absent: an import error *inside* an existing
    module is a bug and propagates.
    """
    try:
        return importlib.import_module(f"biomorph.{package}.{module}")
    except ModuleNotFoundError as exc:
        if exc.name not in (f"biomorph.{package}", f"biomorph.{package}.{module}"):
            raise
        return None
