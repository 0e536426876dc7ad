"""The auxiliary particle filter (Pitt & Shephard 1999) with a tempered look-ahead: ``rpf``.

Why: the paper's bootstrap SIR proposes from the transition prior and weighs afterwards. Its
position noise is tiny (sqrt(q1) T^2/2 = 0.16 m per step) and two sharp likelihoods (z_k and the
transfer) multiply: after resampling, a cloud whose velocity or turn rate is slightly off has no
particle left where the next measurement points, and it never comes back (lost tracks under the
paper's own parameters; papers/rpf/README.md measures it). The position at k is almost entirely
decided by x_{k-1}, so the remedy is to choose *which* particles to propagate with the data of
step k before propagating them.

One step, given the weighted cloud (x_{k-1}^i, w_{k-1}^i) and every statement of step k (z_k, the
transfers: their product is the likelihood l_k):

1. m_i = f(x_{k-1}^i), the transition's mean;
2. first stage: ancestors a_i by systematic resampling on w_{k-1}^i l_k(m_i)^beta;
3. x_k^i = m_{a_i} + L v_i, v_i ~ N(0, I_r) with L = Q_sqrt (the prior as proposal, so Q_v is
   sampled through its square root and never inverted);
4. second stage: w_k^i ∝ l_k(x_k^i) / l_k(m_{a_i})^beta, normalised.

The weights are exact for this proposal: the first stage's factor l_k(m)^beta is divided out in
the second, so (x_k^i, w_k^i) targets p(x_k | z_{1:k}) with no heuristic reweighting; beta = 0
is the bootstrap filter with the resampling moved before the propagation. beta < 1 tempers the
look-ahead, because l_k(m) ignores the spread L v adds (it would be overconfident at beta = 1 when
the likelihood is sharper than that spread). The estimate is the weighted cloud's mean and
covariance plus Q_v, as the paper writes the SIR's.

Regularisation (``bandwidth`` h > 0, off by default). Position is nearly deterministic given the
velocity and the turn rate, so resampling every step can shrink the cloud's genealogy to a few
ancestors: the cloud then spreads over metres where the posterior spreads over tens of metres,
and, once the target manoeuvres, it sits beside the measurements with no particle on them
(papers/rpf/README.md, "Regularisation"). When the first stage's weights are degenerate
(effective sample size below ``ess_min`` N), the cloud of x_{k-1} is first redrawn from the
Liu-West shrinkage kernel (Liu & West 2001; the regularised PF of Musso, Oudjane & Le Gland 2001):

    x_{k-1}^i  <-  a x_{k-1}^i + (1 - a) mu + h D e_i,   a = sqrt(1 - h^2),  D D^T = Sigma,

with (mu, Sigma) the weighted cloud's mean and covariance and e_i ~ N(0, I): the smoothed cloud
keeps the weighted mean and covariance, and its particles are new. The steps above then run on
it unchanged, so the weights stay exact for the proposal. The kernel's Gaussians come from a
child of the run's stream (``Generator.spawn``), drawn only when a run is regularised: with
h = 0, or on a step that does not fire, every number is the unregularised filter's.

Random numbers, per run and in this order, are the bootstrap filter's: the propagation's
uniforms in ``predict`` (so a source can preview its predicted cloud, slot i taking noise v_i
whatever its ancestor, and then propagate with the very same noise), and one uniform in
``update`` for the systematic offset. The fast path (:mod:`~.fastpath`) runs every pass as a
kernel for the models it lists; any other model runs the same algorithm in NumPy.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.filters import fastpath
from tltrack.filters.base import Estimate
from tltrack.filters.kernels import auxiliary, gaussians
from tltrack.filters.likelihood import Likelihood
from tltrack.filters.particle import initial_cloud
from tltrack.filters.particle_modes import ParticleModes
from tltrack.models.base import MeasurementModel, MotionModel
from tltrack.models.modes import MotionModes
from tltrack.models.observation import Observation
from tltrack.models.scan import Statement

Array = NDArray[np.float64]

#: the look-ahead's exponent (papers/rpf/README.md, "tuning": chosen on seed 11, not on reported
#: seeds)
BETA = 0.3
#: regularise a run when its first-stage effective sample size is below this share of N
ESS_MIN = 0.1


@dataclass(frozen=True)
class Draw:
    """What a :class:`Proposal` drew for a step: the ancestors (B, N + 1) chosen on the
    look-ahead ``look_ahead`` (B, N) to the power ``beta``, whether each run's first stage
    succeeded, the particles (n_x, B, N), and each particle's log p(x | x_anc) / q(x | x_anc)."""

    ancestors: NDArray[np.int64]
    look_ahead: Array
    beta: float
    ok: NDArray[np.bool_]
    x: Array
    log_prior_over_proposal: Array


