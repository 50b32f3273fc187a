"""Array aliases for annotations: numpy arrays by dtype (shapes are given in the docstrings)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: float64 values: positions [m], directions, weights, delays [s] ...
FloatArray = NDArray[np.float64]
#: int64 indices: links, primitives, receivers, orders ...
IntArray = NDArray[np.int64]
#: boolean masks
BoolArray = NDArray[np.bool_]
