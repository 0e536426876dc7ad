"""The two roles of the TL-PF, for any :class:`~tltrack.filters.base.Filter`.

Source (Algorithm 1): update at k, then propagate once and summarise the propagated density as the
predicted observation (eta_hat_{k+1}, P_eta_eta,k+1). The propagated state *is* its prior at k+1,
so its next step skips the predict: the source draws exactly the random numbers an isolated filter
with its data would, and its estimates equal that filter's.

Primary (Algorithm 2): predict, then update on its own measurement together with every transfer
whose ``k_apply`` is k. With no transfer it is the isolated filter.

A live tracker can miss a measurement (a partition, a lost packet): ``z=None`` then means a
prediction-only step, so the filter stays on the clock instead of waiting forever.

The own measurement may be a scan with false alarms (:class:`~tltrack.models.scan.Scan`): the
filter takes it whole, and the NIS, the robust policy and the lost-track recovery read the scan's
PDA-combined measurement and its likeliest detection (:mod:`~tltrack.filters.association`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tltrack.filters.association import associate, combined, likeliest
from tltrack.filters.base import Array, Estimate, Filter
from tltrack.filters.consistency import nis
from tltrack.filters.decision import TransferPolicy
from tltrack.filters.sigma_point import UKF_KAPPA, SigmaPointFilter, unscented
from tltrack.models.base import MeasurementModel, MotionModel
from tltrack.models.observation import Observation
from tltrack.models.scan import Scan, Statement

#: the time step of the central difference that gives a carried state's rate of change
RATE_STEP_S = 1e-3

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
        self._posterior: Estimate | None = None  #: the last step's estimate

    def step(self, z: Statement | None) -> tuple[Estimate, Observation]:
        if self._upcoming is None:
            self.filter.predict()
            self._upcoming = self.filter.predicted_observation(self.sensor, self.R)
        self.recovered = None
        self.nis = None
        if z is not None:
            own = Own(z, self._upcoming)
            self.nis = own.nis
            if self.recover is not None:
                self.recovered = self.recover(self.filter, own.anchor)
            self.filter.update([z])
        est = self._posterior = self.filter.estimate()
        self.filter.predict()
        self._upcoming = self.filter.predicted_observation(self.sensor, self.R)
        return est, self._upcoming

    def ahead(
        self, over: Callable[[float], MotionModel], horizon_s: float, spread_s: float = 0.0
    ) -> Observation:
        """The transfer for a time off the source's own steps, ``horizon_s`` after its last one
        (operators with their own periods, :mod:`tltrack.config.timeline`): the last posterior
        N(x_hat, P) carried over it (``over(dt)``: the motion model over dt) and through the
        sensor by the unscented transform (eq. BTL_sr_eta_1 with a Gaussian for the posterior).

        ``spread_s``: the standard deviation of the horizon's true length (the two operators'
        clocks). To first order in that error the carried state moves by it times its rate of
        change v, which adds spread_s^2 v v' to its covariance: a transfer whose time is
        uncertain says so. No random number is drawn, so the filter's own steps stay those of
        its isolated twin.
        """
        if self._posterior is None:
            raise RuntimeError("a source sends transfers after its first step")
        m = self._posterior.mean.T
        carried = SigmaPointFilter(over(horizon_s), unscented(len(m), UKF_KAPPA), m,
                                   self._posterior.cov)  # fmt: skip
        carried.predict()
        if spread_s > 0:
            d = min(RATE_STEP_S, horizon_s / 2)
            v = (over(horizon_s + d).f(m) - over(horizon_s - d).f(m)) / (2 * d)
            carried.P += spread_s**2 * np.einsum("ib,jb->bij", v, v)
        return carried.predicted_observation(self.sensor, self.R)


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

    def step(self, z: Statement | None, transfers: Sequence[Statement] = ()) -> Estimate:
        if self.twin is not None:
            self.twin_estimate = self.twin.step(z)
        self.filter.predict()
        own = None if z is None else Own(z, self.filter.predicted_observation(z.sensor, z.cov))
        self.nis = None if own is None else own.nis
        self.recovered = None
        if self.recover is not None and own is not None:
            self.recovered = self.recover(self.filter, own.anchor)
        if self.policy is not None and transfers:
            judged = [t for t in transfers if isinstance(t, Observation)]  # transfers: Gaussian
            transfers = self.policy.select(None if own is None else own.statement, judged)
        self.used = _any_applied(transfers)
        observations: list[Statement] = [*([z] if z is not None else []), *transfers]
        if observations:
            self.filter.update(observations)
        self.rolled_back = None
        if self.policy is not None and transfers and self.twin is not None:
            self.rolled_back = self.policy.forget
            if self.rolled_back.any():
                self.filter.adopt(self.twin.filter, self.rolled_back)
        return self.filter.estimate()


class Own:
    """What a role reads of its own measurement z_k given its prediction N(z_hat, S): the NIS,
    the statement the robust policy judges transfers against, and the anchor a recovery redraws
    around. For a plain measurement, z itself; for a scan, its PDA-combined measurement (the
    prediction itself where no detection is in the gate, and then no NIS) and its likeliest
    detection."""

    def __init__(self, z: Statement, predicted: Observation) -> None:
        if isinstance(z, Scan):
            a = associate(z, predicted)
            self.statement = combined(z, predicted, a)
            self.anchor = likeliest(z, a)
            self.nis = np.where(a.any, nis(self.statement, predicted), np.nan)
        else:
            self.statement = self.anchor = z
            self.nis = nis(z, predicted)


def _any_applied(transfers: Sequence[Statement]) -> NDArray[np.bool_] | None:
    """Per run: did at least one transfer apply? None when there were none at all."""
    if not transfers:
        return None
    B = transfers[0].cov.shape[0]
    used = np.zeros(B, dtype=bool)
    for t in transfers:
        used |= np.ones(B, dtype=bool) if t.mask is None else t.mask
    return used
