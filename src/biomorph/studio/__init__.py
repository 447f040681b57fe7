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

from typing import Any

__all__ = ["Sandbox", "SandboxError", "StudioApp"]


def __getattr__(name: str) -> Any:
    if name == "StudioApp":
        from biomorph.studio.server import StudioApp

        return StudioApp
    if name in ("Sandbox", "SandboxError"):
        from biomorph.studio import sandbox

        return getattr(sandbox, name)
    raise AttributeError(f"module 'biomorph.studio' has no attribute {name!r}")
