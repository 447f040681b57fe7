"""biomorph studio: the four pillars in the browser (viser), thin over the Python API.

Start it with ``biomorph studio --data DIR`` or from Python::

    from biomorph.studio import StudioApp
    app = StudioApp("data", port=8080)
    print(app.start())   # URL
    ...
    app.stop()
"""

from biomorph.studio.sandbox import Sandbox, SandboxError
from biomorph.studio.server import StudioApp

__all__ = ["Sandbox", "SandboxError", "StudioApp"]
