"""The SIR particle filter of the seed's Sec. IV, batched over B runs.

With the transition prior as proposal and resampling at every step, the weight of particle i is
the product of the Gaussian likelihoods of every observation (seed eqs. TL_tr_weights_1/2):

    w_k^(i)  ∝  p(z_k | x_k^(i)) · p(eta_hat_k | x_k^(i))

An isolated PF passes only z_k; TL-PF adds the source's transfer; centralized fusion adds the
source's raw measurement instead. Weights stay in the log domain, so two sharp likelihoods whose
product underflows in linear space still normalise (no 0/0).

Particles are stored ``(n_x, B, N)``: each state component of each run is one contiguous row.

Speed: the motion models and sensors that :mod:`tltrack.filters.fastpath` lists, systematic
resampling and the moments run as numba kernels (:mod:`tltrack.filters.kernels`). Any other
motion model or sensor takes the generic NumPy path, with the same random numbers. Each step
draws, from each run's own generator and in this order: ``uniforms_per_run(r, N)`` uniforms in
``predict`` (made into the r = rank(Q_v) Gaussians per particle by Box-Muller), then one uniform
in ``update`` (the systematic offset). A run's numbers therefore never depend on the batch size.

``update`` does not write the resampled cloud out: it keeps the ancestor indices, the next
``predict`` propagates through them, and ``estimate`` takes the resampled cloud's moments from the
offspring counts. Reading :attr:`ParticleFilter.x` gathers the cloud on demand (read-only until
the next ``predict``: the estimate was computed from it; assign a new array to replace it).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.filters import fastpath
from tltrack.filters.base import Estimate
from tltrack.filters.kernels import gaussians, moments, propagation, resample
from tltrack.filters.likelihood import Likelihood
from tltrack.filters.particle_modes import ParticleModes
from tltrack.models.base import MeasurementModel, MotionModel
from tltrack.models.modes import MotionModes
from tltrack.models.observation import Observation
from tltrack.models.scan import Statement

Array = NDArray[np.float64]


_f64 = fastpath.f64


def initial_cloud(x0_hat: Array, P0: Array, N: int, rngs: Sequence[np.random.Generator]) -> Array:
    """N particles per run drawn from N(x0_hat[:, b], P0), (n_x, B, N); run b from ``rngs[b]``."""
    n, B = x0_hat.shape
    if len(rngs) != B:
        raise ValueError(f"{len(rngs)} random streams for a batch of {B} runs")
    eps = np.empty((n, B, N))
    for b, g in enumerate(rngs):
        eps[:, b, :] = g.standard_normal((n, N))
    return np.asarray(x0_hat[:, :, None] + np.tensordot(np.linalg.cholesky(P0), eps, axes=1))


class ParticleFilter:
    """SIR-PF with systematic resampling at every step; one random stream per run.

    ``update`` leaves the resampled cloud as (pre-resampling cloud, ancestor indices): the next
    ``predict`` propagates through the ancestors directly, and the estimate's moments come from the
    offspring counts, so the resampled cloud is never written out unless :attr:`x` is read.
    """

    kind: ClassVar[str] = "pf"
    particle: ClassVar[bool] = True
    parameters: ClassVar[tuple[Parameter, ...]] = ()

    @classmethod
    def build(
        cls,
        model: MotionModel,
        x0_hat: Array,
        P0: Array,
        *,
        particles: int,
        rngs: Sequence[np.random.Generator] | None,
        params: Mapping[str, float],
        modes: MotionModes | None = None,
    ) -> ParticleFilter:
        assert rngs is not None, "a particle filter draws from one stream per run"
        return cls(model, x0_hat, P0, particles, rngs, modes=modes)

    def __init__(
        self,
        model: MotionModel,
        x0_hat: Array,
        P0: Array,
        n_particles: int,
        rngs: Sequence[np.random.Generator],
        modes: MotionModes | None = None,
    ) -> None:
        """Draw N particles per run from N(x0_hat[:, b], P0); ``x0_hat`` is (n_x, B).

        ``modes``: a jump-Markov motion model; each particle then carries a mode
        (:mod:`~tltrack.filters.particle_modes`), and ``model`` is its first mode's.
        """
        model = model if modes is None else modes.models[0]
        self.model = model
        self.rngs = list(rngs)
        self.N = n_particles
        self.modes = None if modes is None else ParticleModes(modes, self.rngs, n_particles)
        B = x0_hat.shape[1]
        L = np.asarray(model.Q_sqrt, dtype=np.float64)
        self._L = _f64(L)
        self._r = L.shape[1]
        self._propagate = fastpath.propagator(model, self.N)
        self._U1 = np.empty((1, gaussians.uniforms_per_run(self._r, self.N)))  # one run's
        self._likelihood = Likelihood(B)
        self._logw = np.empty((B, self.N))
        self._u = np.empty(B)  # this step's systematic offsets
        self._anc = np.empty((B, self.N + 1), dtype=np.int64)  # ancestors (+ a scratch column)
        self._pre: Array | None = None  # the cloud before resampling, while x is not gathered
        self._moments: tuple[Array, Array] | None = None  # of the resampled cloud, from update()
        self.x = initial_cloud(x0_hat, P0, self.N, self.rngs)

    @property
    def x(self) -> Array:
        """The particles (n_x, B, N); after ``update``, the resampled cloud (gathered on demand).

        After ``predict`` the array may be modified in place (a recovery redraws lost runs so).
        After ``update`` it is read-only, as ``estimate`` was computed from it: to change it then,
        assign a new array.
        """
        return self._cloud()

    @x.setter
    def x(self, value: Array) -> None:
        self._x = value
        self._pre = None
        self._moments = None

    @property
    def anchors(self) -> Array:
        """Where a lost-track test weighs z_k after ``predict``: the predicted cloud itself, which
        the update weighs."""
        return self._cloud()

    def _cloud(self) -> Array:
        """The current cloud, gathered from (pre-resampling cloud, ancestors) if need be."""
        if self._pre is not None:
            out = np.empty_like(self._pre)
            propagation.gather(self._pre, self._anc, out)
            out.flags.writeable = False
            if self.modes is not None:  # each slot takes its ancestor's mode, as its state
                self.modes.of = self.modes.gather(self.modes.of, self._anc)
            self._x, self._pre = out, None
        return self._x

    @property
    def batch(self) -> int:
        return len(self.rngs)

    def _draw_uniforms(self) -> Array:
        U = np.empty((self.batch, self._U1.shape[1]))
        for b, g in enumerate(self.rngs):
            g.random(out=U[b])
        return U

    def gaussians(self) -> Array:
        """Draw this step's process-noise Gaussians (r, B, N): what ``predict`` adds via Q_sqrt.

        The generic path uses it, and it lets tests reproduce the fast path's numbers exactly.
        """
        return self._gaussians(self._draw_uniforms())

    def _gaussians(self, U: Array) -> Array:
        E = np.empty((self.batch, self._r, self.N))
        gaussians.gaussians(U, E)
        return E.transpose(1, 0, 2)

    @property
    def mode_probabilities(self) -> Array | None:
        """(M, B): each motion mode's share of the (resampled) cloud; None without modes."""
        if self.modes is None:
            return None
        of = self.modes.of
        if self._pre is not None:  # resampled: each slot holds its ancestor's mode
            of = self.modes.gather(of, self._anc)
        return self.modes.probabilities(of)

    def _process_noise(self) -> Array:
        """Q_v, or with modes the mixture sum_m P(m) Q_m of each run (B, n, n)."""
        p = self.mode_probabilities
        if p is None or self.modes is None:
            return np.asarray(self.model.Q)
        return np.einsum("mb,mij->bij", p, self.modes.Qs)

    def predict(self) -> None:
        """x_k^(i) ~ p(x_k | x_{k-1}^(i)) (seed eq. BTL_tr_particle_2), noise through Q_sqrt."""
        if self._pre is not None:
            src, anc = self._pre, self._anc
        else:  # not resampled yet (the first step): every particle is its own ancestor
            src, anc = self._x, self._anc
            anc[:] = np.arange(self.N + 1)
        if self.modes is not None:
            modes = self.modes.switch(self.modes.gather(self.modes.of, anc))
            U = self._draw_uniforms()  # each run's, as the single-model filter draws them
            self.x = self.modes.propagate(src, anc, modes, U, lambda: self._gaussians(U))
            self.modes.of = modes
            return
        if self._propagate is None or src.dtype != np.float64 or not src.flags.c_contiguous:
            x = self._cloud()
            self.x = self.model.f(x) + np.tensordot(self._L, self.gaussians(), axes=1)
            return
        out = np.empty_like(src)
        # Run by run: a run's uniforms are drawn into one reused row, still in cache when read
        U = self._U1
        for b, g in enumerate(self.rngs):
            g.random(out=U[0])
            self._propagate(src, anc, U, out, b)
        self.x = out

    def _loglik_into(self, observations: Sequence[Statement], logw: Array) -> None:
        """Write the sum of every observation's log-likelihood into ``logw`` (B, N)."""
        self._likelihood.into(self._cloud(), observations, logw)

    def log_weights(self, observations: Sequence[Statement]) -> Array:
        """Unnormalised log-weights (B, N): the sum of every observation's log-likelihood."""
        logw = np.empty((self.batch, self.N))
        self._loglik_into(observations, logw)
        return logw

    def update(self, observations: Sequence[Statement]) -> None:
        """Weight, normalise and resample (Algorithm 2, lines 3-9).

        A run whose weights are not finite (NaN particles) gets a NaN cloud, so it reads as lost.
        """
        x = self._cloud()
        if x.dtype != np.float64 or not x.flags.c_contiguous:
            x = _f64(x)
        n, B = x.shape[0], self.batch
        u = self._u
        for b, g in enumerate(self.rngs):
            u[b] = g.random()
        mean = np.empty((B, n))
        cov = np.empty((B, n, n))
        ok = np.empty(B, dtype=np.bool_)
        fast, others = self._likelihood.split(observations, x)
        if fast is not None and not others:  # likelihood and resampling fused, run by run
            kernels, obs = fast
            good = kernels.update(x, obs, u, self._anc, mean, cov, ok, self._logw[0])
        else:
            self._loglik_into(observations, self._logw)
            good = resample.resample(self._logw, u, x, self._anc, mean, cov, ok)
        if good < B:
            bad = ~ok
            x = x.copy()  # the caller's array stays as it was
            x[:, bad, :] = np.nan
            self._anc[bad, : self.N] = np.arange(self.N)
            mean[bad] = np.nan
            cov[bad] = np.nan
        self.x = x
        self._pre = x
        self._moments = (mean, cov)

    def estimate(self) -> Estimate:
        """Mean and covariance of the resampled cloud, plus Q_v (eqs. BTL_tr_state_mean/cov)."""
        if self._moments is not None:
            mean, cov = self._moments  # from update(), by offspring counts
        else:
            n, B = self._x.shape[0], self.batch
            mean = np.empty((B, n))
            cov = np.empty((B, n, n))
            moments.moments(_f64(self._cloud()), mean, cov)
        return Estimate(mean.copy(), cov + self._process_noise())

    def reinitialise(self, b: int, particles: Array) -> None:
        """Run ``b``'s cloud becomes ``particles`` (n_x, N): a lost-track recovery, after
        predict (or a fresh start after update)."""
        x = self._cloud() if self._x.flags.writeable else np.array(self._cloud())
        x[:, b, :] = particles
        self.x = x

    def adopt(self, other: ParticleFilter, runs: NDArray[np.bool_]) -> None:
        """``other``'s cloud (and modes) for ``runs`` (the robust TL's rollback to its twin)."""
        x = np.array(self.x)
        x[:, runs, :] = other.x[:, runs, :]  # (reading x gathers the clouds and their modes)
        if self.modes is not None and other.modes is not None:
            self.modes.of = np.where(runs[:, None], other.modes.of, self.modes.of)
        self.x = x

    def predicted_observation(self, sensor: MeasurementModel, R: Array) -> Observation:
        """eta_hat and P_eta_eta from the propagated cloud (seed eqs. BTL_sr_pred_obser_mean/cov).

        Angles' means are circular, and their deviations wrapped, as tracks cross the +-pi cut.
        """
        kernels = self._likelihood.kernels(sensor)
        x = self._cloud()
        if kernels is not None:
            eta, cov = kernels.predicted_observation(_f64(x), sensor)
            return Observation(sensor, eta, cov + R)
        Z = sensor.h(x)  # (n_z, B, N)
        eta = sensor.mean(Z, axis=2)  # (n_z, B)
        d = sensor.residual(Z, eta[:, :, None])
        cov = np.einsum("ibn,jbn->bij", d, d) / self.N + R
        return Observation(sensor, eta, cov)
