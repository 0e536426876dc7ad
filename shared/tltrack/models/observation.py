"""A Gaussian statement about h(x_k): a raw measurement or a transferred predicted observation.

The TL-PF (seed, eq. for w_k^(i)) multiplies the particle weights by one Gaussian likelihood per
such statement: the primary's own z_k with Q_w, and the source's eta_hat_k with P_eta_eta,k. Raw
measurements and transfers therefore share one type, so that isolated, transfer, multi-source and
centralized-fusion filters are the same filter fed different lists.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tltrack.models.base import MeasurementModel

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Observation:
    """N(mean; h(x), cov) for a batch: ``mean`` is (n_z, B), ``cov`` is (B, n_z, n_z).

    ``mask`` (B,) marks the runs the statement applies to; a run without it is left untouched,
    which is how a missing transfer becomes an isolated step for that run alone. ``origin`` names
    the source operator of a transfer, so that its record follows it whichever others arrive.
    """

    sensor: MeasurementModel
    mean: Array
    cov: Array
    mask: NDArray[np.bool_] | None = None
    origin: str | None = None

    @classmethod
    def broadcast(cls, sensor: MeasurementModel, mean: Array, cov: Array) -> Observation:
        """From one (n_z,) or (n_z, B) mean and one shared (n_z, n_z) covariance."""
        m = np.asarray(mean, dtype=float)
        if m.ndim == 1:
            m = m[:, None]
        c = np.broadcast_to(np.asarray(cov, dtype=float), (m.shape[1], *np.shape(cov)[-2:]))
        return cls(sensor, m, c)
