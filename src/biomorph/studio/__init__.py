"""biomorph studio: the four pillars in the browser (viser), thin over the Python API.

Start it with ``biomorph studio --data DIR`` or from Python::

    from biomorph.studio import StudioApp
    app = StudioApp("data", port=8080)
    print(app.start())   # URL
    ...
    app.stop()

The names load lazily, so ``biomorph studio --help`` imports no numeric stack.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {"StudioApp": "server", "Sandbox": "sandbox", "SandboxError": "sandbox"}
__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    mod = _WHERE.get(name)
    if mod is None:
        raise AttributeError(f"module 'biomorph.studio' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"biomorph.studio.{mod}"), name)
    globals()[name] = value
    return value
