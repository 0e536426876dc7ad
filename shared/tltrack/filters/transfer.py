"""The two roles of the TL-PF, for any :class:`~tltrack.filters.base.Filter`.

Source (Algorithm 1): update at k, then propagate once and summarise the propagated density as the
predicted observation (eta_hat_{k+1}, P_eta_eta,k+1). The propagated state *is* its prior at k+1,
so its next step skips the predict: the source draws exactly the random numbers an isolated filter
with its data would, and its estimates equal that filter's.

Primary (Algorithm 2): predict, then update on its own measurement together with every transfer
whose ``k_apply`` is k. With no transfer it is the isolated filter.

A live tracker can miss a measurement (a partition, a lost packet): ``z=None`` then means a
prediction-only step, so the filter stays on the clock instead of waiting forever.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tltrack.filters.base import Array, Estimate, Filter
from tltrack.filters.consistency import nis
from tltrack.filters.decision import TransferPolicy
from tltrack.models.base import MeasurementModel
from tltrack.models.observation import Observation

#: Reinitialises the lost runs of a filter around a measurement; returns which runs it did (see
#: tltrack.filters.recovery).
Recover = Callable[[Any, Observation], NDArray[np.bool_]]


class Source:
    """Algorithm 1: ``step(z_k)`` returns the estimate at k and the transfer for k + 1."""

    def __init__(
        self, filt: Filter, sensor: MeasurementModel, R: Array, recover: Recover | None = None
    ) -> None:
        self.filter = filt
        self.sensor = sensor
        self.R = R
        self.recover = recover
        self.recovered: NDArray[np.bool_] | None = None  #: per run, by the last step
        self.nis: Array | None = None  #: per run, of the last step's z_k (None: no z_k)
        self._upcoming: Observation | None = None  #: the last transfer: its z_k's prediction

    def step(self, z: Observation | None) -> tuple[Estimate, Observation]:
        if self._upcoming is None:
            self.filter.predict()
            self._upcoming = self.filter.predicted_observation(self.sensor, self.R)
        self.recovered = None
        self.nis = None if z is None else nis(z, self._upcoming)
        if z is not None:
            if self.recover is not None:
                self.recovered = self.recover(self.filter, z)
            self.filter.update([z])
        est = self.filter.estimate()
        self.filter.predict()
        self._upcoming = self.filter.predicted_observation(self.sensor, self.R)
        return est, self._upcoming


class Primary:
    """Algorithm 2: ``step(z_k, transfers)``; an empty ``transfers`` is an isolated step.

    With a :class:`~tltrack.filters.decision.TransferPolicy` the primary first decides, per run,
    which transfers to use (robust TL). :attr:`used` tells, per run, whether the last step used one.
    A robust primary also steps an isolated ``twin`` (a filter of the same kind on z alone, best
    with the same random numbers) and rolls the runs the policy says to :attr:`forget
    <tltrack.filters.decision.TransferPolicy.forget>` back to it, so a source found out late
    leaves no lasting harm.
    """

    def __init__(
        self,
        filt: Filter,
        policy: TransferPolicy | None = None,
        recover: Recover | None = None,
        twin: Primary | None = None,
    ) -> None:
        self.filter = filt
        self.policy = policy
        self.recover = recover
        self.twin = twin
        self.used: NDArray[np.bool_] | None = None
        self.rolled_back: NDArray[np.bool_] | None = None  #: per run, by the last step
        self.recovered: NDArray[np.bool_] | None = None  #: per run, by the last step
        self.nis: Array | None = None  #: per run, of the last step's own z_k (None: no z_k)
        self.twin_estimate: Estimate | None = None

    def step(self, z: Observation | None, transfers: Sequence[Observation] = ()) -> Estimate:
        if self.twin is not None:
            self.twin_estimate = self.twin.step(z)
        self.filter.predict()
        self.nis = None if z is None else nis(z, self.filter.predicted_observation(z.sensor, z.cov))
        self.recovered = None
        if self.recover is not None and z is not None:
            self.recovered = self.recover(self.filter, z)
        if self.policy is not None and transfers:
            transfers = self.policy.select(z, transfers)
        self.used = _any_applied(transfers)
        observations = [*([z] if z is not None else []), *transfers]
        if observations:
            self.filter.update(observations)
        self.rolled_back = None
        if self.policy is not None and transfers and self.twin is not None:
            self.rolled_back = self.policy.forget
            if self.rolled_back.any():
                self.filter.adopt(self.twin.filter, self.rolled_back)
        return self.filter.estimate()


def _any_applied(transfers: Sequence[Observation]) -> NDArray[np.bool_] | None:
    """Per run: did at least one transfer apply? None when there were none at all."""
    if not transfers:
        return None
    B = transfers[0].mean.shape[1]
    used = np.zeros(B, dtype=bool)
    for t in transfers:
        used |= np.ones(B, dtype=bool) if t.mask is None else t.mask
    return used
