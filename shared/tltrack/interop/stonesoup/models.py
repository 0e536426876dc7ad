"""tltrack's sensors and motion models as Stone Soup models.

A transfer is a statement in the coordinates of the source's sensor, whose description (kind,
position, noise parameters: a :class:`~tltrack.config.SensorSpec`) travels with it. To take it, a
Stone Soup tracker needs that sensor as a Stone Soup measurement model: :class:`Sensor` is any
tltrack sensor kind, built from such a description. :class:`Motion` is any tltrack motion model as a
Stone Soup transition model, so a Stone Soup pipeline can run the very models tltrack's engine runs.

Angles. Stone Soup averages an angle circularly (``Bearing.average``). tltrack's sigma-point
filters take a mean about the centre point instead, ref + sum_s w_s wrap(z_s - ref)
(:mod:`tltrack.filters.sigma_point`), which stays right with negative weights. A :class:`Sensor`'s
angles are :class:`Angle`, whose average is that one, so a Stone Soup unscented filter with
tltrack's sigma points gives tltrack's numbers to rounding.
"""

from __future__ import annotations

import datetime
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import multivariate_normal
from stonesoup.base import Property
from stonesoup.models.base import GaussianModel, TimeVariantModel
from stonesoup.models.measurement.base import MeasurementModel as StoneSoupMeasurementModel
from stonesoup.models.measurement.nonlinear import CombinedReversibleGaussianMeasurementModel
from stonesoup.models.transition.base import TransitionModel
from stonesoup.types.angle import Bearing
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors

from tltrack.config import SensorSpec
from tltrack.engine.setup import from_spec
from tltrack.models.angles import wrap_angle
from tltrack.models.base import Layout, MeasurementModel, MotionModel

Array = NDArray[np.float64]


class Angle(Bearing):
    """A bearing whose weighted mean is taken about the first of the angles averaged.

    In Stone Soup's unscented transform the first sigma point is the centre, so this is
    tltrack's mean; over a particle cloud the first particle is as good a reference as any.
    """

    @classmethod
    def average(cls, angles: Sequence[Any], weights: Any = None) -> Angle:
        a = np.asarray(angles, dtype=float)
        w = np.ones_like(a) if weights is None else np.asarray(weights, dtype=float)
        ref = a[0]
        return cls(ref + float(np.sum(w * wrap_angle(a - ref)) / np.sum(w)))


def _floats(state: Any) -> Array:
    """A state's vector(s) as plain floats, (n_x, S)."""
    return np.asarray(state.state_vector, dtype=float)


#: the periods a motion model keeps its matrices for (a new interval each step would grow it)
_KEPT_PERIODS = 64


def _spd(P: Any, n: int, name: str) -> Array:
    """``P`` as an (n, n) finite, symmetric, positive-definite matrix, or a ValueError naming it:
    a transfer's covariance is made from it, and a broken one went out as near certainty."""
    P = np.asarray(P, dtype=float)
    if P.shape != (n, n) or not np.all(np.isfinite(P)):
        raise ValueError(f"{name} must be a finite {n} x {n} matrix, not {P.shape} {P.tolist()}")
    if not np.allclose(P, P.T) or np.linalg.eigvalsh(P)[0] <= 0:
        raise ValueError(f"{name} must be symmetric and positive-definite: {P.tolist()}")
    return P


def _indices(mapping: Sequence[int], ndim_state: int, name: str) -> tuple[int, int]:
    """Two distinct indices of a state of ``ndim_state``, or a ValueError naming ``name``."""
    got = tuple(int(i) for i in mapping)
    if len(got) != 2 or got[0] == got[1] or not all(0 <= i < ndim_state for i in got):
        raise ValueError(f"{name}: two distinct indices of a state of {ndim_state}, not {got}")
    return got[0], got[1]


def _reads_velocity(spec: SensorSpec) -> bool:
    """Does the sensor's h depend on the target's velocity (a Doppler's, a plugin kind's)?
    Asked of h itself, on a scratch layout, not of a component's name."""
    probe = from_spec(spec, Layout(pos=(0, 1), vel=(2, 3)))
    x = np.array([[1234.5], [987.6], [3.0], [-4.0]])
    moved = x + np.array([[0.0], [0.0], [5.0], [7.0]])
    return not np.array_equal(probe.h(x), probe.h(moved))


def _full(spec: Any) -> SensorSpec:
    """``spec`` (or the mapping of one) with every parameter its kind declares: the defaults
    filled in, and a ValueError naming those with none (a transfer carries a full description)."""
    spec = spec if isinstance(spec, SensorSpec) else SensorSpec.model_validate(spec)
    given = spec.params
    missing = [
        f"{p.name} [{p.unit}]" for p in spec.declared if p.name not in given and p.default is None
    ]
    if missing:
        raise ValueError(f"a {spec.kind} sensor needs {', '.join(missing)}")
    defaults = {p.name: p.default for p in spec.declared if p.name not in given}
    position = spec.position or (0.0, 0.0)
    return SensorSpec.model_validate({"kind": spec.kind, "position": position, **defaults, **given})


