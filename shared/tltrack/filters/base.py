"""The one interface every filter offers, whatever it approximates the posterior with."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, Self

import numpy as np
from numpy.typing import NDArray

from tltrack.models.base import MeasurementModel
from tltrack.models.observation import Observation
from tltrack.models.scan import Statement

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Estimate:
    """Posterior mean (B, n_x) and covariance (B, n_x, n_x) for each run of the batch."""

    mean: Array
    cov: Array


class Filter(Protocol):
    """predict / update / estimate, plus the source's predicted-observation moments."""

    def predict(self) -> None:
        """Advance the prior from k-1 to k."""

    def update(self, observations: Sequence[Statement]) -> None:
        """Condition on every Gaussian statement about h(x_k) in the list."""

    def estimate(self) -> Estimate:
        """The current posterior's mean and covariance."""

    def predicted_observation(self, sensor: MeasurementModel, R: Array) -> Observation:
        """Moments of eta = h(x) + w under the current (predicted) state density."""

    def adopt(self, other: Self, runs: NDArray[np.bool_]) -> None:
        """Take ``other``'s posterior for ``runs``: forget what only this filter was told."""
