"""Square roots of singular process-noise covariances.

The seed's white-noise-acceleration Q_v (T^4/4, T^3/2, T^2 blocks per axis) has rank 1 per
position/velocity pair, so it has no Cholesky factor. Its exact square root is the column
``sqrt(q) [T^2/2, T]'`` per axis (docs/background.md, "parameter traps"): sampling draws only
``rank`` standard normals, and nothing ever needs Q_v^-1.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter

Array = NDArray[np.float64]

#: the seed's two noise intensities (Table 1); each motion model declares those it reads
Q1 = Parameter("q1", "m^2/s^4", "acceleration noise: its variance per axis", ge=0)
Q2 = Parameter("q2", "rad^2/s^3", "turn-rate noise: Q_v's turn-rate entry is q2 T", ge=0)


def wna_sqrt(T: float, q: float) -> Array:
    """Square root of one axis' white-noise-acceleration block q [[T^4/4, T^3/2], [T^3/2, T^2]]."""
    return np.sqrt(q) * np.array([[T * T / 2.0], [T]])