class Sensor(StoneSoupMeasurementModel, GaussianModel):
    """A tltrack sensor of any registered kind, as a Stone Soup measurement model.

    ``mapping`` gives the state's (x, y) indices and ``velocity_mapping`` its (vx, vy) (Stone
    Soup's usual [x, vx, y, vy] by default); ``noise_covar`` defaults to the sensor's own R at
    noise intensity 1. Its components are in tltrack's order (a range-bearing sensor gives
    [range, bearing]), its angles :class:`Angle`.
    """

    spec: SensorSpec = Property(
        doc="The sensor's description: its kind, position and parameters (or that mapping)."
    )
    velocity_mapping: Sequence[int] | None = Property(
        default=None, doc="The state's (vx, vy) indices; default: each position index + 1."
    )
    noise_covar: CovarianceMatrix = Property(default=None, doc="Noise covariance (default: R).")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.spec = _full(self.spec)
        pos = _indices(self.mapping, self.ndim_state, "mapping")
        vel = tuple(self.velocity_mapping or (i + 1 for i in pos))
        self.model: MeasurementModel = from_spec(self.spec, Layout(pos=pos, vel=(vel[0], vel[1])))
        if _reads_velocity(self.spec):  # (vx, vy) must then be two more of the state's indices
            vel = _indices(vel, self.ndim_state, "velocity_mapping")
            if set(vel) & set(pos):
                raise ValueError(f"velocity_mapping {vel} overlaps the position's {pos}")
        if self.noise_covar is None:
            self.noise_covar = self.model.R(1.0)
        self.noise_covar = CovarianceMatrix(_spd(self.noise_covar, self.model.n_z, "noise_covar"))
        self._angular = tuple(bool(a) for a in getattr(self.model, "angular", ()))

    @property
    def ndim_meas(self) -> int:
        return self.model.n_z

    def covar(self, **kwargs: Any) -> CovarianceMatrix:
        return self.noise_covar

    def _typed(self, z: Array) -> StateVectors:
        """z (n_z, S) with its angle components as :class:`Angle`."""
        if not any(self._angular):
            return StateVectors(z)
        typed = z.astype(object)
        for i, is_angle in enumerate(self._angular):
            if is_angle:
                typed[i, :] = [Angle(v) for v in z[i]]
        return StateVectors(typed)

    def function(self, state: Any, noise: Any = False, **kwargs: Any) -> StateVectors:
        z = self.model.h(_floats(state))
        if noise is True:
            noise = np.asarray(self.rvs(num_samples=z.shape[1], **kwargs), dtype=float)
        if noise is not False and noise is not None:
            z = z + np.asarray(noise, dtype=float).reshape(z.shape)
        return self._typed(z)

    def jacobian(self, state: Any, **kwargs: Any) -> Array:
        return self.model.H(_floats(state)[:, 0])

    def logpdf(self, state1: Any, state2: Any, **kwargs: Any) -> Any:
        """log N(z; h(x), R) with the angles' residual wrapped, on plain floats: a particle cloud's
        likelihood without Stone Soup's per-element angle objects."""
        d = self.model.residual(_floats(state1), self.model.h(_floats(state2)))
        ll = np.atleast_1d(multivariate_normal.logpdf(d.T, cov=self.covar(**kwargs)))
        return ll[0] if len(ll) == 1 else ll


class Stacked(CombinedReversibleGaussianMeasurementModel):
    """Statements with independent errors about one state, as one measurement [z; eta; ...]:
    tltrack's TL update, which conditions on the primary's z_k and every transfer at once."""

    def logpdf(self, state1: Any, state2: Any, **kwargs: Any) -> Any:
        """The sum of the members' log-likelihoods (the noise is block-diagonal)."""
        z = StateVectors(np.asarray(state1.state_vector))
        total: Any = 0.0
        start = 0
        for model in self.model_list:
            part = _Vector(StateVector(z[start : start + model.ndim_meas]))
            total = total + model.logpdf(part, state2, **kwargs)
            start += model.ndim_meas
        return total


class _Vector:
    """A bare ``state_vector`` holder: what a model's logpdf reads of a measurement."""

    def __init__(self, state_vector: Any) -> None:
        self.state_vector = state_vector


class Motion(TransitionModel, GaussianModel, TimeVariantModel):
    """A tltrack motion model as a Stone Soup transition model, over any time interval (its
    ``with_period``)."""

    model: Any = Property(doc="The tltrack motion model (a tltrack.models.base.MotionModel).")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._by_dt: dict[float, MotionModel] = {}

    @property
    def ndim_state(self) -> int:
        return int(self.model.n)

    def _over(self, time_interval: datetime.timedelta) -> MotionModel:
        """The model over ``time_interval``, forward only (CT's noise backwards is NaN)."""
        if not isinstance(time_interval, datetime.timedelta) or time_interval.total_seconds() < 0:
            raise ValueError(f"a motion model predicts forward in time, not over {time_interval!r}")
        dt = time_interval.total_seconds()
        if len(self._by_dt) >= _KEPT_PERIODS:
            self._by_dt.clear()
        if dt not in self._by_dt:
            self._by_dt[dt] = self.model.with_period(dt)
        return self._by_dt[dt]

    def function(
        self, state: Any, noise: Any = False, *, time_interval: datetime.timedelta, **kwargs: Any
    ) -> StateVectors:
        x = self._over(time_interval).f(_floats(state))
        if noise is True:
            noise = self.rvs(num_samples=x.shape[1], time_interval=time_interval, **kwargs)
        if noise is not False and noise is not None:
            x = x + np.asarray(noise, dtype=float).reshape(x.shape)
        return StateVectors(x)

    def covar(self, *, time_interval: datetime.timedelta, **kwargs: Any) -> CovarianceMatrix:
        return CovarianceMatrix(self._over(time_interval).Q)

    def jacobian(self, state: Any, *, time_interval: datetime.timedelta, **kwargs: Any) -> Array:
        return self._over(time_interval).F(_floats(state)[:, 0])