class Proposal(Protocol):
    """Another second-stage proposal than the transition prior, passed in as a component.

    The filter's second stage then weighs its draw exactly (the prior over the proposal enters
    the weights), so any proposal keeps the posterior right. It runs on the generic path.
    """

    def draw(self, apf: AuxiliaryParticleFilter, observations: Sequence[Statement]) -> Draw:
        """The step's draw, from the filter's public pieces (anchors, first_stage, ...)."""


class AuxiliaryParticleFilter:
    """The auxiliary particle filter over B runs, with the :class:`~tltrack.filters.base.Filter`
    interface; one random stream per run, as :class:`~tltrack.filters.particle.ParticleFilter`.

    ``proposal``: a :class:`Proposal` in place of the transition prior (none: the prior).
    """

    kind: ClassVar[str] = "rpf"
    particle: ClassVar[bool] = True
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter("rpf_beta", "1", "rpf: the look-ahead's exponent beta", default=BETA, ge=0),
        Parameter(
            "rpf_bandwidth",
            "1",
            "rpf: the regularisation kernel's bandwidth h (0: off; papers/rpf/README.md)",
            default=0.0,
            ge=0,
            lt=1,
        ),
    )

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
    ) -> AuxiliaryParticleFilter:
        assert rngs is not None, "a particle filter draws from one stream per run"
        return cls(
            model,
            x0_hat,
            P0,
            particles,
            rngs,
            beta=params["rpf_beta"],
            bandwidth=params["rpf_bandwidth"],
            modes=modes,
        )

    def __init__(
        self,
        model: MotionModel,
        x0_hat: Array,
        P0: Array,
        n_particles: int,
        rngs: Sequence[np.random.Generator],
        beta: float = BETA,
        bandwidth: float = 0.0,
        ess_min: float = ESS_MIN,
        proposal: Proposal | None = None,
        modes: MotionModes | None = None,
    ) -> None:
        """Draw N particles per run from N(x0_hat[:, b], P0), equally weighted.

        ``modes``: a jump-Markov motion model; each particle then carries a mode, drawn from the
        chain before the first stage, so its look-ahead point is f_m(x) of its new mode m
        (:mod:`~tltrack.filters.particle_modes`); ``model`` is then its first mode's.
        """
        if not 0.0 <= bandwidth < 1.0:
            raise ValueError(f"bandwidth must be in [0, 1), not {bandwidth}")
        model = model if modes is None else modes.models[0]
        self.model, self.rngs, self.N, self.beta = model, list(rngs), n_particles, beta
        self.bandwidth, self.ess_min, self.proposal = bandwidth, ess_min, proposal
        self._kernel_rngs = [g.spawn(1)[0] for g in self.rngs] if bandwidth > 0 else []
        self.modes = None if modes is None else ParticleModes(modes, self.rngs, n_particles)
        self._next: NDArray[np.int64] | None = None  # each slot's mode for the pending step
        #: the last ancestry and the modes gathered along it (:meth:`_chosen_modes`)
        self._gathered: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None
        #: how many times each run was regularised
        self.regularised = np.zeros(len(self.rngs), dtype=np.int64)
        B = x0_hat.shape[1]
        self._x: Array = np.ascontiguousarray(initial_cloud(x0_hat, P0, self.N, self.rngs))
        self._logw = np.full((B, self.N), -np.log(self.N))
        self._L = fastpath.f64(model.Q_sqrt)
        self._r = self._L.shape[1]
        self._propagate = fastpath.propagator(model, self.N)
        self._likelihood = Likelihood(B)
        self._U = np.empty((B, gaussians.uniforms_per_run(self._r, self.N)))
        self._pending = False  # predict() was called: the propagation waits for update()
        self._preview: Array | None = None  # the unselected predicted cloud, when asked for
        self._means: Array | None = None  # f(x_{k-1}^i) of the pending step, once computed
        self._reset: dict[int, Array] = {}  # runs a recovery redrew while pending
        self._moments: tuple[Array, Array] | None = None
        self._anc = np.empty((B, self.N + 1), dtype=np.int64)
        self._identity = np.broadcast_to(np.arange(self.N + 1), (B, self.N + 1)).copy()

    @property
    def batch(self) -> int:
        return len(self.rngs)

    # ---- the Filter interface ---------------------------------------------------------------

    def predict(self) -> None:
        """Draw the propagation's noise; the propagation itself waits for the data of the step
        (:meth:`update`). Two predicts in a row move the cloud on, its weights unchanged."""
        if self._pending:
            self._x = self._propagated(self._identity)
            self._apply_reset(self._x)
            self._reset = {}
            if self.modes is not None and self._next is not None:
                self.modes.of = self._next
        for b, g in enumerate(self.rngs):
            g.random(out=self._U[b])
        if self.modes is not None:
            self._next, self._gathered = self.modes.switch(self.modes.of), None
        self._pending, self._preview, self._means, self._moments = True, None, None, None

    def update(self, observations: Sequence[Statement]) -> None:
        """The two stages on every statement of the step (eqs. in the module docstring)."""
        if not self._pending:
            raise RuntimeError("update() needs predict() first")
        if self.proposal is not None:
            if self._reset:
                raise RuntimeError("a Proposal takes no lost-track recovery: run without it")
            d = self.proposal.draw(self, observations)
            ll = np.empty(self._logw.shape)
            self._likelihood.into(d.x, observations, ll)
            ll += d.log_prior_over_proposal
            self._second_stage(d.x, ll, d.look_ahead, d.ancestors, d.beta, d.ok)
            return
        x_prev, (B, N) = self._x, self._logw.shape
        la = self._look_ahead(self.anchors, observations)
        u = np.array([g.random() for g in self.rngs])
        ok, ess = np.empty(B, dtype=np.bool_), np.empty(B)
        auxiliary.first_stage(self._logw, la, self.beta, u, self._anc, np.empty(N), ok, ess)
        if self.bandwidth > 0:
            fire = ok & (ess < self.ess_min)
            fire[list(self._reset)] = False
            if fire.any():
                x_prev = self._regularise(x_prev, fire)
                la = self._look_ahead(self._transition_means(x_prev), observations)
                auxiliary.first_stage(self._logw, la, self.beta, u, self._anc, np.empty(N), ok, ess)
        for b in self._reset:  # a redrawn run takes its new particles as they are
            la[b] = 0.0
            ok[b] = True
        anc = np.where(ok[:, None], self._anc, self._identity)  # a failed run stays NaN below
        x = self._propagated(anc, x_prev)
        self._apply_reset(x)
        ll = np.empty((B, N))
        self._likelihood.into(x, observations, ll)
        self._second_stage(x, ll, la, anc, self.beta, ok)

    def _second_stage(
        self,
        x: Array,
        ll: Array,
        la: Array,
        anc: NDArray[np.int64],
        beta: float,
        ok: NDArray[np.bool_],
    ) -> None:
        """The propagated cloud ``x``, weighed by ``ll`` over ``beta`` ``la`` of its ancestors,
        becomes the posterior; a run not ``ok``, or whose weights are not finite, reads as lost."""
        B, N = ll.shape
        mean, cov = np.empty((B, x.shape[0])), np.empty((B, x.shape[0], x.shape[0]))
        auxiliary.second_stage(ll, la, anc, beta, x, self._logw, mean, cov, ok, np.empty(N))
        if not ok.all():  # weights not finite (NaN particles): the run reads as lost
            x[:, ~ok, :] = np.nan
            self._logw[~ok] = -np.log(N)
            mean[~ok], cov[~ok] = np.nan, np.nan
        self._x, self._moments = x, (mean, cov)
        self._pending, self._preview, self._means, self._reset = False, None, None, {}
        if self.modes is not None and self._next is not None:
            self.modes.of = self._chosen_modes(anc)

    @property
    def anchors(self) -> Array:
        """m_i = f(x_{k-1}^i) after ``predict``: where the first stage weighs the step's data,
        so where a lost-track test looks too. Computed once a step and shared with the update
        (the noisy predicted cloud, :attr:`x`, would be one more propagation). Read-only."""
        if not self._pending:
            raise RuntimeError("anchors exist between predict() and update() only")
        if self._means is None:
            self._means = self._transition_means(self._x)
            self._means.flags.writeable = False
        return self._means

    def _transition_means(self, x_prev: Array) -> Array:
        if self.modes is not None and self._next is not None:
            return np.ascontiguousarray(self.modes.means(x_prev, self._next))
        m = np.empty_like(x_prev)
        if self._propagate is not None and self._fast(x_prev):
            self._propagate.mean(x_prev, m)
            return m
        return np.ascontiguousarray(self.model.f(x_prev))

    def first_stage(
        self, look_ahead: Array, beta: float
    ) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        """Ancestors (B, N + 1) by systematic resampling on w_{k-1} l^beta, drawing the step's
        offset, and which runs succeeded (a run whose weights are not finite keeps its own)."""
        B, N = self._logw.shape
        u = np.array([g.random() for g in self.rngs])
        ok, ess = np.empty(B, dtype=np.bool_), np.empty(B)
        auxiliary.first_stage(self._logw, look_ahead, beta, u, self._anc, np.empty(N), ok, ess)
        return np.where(ok[:, None], self._anc, self._identity), ok

    def look_ahead(self, m: Array, observations: Sequence[Statement]) -> Array:
        """log l_k(m_i): the step's likelihood at points ``m`` (n_x, B, N)."""
        return self._look_ahead(m, observations)

    def propagated(self, ancestors: NDArray[np.int64]) -> Array:
        """f(x_{k-1}^{a_i}) + L v_i with this step's noise v: the prior's draw (a new array)."""
        return self._propagated(ancestors, self._x)

    @property
    def log_weights(self) -> Array:
        """log w_{k-1} (B, N) before an update, log w_k after, normalised. Read-only."""
        view = self._logw.view()
        view.flags.writeable = False
        return view

    def _look_ahead(self, m: Array, observations: Sequence[Statement]) -> Array:
        """log l_k(m_i), the first stage's look-ahead."""
        la = np.empty(self._logw.shape)
        self._likelihood.into(m, observations, la)
        return la

    def _regularise(self, x_prev: Array, runs: NDArray[np.bool_]) -> Array:
        """The cloud with ``runs`` redrawn from the Liu-West shrinkage kernel (module docstring):
        weighted mean and covariance kept, particles new."""
        h = self.bandwidth
        a = np.sqrt(1.0 - h * h)
        x = np.array(x_prev)
        w = self._weights()
        for b in np.flatnonzero(runs):
            mu, Sigma = (v[0] for v in _weighted_moments(x_prev[:, b : b + 1], w[b : b + 1]))
            D = _cholesky_psd(Sigma)
            e = self._kernel_rngs[b].standard_normal((len(mu), self.N))
            x[:, b] = a * x_prev[:, b] + (1.0 - a) * mu[:, None] + h * (D @ e)
            self.regularised[b] += 1
        return x

    def estimate(self) -> Estimate:
        """The weighted cloud's mean and covariance, plus Q_v (as the paper's SIR reports)."""
        w = None
        if self._moments is None:
            w = self._weights()
            self._moments = _weighted_moments(self.x, w)
        mean, cov = self._moments
        if self.modes is None:
            return Estimate(mean.copy(), cov + self.model.Q)
        p = self._mode_shares(self._weights() if w is None else w)  # an exp over (B, N): reused
        return Estimate(mean.copy(), cov + np.einsum("mb,mij->bij", p, self.modes.Qs))

    @property
    def mode_probabilities(self) -> Array | None:
        """(M, B): each motion mode's weighted share of the cloud; None without modes."""
        return None if self.modes is None else self._mode_shares(self._weights())

    def _mode_shares(self, w: Array) -> Array:
        assert self.modes is not None
        modes = self.modes.of if not self._pending or self._next is None else self._next
        return self.modes.probabilities(modes, w)

    def predicted_observation(self, sensor: MeasurementModel, R: Array) -> Observation:
        """eta_hat and P_eta_eta: the weighted moments of h over the predicted cloud (seed eqs.
        BTL_sr_pred_obser_mean/cov, with the weights an auxiliary filter carries)."""
        x = self.x
        kernels = self._likelihood.kernels(sensor)
        if kernels is not None and self._fast(x):
            eta, cov = kernels.predicted_observation(x, sensor, self._logw)
            return Observation(sensor, eta, cov + R)
        Z = sensor.h(x)  # (n_z, B, N)
        w = self._weights()
        eta = sensor.mean(Z, axis=2, weights=w)
        D = sensor.residual(Z, eta[:, :, None])
        cov = np.einsum("ibn,jbn->bij", D * w[None], D)
        return Observation(sensor, eta, cov + R)

    def adopt(self, other: AuxiliaryParticleFilter, runs: NDArray[np.bool_]) -> None:
        """``other``'s weighted cloud for ``runs`` (the robust TL's rollback to its twin)."""
        if self._pending or other._pending:
            raise RuntimeError("adopt() between update() and predict() only")
        self._x = np.array(self._x)
        self._x[:, runs] = other._x[:, runs]
        self._logw[runs] = other._logw[runs]
        if self.modes is not None and other.modes is not None:
            self.modes.of = np.where(runs[:, None], other.modes.of, self.modes.of)
        if self._moments is not None and other._moments is not None:
            mean, cov = (np.array(a) for a in self._moments)
            mean[runs], cov[runs] = other._moments[0][runs], other._moments[1][runs]
            self._moments = (mean, cov)

    # ---- the cloud --------------------------------------------------------------------------

    @property
    def x(self) -> Array:
        """The particles (n_x, B, N): after predict, the predicted cloud (each particle moved by
        its own noise, unselected); after update, the weighted posterior cloud. Read-only: a
        recovery redraws a run through :meth:`reinitialise`."""
        if self._pending:
            if self._preview is None:
                self._preview = self._propagated(self._identity)
                self._apply_reset(self._preview)
                self._preview.flags.writeable = False
            return self._preview
        return self._x

    def reinitialise(self, b: int, particles: Array) -> None:
        """Run ``b`` restarts from ``particles`` (n_x, N), equally weighted: after predict, they
        are its predicted cloud, weighed by this step's statements alone (a lost-track
        recovery)."""
        self._logw[b] = -np.log(self.N)
        if self._pending:
            self._reset[b] = np.array(particles, dtype=np.float64)
            self._preview = None
        else:
            self._x = np.array(self._x)
            self._x[:, b, :] = particles
            self._moments = None

    def gaussians(self) -> Array:
        """This step's process-noise Gaussians (r, B, N), made from the uniforms of predict."""
        E = np.empty((self.batch, self._r, self.N))
        gaussians.gaussians(self._U, E)
        return E.transpose(1, 0, 2)

    def _weights(self) -> Array:
        w = np.exp(self._logw - self._logw.max(axis=1, keepdims=True))
        return np.asarray(w / w.sum(axis=1, keepdims=True))

    def _fast(self, x: Array) -> bool:
        return x.dtype == np.float64 and x.flags.c_contiguous

    def _propagated(self, anc: NDArray[np.int64], x_prev: Array | None = None) -> Array:
        """x^i = f(x_prev^{anc_i}) + L v_i with this step's noise v (slot i: v_i); with modes,
        f and L of the ancestor's new mode."""
        src = self._x if x_prev is None else x_prev
        if self.modes is not None and self._next is not None:
            modes = self._chosen_modes(anc)
            return self.modes.propagate(src, anc, modes, self._U, self.gaussians)
        if self._propagate is not None and self._fast(src):
            out = np.empty_like(src)
            for b in range(self.batch):
                self._propagate(src, anc, self._U[b : b + 1], out, b)
            return out
        chosen = np.take_along_axis(src, anc[None, :, : self.N], axis=2)
        return np.ascontiguousarray(
            self.model.f(chosen) + np.tensordot(self._L, self.gaussians(), axes=1)
        )

    def _chosen_modes(self, anc: NDArray[np.int64]) -> NDArray[np.int64]:
        """Each slot's new mode, its ancestor's: gathered once per ancestry (the propagation
        and the update of a step ask for the same)."""
        assert self._next is not None and self.modes is not None
        if anc is self._identity:  # the predicted cloud's: every slot its own ancestor
            return self._next
        if self._gathered is None or self._gathered[0] is not anc:
            modes = self.modes.gather(self._next, anc)
            self._gathered = (anc, modes)
        return self._gathered[1]

    def _apply_reset(self, x: Array) -> None:
        for b, particles in self._reset.items():
            x[:, b, :] = particles


def _cholesky_psd(S: Array) -> Array:
    """A square root D (D D^T = S) of a covariance that may be singular (a cloud whose turn rate
    or position collapsed): the Cholesky factor when it exists, else the eigen square root."""
    try:
        return np.asarray(np.linalg.cholesky(S), dtype=np.float64)
    except np.linalg.LinAlgError:
        lam, V = np.linalg.eigh(S)
        return np.asarray(V * np.sqrt(np.clip(lam, 0.0, None)))


def _weighted_moments(x: Array, w: Array) -> tuple[Array, Array]:
    """Mean (B, n) and covariance (B, n, n) of clouds x (n, B, N) with weights w (B, N)."""
    mean = np.einsum("ibn,bn->bi", x, w)
    d = x - mean.T[:, :, None]
    return mean, np.einsum("ibn,jbn->bij", d * w[None], d)
