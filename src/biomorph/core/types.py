"""Type aliases shared by every layer (one definition instead of one per module).

``Array`` is a float64 ndarray, ``IntArray`` an int64 one, ``PathLike`` anything naming a
file. Importing this module costs only numpy's typing stubs.
"""

from __future__ import annotations

import os
from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray

Array: TypeAlias = NDArray[np.float64]
IntArray: TypeAlias = NDArray[np.int64]
PathLike: TypeAlias = str | os.PathLike[str]

__all__ = ["Array", "IntArray", "PathLike"]
