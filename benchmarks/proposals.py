"""Two more proposals for ``rpf``, measured on the runs it loses at N = 6000 (docs/rpf.md, "Two
more proposals"). Neither is in the filter: each is a subclass here whose second stage draws
x_k from another proposal, with the weights exact for it, and the engine is run with it in
place of :class:`~tltrack.filters.auxiliary.AuxiliaryParticleFilter` (for every ``rpf`` role).

- ``defensive``: a defensive mixture (Hesterberg 1995) on the process noise. Every M-th slot
  draws its noise at C times the prior's standard deviation (x = m + C L e); every particle is
  weighted with the mixture's density, q(v) = (1 - a) N(v; 0, I) + a N(v; 0, C^2 I), a = 1/M
  (the balance heuristic, unbiased for this stratified draw): tails for a turn the cloud lags.
- ``linearised``: the fully adapted auxiliary filter with the optimal proposal linearised at
  m_i = f(x_{k-1}^i) in the noise coordinates e (x = m_i + L e, so Q_v is never inverted):
  with G_s the Jacobian of h_s(m_i + L e) at e = 0 (finite differences) and d_s the residual of
  statement s, Lambda = I + sum_s G_s' R_s^-1 G_s, e ~ N(Lambda^-1 sum_s G_s' R_s^-1 d_s,
  Lambda^-1), and the first stage weighs the ancestors by that linear-Gaussian model's
  predictive likelihood. On a linear-Gaussian model the second stage's weights are all equal.

Usage: the variant, then the arguments of ``divergent_runs.py``, or ``tltrack`` and a command:

    .venv/bin/python benchmarks/proposals.py linearised \\
        docs/results/long/losses-rpf-10000/arasaratnam-haykin-random/results.json \\
        --particles 6000 --compare ""
    .venv/bin/python benchmarks/proposals.py defensive tltrack experiment --scenario ct \\
        --preset arasaratnam-haykin --truth random --filters rpf,tl-rpf,robust-tl-rpf \\
        --particles 6000 --runs 10000 --primary-intensity 4 --seed 1 --out /tmp/defensive
"""

from __future__ import annotations

import sys
from abc import ABC, abstractmethod
from collections.abc import Sequence

import divergent_runs
import numpy as np
from numba import njit
from numpy.typing import NDArray
from tltrack.cli import app
from tltrack.engine import registry
from tltrack.filters.auxiliary import AuxiliaryParticleFilter
from tltrack.filters.kernels import auxiliary
from tltrack.models.observation import Observation

Array = NDArray[np.float64]

#: defensive: every M-th slot is drawn at C times the prior's standard deviation
M, C = 10, 3.0
#: linearised: the finite-difference step along each column of L
EPS = 1e-3


class _Proposal(AuxiliaryParticleFilter, ABC):
    """The auxiliary filter with the second stage's draw replaced: :meth:`_draw` returns the
    ancestors (B, N + 1), the look-ahead they were chosen by, the particles, and each
    particle's log p(x | x_anc) / q(x | x_anc) (the prior over the proposal)."""

    def update(self, observations: Sequence[Observation]) -> None:
        if not self._pending or self._reset:
            raise RuntimeError("a proposal benchmark runs without recovery")
        anc, la, beta, x, log_pq = self._draw(observations)
        ll = np.empty(self._logw.shape)
        self._likelihood.into(x, observations, ll)
        self._second_stage(x, ll + log_pq, la, anc, beta, self._first_stage_ok)

    def _ancestors(self, la: Array, beta: float) -> NDArray[np.int64]:
        B, N = self._logw.shape
        u = np.array([g.random() for g in self.rngs])
        ok, ess = np.empty(B, dtype=np.bool_), np.empty(B)
        auxiliary.first_stage(self._logw, la, beta, u, self._anc, np.empty(N), ok, ess)
        self._first_stage_ok = ok  # a run whose weights are not finite is lost: left NaN
        return np.where(ok[:, None], self._anc, self._identity)

    @abstractmethod
    def _draw(
        self, observations: Sequence[Observation]
    ) -> tuple[NDArray[np.int64], Array, float, Array, Array]:
        """The ancestors, their look-ahead and its exponent, the particles, log p/q."""


