"""The SIR particle filter of the seed's Sec. IV, batched over B runs.

With the transition prior as proposal and resampling at every step, the weight of particle i is
the product of the Gaussian likelihoods of every observation (seed eqs. TL_tr_weights_1/2):

    w_k^(i)  ∝  p(z_k | x_k^(i)) · p(eta_hat_k | x_k^(i))

An isolated PF passes only z_k; TL-PF adds the source's transfer; centralized fusion adds the
source's raw measurement instead. Weights stay in the log domain, so two sharp likelihoods whose
product underflows in linear space still normalise (no 0/0).

Particles are stored ``(n_x, B, N)``: each state component of each run is one contiguous row.

Speed: the coordinated-turn and constant-velocity models (by exact type), range-bearing sensors
(by exact type), systematic resampling and the moments run as numba kernels
(:mod:`tltrack.filters.kernels`). Any other motion model or sensor takes the generic NumPy path,
with the same random numbers. Each step draws, from each run's own generator and in this order:
``uniforms_per_run(r, N)`` uniforms in ``predict`` (made into the r = rank(Q_v) Gaussians per
particle by Box-Muller), then one uniform in ``update`` (the systematic offset). A run's numbers
therefore never depend on the batch size.

``update`` does not write the resampled cloud out: it keeps the ancestor indices, the next
``predict`` propagates through them, and ``estimate`` takes the resampled cloud's moments from the
offspring counts. Reading :attr:`ParticleFilter.x` gathers the cloud on demand (read-only until
the next ``predict``: the estimate was computed from it; assign a new array to replace it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tltrack.filters import kernels
from tltrack.filters.base import Estimate
from tltrack.models.measurement import RangeBearing
from tltrack.models.motion import POS, ConstantVelocity, CoordinatedTurn, MotionModel
from tltrack.models.observation import Observation

Array = NDArray[np.float64]


def gaussian_loglik(obs: Observation, x: Array) -> Array:
    """log N(obs.mean; h(x), obs.cov) up to a per-run constant, (B, N) (eq. TL_tr_likelihood_2).

    The generic path, for any sensor with ``h`` and ``residual``; range-bearing sensors use
    :func:`tltrack.filters.kernels.rb_loglik`, which computes the same quantity.
    """
    d = obs.sensor.residual(obs.mean[:, :, None], obs.sensor.h(x))  # (2, B, N)
    Pinv = np.linalg.inv(obs.cov)  # (B, 2, 2)
    a = Pinv[:, 0, 0, None]
    b = Pinv[:, 0, 1, None]
    c = Pinv[:, 1, 1, None]
    rho = -0.5 * (a * d[0] * d[0] + 2.0 * b * d[0] * d[1] + c * d[1] * d[1])
    if obs.mask is not None:
        rho = np.where(obs.mask[:, None], rho, 0.0)
    return rho


def _f64(a: Array) -> Array:
    return np.ascontiguousarray(a, dtype=np.float64)


class ParticleFilter:
    """SIR-PF with systematic resampling at every step; one random stream per run.

    ``update`` leaves the resampled cloud as (pre-resampling cloud, ancestor indices): the next
    ``predict`` propagates through the ancestors directly, and the estimate's moments come from the
    offspring counts, so the resampled cloud is never written out unless :attr:`x` is read.
    """

    def __init__(
        self,
        model: MotionModel,
        x0_hat: Array,
        P0: Array,
        n_particles: int,
        rngs: Sequence[np.random.Generator],
    ) -> None:
        """Draw N particles per run from N(x0_hat[:, b], P0); ``x0_hat`` is (n_x, B)."""
        self.model = model
        self.rngs = list(rngs)
        self.N = n_particles
        n, B = x0_hat.shape
        if len(self.rngs) != B:
            raise ValueError(f"{len(self.rngs)} random streams for a batch of {B} runs")
        L0 = np.linalg.cholesky(P0)
        eps = np.empty((n, B, self.N))
        for b, g in enumerate(self.rngs):
            eps[:, b, :] = g.standard_normal((n, self.N))
        L = np.asarray(model.Q_sqrt, dtype=np.float64)
        self._L = _f64(L)
        self._r = L.shape[1]
        self._motion = self._motion_kind(model, L)
        self._U1 = np.empty((1, kernels.uniforms_per_run(self._r, self.N)))  # one run's uniforms
        self._A = _f64(model.A) if isinstance(model, ConstantVelocity) else np.eye(n)
        self._e = np.empty((self._r, self.N))  # one run's Gaussians, scratch shared by the batch
        self._g = np.empty((n, kernels.BLOCK))  # a block of resampled particles (scratch)
        self._logw = np.empty((B, self.N))
        self._u = np.empty(B)  # this step's systematic offsets
        self._packs: dict[int, tuple[Array, Array, Array, NDArray[np.bool_]]] = {}
        self._anc = np.empty((B, self.N + 1), dtype=np.int64)  # ancestors (+ a scratch column)
        self._pre: Array | None = None  # the cloud before resampling, while x is not gathered
        self._moments: tuple[Array, Array] | None = None  # of the resampled cloud, from update()
        self.x = x0_hat[:, :, None] + np.tensordot(L0, eps, axes=1)

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

    def _cloud(self) -> Array:
        """The current cloud, gathered from (pre-resampling cloud, ancestors) if need be."""
        if self._pre is not None:
            out = np.empty_like(self._pre)
            kernels.gather(self._pre, self._anc, out)
            out.flags.writeable = False
            self._x, self._pre = out, None
        return self._x

    @staticmethod
    def _motion_kind(model: MotionModel, L: Array) -> str:
        if type(model) is CoordinatedTurn and L.shape == (5, 3):
            return "ct"
        if type(model) is ConstantVelocity and L.shape == (4, 2):
            return "cv"
        return "generic"

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
        E = np.empty((self.batch, self._r, self.N))
        kernels.gaussians(self._draw_uniforms(), E)
        return E.transpose(1, 0, 2)

    def predict(self) -> None:
        """x_k^(i) ~ p(x_k | x_{k-1}^(i)) (seed eq. BTL_tr_particle_2), noise through Q_sqrt."""
        if self._pre is not None:
            src, anc = self._pre, self._anc
        else:  # not resampled yet (the first step): every particle is its own ancestor
            src, anc = self._x, self._anc
            anc[:] = np.arange(self.N + 1)
        if self._motion == "generic" or src.dtype != np.float64 or not src.flags.c_contiguous:
            x = self._cloud()
            self.x = self.model.f(x) + np.tensordot(self._L, self.gaussians(), axes=1)
            return
        out = np.empty_like(src)
        m = self.model
        # Run by run: a run's uniforms are drawn into one reused row, still in cache when read
        U = self._U1
        for b, g in enumerate(self.rngs):
            g.random(out=U[0])
            if self._motion == "ct":
                assert isinstance(m, CoordinatedTurn)
                kernels.ct_predict(
                    src, anc, U, self._e, self._g, float(m.T), float(m.SMALL), self._L, out, b
                )
            else:
                kernels.cv_predict(src, anc, U, self._e, self._g, self._A, self._L, out, b)
        self.x = out

    def _split(
        self, observations: Sequence[Observation]
    ) -> tuple[tuple[Array, Array, Array, NDArray[np.bool_]] | None, list[Observation]]:
        """The range-bearing statements packed for the kernels, and the others (generic path)."""
        fast = self._x.dtype == np.float64 and self._x.flags.c_contiguous
        rb: list[Observation] = []
        others: list[Observation] = []
        for o in observations:
            (
                rb if fast and type(o.sensor) is RangeBearing and o.mean.shape[0] == 2 else others
            ).append(o)
        if not rb:
            return None, others
        pos, mean, cov, mask = packed = self._packing(len(rb))
        for j, o in enumerate(rb):
            pos[j, 0], pos[j, 1] = o.sensor.position
            mean[j] = o.mean
            cov[j] = o.cov
            mask[j] = True if o.mask is None else o.mask
        return packed, others

    def _loglik_into(self, observations: Sequence[Observation], logw: Array) -> None:
        """Write the sum of every observation's log-likelihood into ``logw`` (B, N)."""
        x = self._cloud()
        packed, others = self._split(observations)
        if packed is not None:
            kernels.rb_loglik(x, POS[0], POS[1], *packed, logw)
        else:
            logw[...] = 0.0
        for o in others:
            logw += gaussian_loglik(o, x)

    def _packing(self, M: int) -> tuple[Array, Array, Array, NDArray[np.bool_]]:
        """Reused buffers (positions, means, covariances, masks) for M range-bearing statements."""
        if M not in self._packs:
            B = self.batch
            self._packs[M] = (
                np.empty((M, 2)),
                np.empty((M, 2, B)),
                np.empty((M, B, 2, 2)),
                np.empty((M, B), dtype=np.bool_),
            )
        return self._packs[M]

    def log_weights(self, observations: Sequence[Observation]) -> Array:
        """Unnormalised log-weights (B, N): the sum of every observation's log-likelihood."""
        logw = np.empty((self.batch, self.N))
        self._loglik_into(observations, logw)
        return logw

    def update(self, observations: Sequence[Observation]) -> None:
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
        packed, others = self._split(observations)
        if packed is not None and not others:  # likelihood and resampling fused, run by run
            good = kernels.rb_update(
                x, POS[0], POS[1], *packed, u, self._anc, mean, cov, ok, self._logw[0]
            )
        else:
            self._loglik_into(observations, self._logw)
            good = kernels.resample(self._logw, u, x, self._anc, mean, cov, ok)
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
            kernels.moments(_f64(self._cloud()), mean, cov)
        return Estimate(mean.copy(), cov + self.model.Q)

    def adopt(self, other: ParticleFilter, runs: NDArray[np.bool_]) -> None:
        """``other``'s cloud for ``runs`` (the robust TL's rollback to its isolated twin)."""
        x = np.array(self.x)
        x[:, runs, :] = other.x[:, runs, :]
        self.x = x

    def predicted_observation(self, sensor: RangeBearing, R: Array) -> Observation:
        """eta_hat and P_eta_eta from the propagated cloud (seed eqs. BTL_sr_pred_obser_mean/cov).

        The bearing's mean is circular, and deviations are wrapped, as tracks cross the +-pi cut.
        """
        if type(sensor) is RangeBearing:
            B = self.batch
            eta = np.empty((2, B))
            cov = np.empty((B, 2, 2))
            sx, sy = sensor.position
            kernels.rb_predicted_obs(
                _f64(self._cloud()), POS[0], POS[1], float(sx), float(sy), eta, cov
            )
            return Observation(sensor, eta, cov + R)
        Z = sensor.h(self._cloud())  # (2, B, N)
        eta = sensor.mean(Z, axis=2)  # (2, B)
        d = sensor.residual(Z, eta[:, :, None])
        cov = np.einsum("ibn,jbn->bij", d, d) / self.N + R
        return Observation(sensor, eta, cov)


def warm_up() -> None:
    """Load (or, on a cold cache, compile) every fast-path kernel, on a tiny problem.

    Call it in a parent process before starting workers, so they find numba's cache on disk
    instead of compiling the same kernels side by side.
    """
    from tltrack.filters.resampling import systematic_indices

    rngs = [np.random.default_rng(0)]
    sensor = RangeBearing(10.0, 0.01)
    z = Observation.broadcast(sensor, np.array([1500.0, 0.5]), sensor.R(1.0))
    for model in (CoordinatedTurn(T=1.0, q1=0.1, q2=1e-4), ConstantVelocity(T=1.0, q=0.1)):
        n = model.n
        x0 = np.full((n, 1), 1000.0)
        pf = ParticleFilter(model, x0, np.eye(n), 8, rngs)
        pf.predict()
        pf.estimate()
        pf.predicted_observation(sensor, sensor.R(1.0))
        pf.update([z, z])
        pf.estimate()
        _ = pf.x
        pf.gaussians()
    systematic_indices(np.full((1, 4), 0.25), rngs)
