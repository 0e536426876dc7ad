"""The particle filter's compiled fast paths, looked up by model type.

This is the only module of :mod:`tltrack.filters` that names concrete model classes. A motion model
listed in :data:`PROPAGATORS` propagates its particles in a numba kernel; a sensor listed in
:data:`SENSOR_KERNELS` weighs them (fused with resampling) and summarises them in one. Any other
model takes :class:`~tltrack.filters.particle.ParticleFilter`'s generic NumPy path, with the same
random numbers, so a new model needs no entry here to work: only to be faster.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, cast

import numpy as np
from numpy.typing import NDArray

from tltrack.filters.kernels import auxiliary, propagation, range_bearing
from tltrack.models.base import Layout, MeasurementModel, MotionModel
from tltrack.models.constant_velocity import ConstantVelocity
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.modes import Straight
from tltrack.models.observation import Observation
from tltrack.models.range_bearing import RangeBearing

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]


def f64(a: Array) -> Array:
    return np.ascontiguousarray(a, dtype=np.float64)


# ---- propagation ------------------------------------------------------------------------------


class Propagator(Protocol):
    """Propagates run ``b``: out[:, b, i] = f(src[:, b, anc[b, i]]) + Q_sqrt eps, eps made from
    that run's uniforms ``U`` (1, uniforms_per_run(r, N)); and the transition's mean alone."""

    def __call__(self, src: Array, anc: NDArray[np.int64], U: Array, out: Array, b: int) -> None:
        """Propagate run b."""

    def mean(self, x: Array, out: Array) -> None:
        """out = f(x) for clouds (n_x, B, N), every run."""


@dataclass
class _CT:
    model: CoordinatedTurn
    N: int
    L: Array = field(init=False)
    e: Array = field(init=False)  # one run's Gaussians (scratch)
    g: Array = field(init=False)  # a block of gathered ancestors (scratch)

    def __post_init__(self) -> None:
        self.L = f64(self.model.Q_sqrt)
        self.e = np.empty((3, self.N))
        self.g = np.empty((5, propagation.BLOCK))

    def __call__(self, src: Array, anc: NDArray[np.int64], U: Array, out: Array, b: int) -> None:
        m = self.model
        propagation.ct_predict(
            src, anc, U, self.e, self.g, float(m.T), float(m.SMALL), self.L, out, b
        )

    def mean(self, x: Array, out: Array) -> None:
        auxiliary.ct_mean(x, float(self.model.T), float(self.model.SMALL), out)


@dataclass
class _CV:
    model: ConstantVelocity
    N: int
    A: Array = field(init=False)
    L: Array = field(init=False)
    e: Array = field(init=False)
    g: Array = field(init=False)

    def __post_init__(self) -> None:
        self.A = f64(self.model.A)
        self.L = f64(self.model.Q_sqrt)
        self.e = np.empty((2, self.N))
        self.g = np.empty((4, propagation.BLOCK))

    def __call__(self, src: Array, anc: NDArray[np.int64], U: Array, out: Array, b: int) -> None:
        propagation.cv_predict(src, anc, U, self.e, self.g, self.A, self.L, out, b)

    def mean(self, x: Array, out: Array) -> None:
        out[...] = np.tensordot(self.A, x, axes=1)


#: motion model type -> (the Q_sqrt shape its kernel assumes, the propagator's factory)
PROPAGATORS: dict[type, tuple[tuple[int, int], Callable[[Any, int], Propagator]]] = {
    CoordinatedTurn: ((5, 3), _CT),
    ConstantVelocity: ((4, 2), _CV),
}


def propagator(model: MotionModel, N: int) -> Propagator | None:
    """The compiled propagation of ``model`` for N particles, or None (the generic path)."""
    entry = PROPAGATORS.get(type(model))
    if entry is None or np.shape(model.Q_sqrt) != entry[0]:
        return None
    return entry[1](model, N)


@dataclass
class ModesPropagator:
    """The jump-Markov coordinated turn's propagation: each particle in its own mode, every mode
    a :class:`~tltrack.models.coordinated_turn.CoordinatedTurn` or a
    :class:`~tltrack.models.modes.Straight` of one period."""

    T: float
    small: float
    Ls: Array  # (M, 5, 3): each mode's Q_sqrt
    keep: Array  # (M,): 1 where the mode turns, 0 where it holds Omega at 0
    N: int
    C: Array = field(init=False)  # (M, 5): Ls's entries that may be non-zero
    e: Array = field(init=False)
    g: Array = field(init=False)
    c: Array = field(init=False)

    def __post_init__(self) -> None:
        rows, cols = zip(*propagation.MODE_NOISE, strict=True)
        self.C = f64(self.Ls[:, list(rows), list(cols)])
        self.e = np.empty((3, self.N))
        self.g = np.empty((5, propagation.BLOCK))
        self.c = np.empty((5, propagation.BLOCK))

    def __call__(
        self, src: Array, anc: NDArray[np.int64], modes: NDArray[np.int64], U: Array, out: Array,
        b: int,
    ) -> None:  # fmt: skip
        """Propagate run b (its uniforms U (1, ...)), particle i in mode modes[b, i]."""
        propagation.modes_ct_predict(
            src, anc, U, self.e, self.g, self.c, modes, self.keep, self.C, self.Ls, self.T,
            self.small, out, b,
        )  # fmt: skip

    def mean(self, x: Array, modes: NDArray[np.int64], out: Array) -> None:
        """out = f_m(x), particle by particle in its mode, every run."""
        auxiliary.modes_ct_mean(x, modes, self.keep, self.T, self.small, out)


def modes_propagator(models: Sequence[MotionModel], N: int) -> ModesPropagator | None:
    """The compiled propagation of a cloud whose particles move in these modes, or None (the
    generic path): every mode a coordinated turn or straight, of one period, whose noise factor
    has no entry beyond :data:`~tltrack.filters.kernels.propagation.MODE_NOISE`."""
    if not all(type(m) in (CoordinatedTurn, Straight) for m in models):
        return None
    turns = cast("list[CoordinatedTurn | Straight]", list(models))
    if len({float(m.T) for m in turns}) != 1 or any(np.shape(m.Q_sqrt) != (5, 3) for m in turns):
        return None
    Ls = f64(np.stack([m.Q_sqrt for m in turns]))
    outside = Ls.copy()
    for i, j in propagation.MODE_NOISE:
        outside[:, i, j] = 0.0
    if np.any(outside != 0.0):
        return None
    return ModesPropagator(
        T=float(turns[0].T),
        small=float(CoordinatedTurn.SMALL),
        Ls=Ls,
        keep=np.array([1.0 if isinstance(m, CoordinatedTurn) else 0.0 for m in turns]),
        N=N,
    )


# ---- sensors ----------------------------------------------------------------------------------


class SensorKernels(Protocol):
    """The compiled likelihood and predicted-observation moments of one sensor type, for a batch
    of B runs. ``observations`` are statements about sensors of that type, sharing a layout."""

    def loglik(self, x: Array, observations: Sequence[Observation], logw: Array) -> None:
        """logw (B, N) = the sum of the observations' log-likelihoods (up to constants)."""

    def update(
        self,
        x: Array,
        observations: Sequence[Observation],
        u: Array,
        anc: NDArray[np.int64],
        mean: Array,
        cov: Array,
        ok: Mask,
        row: Array,
    ) -> int:
        """:meth:`loglik`, then systematic resampling with offsets u (B,), run by run: ancestors
        into anc, the resampled moments into mean and cov, ok[b] for runs with finite weights;
        returns how many runs are ok. ``row`` (N,) is scratch."""

    def predicted_observation(
        self, x: Array, sensor: MeasurementModel, logw: Array | None = None
    ) -> tuple[Array, Array]:
        """The sample mean (n_z, B) and covariance (B, n_z, n_z) of h(x) over each run's cloud,
        weighted by the normalised log-weights ``logw`` (B, N) if given."""


