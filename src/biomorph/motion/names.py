"""Joint-name conventions for the motion pillar: the presets live in
:mod:`biomorph.core.names` (the BVH reader needs them too); this module re-exports them."""

from biomorph.core.names import *  # noqa: F403
from biomorph.core.names import __all__  # noqa: F401