class Defensive(_Proposal):
    def _draw(
        self, observations: Sequence[Observation]
    ) -> tuple[NDArray[np.int64], Array, float, Array, Array]:
        la = self._look_ahead(self.anchors, observations)
        anc = self._ancestors(la, self.beta)
        x = self._propagated(anc, self._x)
        E = self.gaussians()  # (r, B, N): slot i's e_i
        N, r = self.N, E.shape[0]
        wide = slice(0, N, M)
        x[:, :, wide] += (C - 1.0) * np.tensordot(self._L, E[:, :, wide], axes=1)
        a = len(range(0, N, M)) / N
        v2 = (E**2).sum(axis=0)
        v2[:, wide] *= C * C
        log_pq = -np.log((1 - a) + a * C ** (-r) * np.exp(0.5 * v2 * (1 - 1 / C**2)))
        return anc, la, self.beta, x, log_pq


@njit(cache=True)
def _gaussian_step(
    GRG: Array, GRd: Array, dRd: Array, mu: Array, chol: Array, lp: Array, logdet: Array
) -> None:
    """Per particle: Lambda = I + GRG, mu = Lambda^-1 GRd, chol chol' = Lambda^-1, the
    predictive log-likelihood lp = -(dRd - mu' Lambda mu + log det Lambda) / 2, log det Lambda."""
    B, N, r = GRd.shape
    Lam = np.empty((r, r))
    for b in range(B):
        for n in range(N):
            for j in range(r):
                for k in range(r):
                    Lam[j, k] = GRG[b, n, j, k] + (1.0 if j == k else 0.0)
            S = np.linalg.inv(Lam)
            m = S @ GRd[b, n]
            mu[b, n] = m
            chol[b, n] = np.linalg.cholesky(0.5 * (S + S.T))
            Lc = np.linalg.cholesky(Lam)
            ld = 0.0
            for j in range(r):
                ld += 2.0 * np.log(Lc[j, j])
            logdet[b, n] = ld
            lp[b, n] = -0.5 * (dRd[b, n] - m @ GRd[b, n] + ld)


class Linearised(_Proposal):
    def _draw(
        self, observations: Sequence[Observation]
    ) -> tuple[NDArray[np.int64], Array, float, Array, Array]:
        m, L = self.anchors, self._L
        (B, N), r = self._logw.shape, L.shape[1]
        GRG, GRd, dRd = np.zeros((B, N, r, r)), np.zeros((B, N, r)), np.zeros((B, N))
        for o in observations:
            s, hm = o.sensor, o.sensor.h(m)
            d = s.residual(o.mean[:, :, None], hm)  # (n_z, B, N)
            G = np.stack(
                [s.residual(s.h(m + EPS * L[:, j, None, None]), hm) / EPS for j in range(r)], 1
            )  # (n_z, r, B, N)
            Ri = np.linalg.inv(o.cov)
            on = np.ones(B) if o.mask is None else o.mask.astype(float)
            RG, Rd = np.einsum("bac,cjbn->ajbn", Ri, G), np.einsum("bac,cbn->abn", Ri, d)
            GRG += on[:, None, None, None] * np.einsum("ajbn,akbn->bnjk", G, RG)
            GRd += on[:, None, None] * np.einsum("ajbn,abn->bnj", G, Rd)
            dRd += on[:, None] * np.einsum("abn,abn->bn", d, Rd)
        mu, chol = np.empty((B, N, r)), np.empty((B, N, r, r))
        lp, logdet = np.empty((B, N)), np.empty((B, N))
        _gaussian_step(GRG, GRd, dRd, mu, chol, lp, logdet)
        anc = self._ancestors(lp, 1.0)
        xi = self.gaussians().transpose(1, 2, 0)  # (B, N, r)
        rows, a = np.arange(B)[:, None], anc[:, :N]
        e = mu[rows, a] + np.einsum("bnjk,bnk->bnj", chol[rows, a], xi)
        x = np.take_along_axis(m, a[None], axis=2) + np.einsum("ij,bnj->ibn", L, e)
        # log N(e; 0, I) - log N(e; mu, Lambda^-1), where e - mu = chol xi
        log_pq = -0.5 * (e**2).sum(-1) + 0.5 * (xi**2).sum(-1) - 0.5 * logdet[rows, a]
        return anc, lp, 1.0, np.ascontiguousarray(x), log_pq


VARIANTS = {"defensive": Defensive, "linearised": Linearised}


def main() -> None:
    if len(sys.argv) < 2 or sys.argv[1] not in VARIANTS:
        sys.exit(f"usage: proposals.py {{{','.join(VARIANTS)}}} [tltrack] ARGS...\n\n{__doc__}")
    registry.AuxiliaryParticleFilter = VARIANTS[sys.argv[1]]  # type: ignore[misc]
    rest = sys.argv[2:]
    if rest[:1] == ["tltrack"]:
        app(rest[1:])
    else:
        sys.argv = [sys.argv[0], *rest]
        divergent_runs.main()


if __name__ == "__main__":
    main()
