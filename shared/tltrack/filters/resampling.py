"""Systematic resampling (Kitagawa 1996), batched over runs.

One uniform u ~ U[0, 1) per run places N evenly spaced pointers (u + i) / N on that run's weight
CDF. Each run is searched on its own, so a run's ancestors never depend on the batch around it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray


def systematic_indices(
    w: NDArray[np.float64], rngs: Sequence[np.random.Generator]
) -> NDArray[np.intp]:
    """Ancestor indices (B, N) for normalised weights ``w`` (B, N), one draw from each run's stream."""
    B, N = w.shape
    cdf = np.cumsum(w, axis=1)
    cdf[:, -1] = 1.0  # round-off must not leave the last pointer past the end
    base = np.arange(N) / N
    idx = np.empty((B, N), dtype=np.intp)
    for b, g in enumerate(rngs):
        idx[b] = np.searchsorted(cdf[b], base + g.random() / N, side="right")
    return np.minimum(idx, N - 1, out=idx)
