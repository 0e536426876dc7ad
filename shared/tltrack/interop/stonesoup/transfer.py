"""The transfer, in Stone Soup's types: what a source sends, and what a primary takes.

Source side (the seed's Algorithm 1): after its update at k the source propagates once and
summarises the density through its own sensor, eta_hat_{k+1} = E[h(x_{k+1})] and
P_eta_eta = Cov[h(x_{k+1})] + R (the seed's predicted-observation mean and covariance).
:func:`predicted_observation` takes those moments of a Stone Soup prediction: by the unscented
transform of a Gaussian one (tltrack's UKF sigma points by default), by the weighted cloud of a
particle one. :func:`transfer_message` puts them in a :class:`~tltrack.wire.messages.Transfer`.

Primary side (Algorithm 2): the transfer is a second likelihood N(eta_hat; h_source(x), P_eta_eta):
a detection whose measurement model is the source's sensor with noise P_eta_eta
(:func:`detection`). Stone Soup's own updaters, hypothesisers and associators then take it as they
take any detection. :func:`stacked` joins the primary's detection and the transfers of one step
into one measurement [z; eta; ...] with block-diagonal noise, for one update: tltrack's TL update.
"""

from __future__ import annotations

import datetime
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from stonesoup.base import Property
from stonesoup.types.array import CovarianceMatrix, StateVector
from stonesoup.types.detection import Detection
from stonesoup.types.state import ParticleState
from stonesoup.updater.kalman import UnscentedKalmanUpdater

from tltrack.filters.sigma_point import KAPPA
from tltrack.interop.stonesoup.models import Sensor, Stacked
from tltrack.live.tracking import wire_covariance
from tltrack.wire.messages import Transfer

Array = NDArray[np.float64]

#: Stone Soup's unscented parameters that give tltrack's UKF sigma points (Julier & Uhlmann 2000):
#: alpha = 1 and beta = 0 leave kappa alone, so the centre's weight is kappa / (n + kappa)
UKF_POINTS = {"alpha": 1.0, "beta": 0.0, "kappa": KAPPA.check(KAPPA.default)}

EPOCH = datetime.datetime(1970, 1, 1)  #: a message's t_sensor is seconds since this (naive UTC)


def timestamp(t_sensor: float) -> datetime.datetime:
    """A message's ``t_sensor`` as Stone Soup's (naive, UTC) timestamp."""
    return EPOCH + datetime.timedelta(seconds=t_sensor)


def predicted_observation(
    prediction: Any, sensor: Sensor, **unscented: float
) -> tuple[Array, Array]:
    """(eta_hat, P_eta_eta) of a Stone Soup prediction through the source's sensor.

    A particle prediction: the cloud's weighted mean and covariance of h(x), plus R. Any other
    (Gaussian) prediction: the unscented transform with ``unscented`` (alpha, beta, kappa;
    default :data:`UKF_POINTS`), plus R.
    """
    if isinstance(prediction, ParticleState):
        w = np.exp(np.asarray(prediction.log_weight, dtype=float) - np.max(prediction.log_weight))
        w /= w.sum()
        Z = sensor.function(prediction)
        eta = np.average(Z, axis=1, weights=w)
        d = np.asarray(Z - eta, dtype=float)
        P = (d * w) @ d.T + np.asarray(sensor.covar(), dtype=float)
        return np.asarray(eta, dtype=float)[:, 0], P
    updater = UnscentedKalmanUpdater(sensor, **{**UKF_POINTS, **unscented})
    mp = updater.predict_measurement(prediction)
    return np.asarray(mp.state_vector, dtype=float)[:, 0], np.asarray(mp.covar, dtype=float)


