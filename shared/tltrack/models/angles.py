"""Angles: wrapping to (-pi, pi] and circular means.

Every difference of two angles is wrapped: a track crossing the +-pi cut would otherwise give a
2 pi innovation. A mean of angles is circular, for the same reason.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


def wrap_angle(a: Array | float) -> Array:
    """Wrap to (-pi, pi]."""
    w = np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2.0 * np.pi)
    return w


def circular_mean(a: Array, axis: int) -> Array:
    """The angle of the mean unit vector of the angles ``a`` along ``axis``."""
    return np.arctan2(np.sin(a).mean(axis=axis), np.cos(a).mean(axis=axis))