@dataclass
class _RangeBearingKernels:
    B: int
    _packs: dict[int, tuple[Array, Array, Array, Mask]] = field(default_factory=dict)

    def _pack(self, observations: Sequence[Observation]) -> tuple[Array, Array, Array, Mask]:
        """Positions, means, covariances and masks of M statements, in reused buffers."""
        M = len(observations)
        if M not in self._packs:
            self._packs[M] = (
                np.empty((M, 2)),
                np.empty((M, 2, self.B)),
                np.empty((M, self.B, 2, 2)),
                np.empty((M, self.B), dtype=np.bool_),
            )
        pos, mean, cov, mask = packed = self._packs[M]
        for j, o in enumerate(observations):
            pos[j, 0], pos[j, 1] = o.sensor.position
            mean[j] = o.mean
            cov[j] = o.cov
            mask[j] = True if o.mask is None else o.mask
        return packed

    @staticmethod
    def _pos(observations: Sequence[Observation]) -> tuple[int, int]:
        layout: Layout = observations[0].sensor.layout  # type: ignore[attr-defined]
        return layout.pos

    def loglik(self, x: Array, observations: Sequence[Observation], logw: Array) -> None:
        ix, iy = self._pos(observations)
        range_bearing.rb_loglik(x, ix, iy, *self._pack(observations), logw)

    def update(
        self,
        x: Array,
        observations: Sequence[Observation],
        u: Array,
        anc: NDArray[np.int64],
        mean: Array,
        cov: Array,
        ok: Mask,
        row: Array,
    ) -> int:
        ix, iy = self._pos(observations)
        packed = self._pack(observations)
        return int(range_bearing.rb_update(x, ix, iy, *packed, u, anc, mean, cov, ok, row))

    def predicted_observation(
        self, x: Array, sensor: MeasurementModel, logw: Array | None = None
    ) -> tuple[Array, Array]:
        assert isinstance(sensor, RangeBearing)
        eta = np.empty((2, self.B))
        cov = np.empty((self.B, 2, 2))
        ix, iy = sensor.layout.pos
        sx, sy = (float(c) for c in sensor.position)
        if logw is None:
            range_bearing.rb_predicted_obs(x, ix, iy, sx, sy, eta, cov)
        else:
            w = np.empty(x.shape[2])
            range_bearing.rb_weighted_predicted_obs(x, ix, iy, sx, sy, logw, eta, cov, w)
        return eta, cov


#: sensor type -> the factory of its kernels for a batch of B runs
SENSOR_KERNELS: dict[type, Callable[[int], SensorKernels]] = {
    RangeBearing: _RangeBearingKernels,
}


def sensor_kernels(sensor: MeasurementModel, B: int) -> SensorKernels | None:
    """The compiled kernels of ``sensor``'s type for B runs, or None (the generic path)."""
    make = SENSOR_KERNELS.get(type(sensor))
    return None if make is None else make(B)


def examples() -> list[tuple[MotionModel, MeasurementModel]]:
    """A small instance of every model with a fast path, to compile its kernels ahead of use."""
    ct = CoordinatedTurn(T=1.0, q1=0.1, q2=1e-4)
    cv = ConstantVelocity(T=1.0, q=0.1)
    return [(m, RangeBearing(10.0, 0.01, m.layout)) for m in (ct, cv)]