def transfer_message(
    prediction: Any,
    sensor: Sensor,
    *,
    episode: str,
    source: str,
    k: int,
    t_sensor: float,
    **unscented: float,
) -> Transfer:
    """What source ``source`` sends after its step ``k``: the transfer for step k + 1, described by
    its sensor. Its covariance is made fit for the wire (symmetric, positive-definite), unless it
    is broken (not finite, or negative beyond round-off: a ValueError, not a near-certain one)."""
    eta, P = predicted_observation(prediction, sensor, **unscented)
    P = np.asarray(P, dtype=float)
    if not np.all(np.isfinite(P)) or np.linalg.eigvalsh(0.5 * (P + P.T))[0] < -1e-9 * max(
        1.0, float(np.trace(np.abs(P)))
    ):
        raise ValueError(f"the predicted observation's covariance is broken: {P.tolist()}")
    return Transfer(
        episode=episode,
        sender=source,
        k=k,
        t_sensor=t_sensor,
        k_apply=k + 1,
        sensor=sensor.spec,
        eta=eta,
        P_eta=wire_covariance(P),
    )


class TransferDetection(Detection):
    """A source's transfer as a detection: eta_hat, with the source's sensor and noise P_eta_eta
    as its measurement model. ``timestamp`` is the time of the step it is for (``k_apply``) when
    the primary's period is known, else when the source made it (see :func:`detection`)."""

    source: str = Property(doc="The id of the source that sent it.")
    k_apply: int = Property(doc="The step it is a statement about.")


def detection(
    msg: Transfer,
    *,
    ndim_state: int,
    mapping: Sequence[int],
    velocity_mapping: Sequence[int] | None = None,
    when: datetime.datetime | None = None,
    steps: tuple[datetime.datetime, datetime.timedelta] | None = None,
) -> TransferDetection:
    """The detection of a received transfer, for a state whose (x, y) sit at ``mapping`` (and
    (vx, vy) at ``velocity_mapping``).

    Its timestamp is ``when`` if given; else, given the primary's ``steps`` (its step 0's time
    and its period, the grid its own detections are dated on), the time of the step it is for,
    ``start + k_apply * period``: Stone Soup predicts to a detection's time, and a transfer is a
    statement about step k_apply. On the paper's shared clock and off it alike (a transfer
    stamped with ``t_apply``), k_apply numbers the primary's own samples, so the grid dates both.
    Else its ``t_sensor``, the wall-clock time of the source's step k, one step earlier."""
    P = np.asarray(msg.P_eta, dtype=float)
    model = Sensor(
        spec=msg.sensor,
        ndim_state=ndim_state,
        mapping=tuple(mapping),
        velocity_mapping=None if velocity_mapping is None else tuple(velocity_mapping),
        noise_covar=CovarianceMatrix(0.5 * (P + P.T)),  # symmetric to the wire's tolerance: exactly
    )
    if when is None and steps is not None:
        start, period = steps
        when = start + msg.k_apply * period
    return TransferDetection(
        StateVector(np.asarray(msg.eta, dtype=float)),
        timestamp=timestamp(msg.t_sensor) if when is None else when,
        measurement_model=model,
        source=msg.sender,
        k_apply=msg.k_apply,
        metadata={"episode": msg.episode, "source": msg.sender, "k_apply": msg.k_apply},
    )


def stacked(detections: Sequence[Detection], when: datetime.datetime | None = None) -> Detection:
    """One detection [z; eta_1; ...] of the statements about one state at one time, with
    block-diagonal noise (they have independent errors): one update conditions on them all.
    ``when``: its timestamp (default: the first's)."""
    if not detections:
        raise ValueError("nothing to stack")
    if none := [i for i, d in enumerate(detections) if d.measurement_model is None]:
        raise ValueError(f"detection(s) {none} have no measurement model: a stack needs each one's")
    z = np.vstack([np.asarray(d.state_vector, dtype=float) for d in detections])
    return Detection(
        StateVector(z),
        timestamp=detections[0].timestamp if when is None else when,
        measurement_model=Stacked([d.measurement_model for d in detections]),
        metadata={"stacked": len(detections)},
    )
