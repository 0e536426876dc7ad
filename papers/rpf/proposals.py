"""Two more proposals for ``rpf``, measured on the runs it loses at N = 6000 (papers/rpf/README.md,
"Two more proposals"). Neither is in the product: each is a
:class:`~tltrack.filters.auxiliary.Proposal` here, whose draw replaces the transition prior in the
auxiliary filter's second stage (which then weighs it exactly), and a filter kind that runs ``rpf``
with it, registered on import:

- ``rpf-defensive``: a defensive mixture (Hesterberg 1995) on the process noise. Every M-th slot
  draws its noise at C times the prior's standard deviation (x = m + C L e); every particle is
  weighted with the mixture's density, q(v) = (1 - a) N(v; 0, I) + a N(v; 0, C^2 I), a = 1/M
  (the balance heuristic, unbiased for this stratified draw): tails for a turn the cloud lags.
- ``rpf-linearised``: the fully adapted auxiliary filter with the optimal proposal linearised at
  m_i = f(x_{k-1}^i) in the noise coordinates e (x = m_i + L e, so Q_v is never inverted):
  with G_s the Jacobian of h_s(m_i + L e) at e = 0 (finite differences) and d_s the residual of
  statement s, Lambda = I + sum_s G_s' R_s^-1 G_s, e ~ N(Lambda^-1 sum_s G_s' R_s^-1 d_s,
  Lambda^-1), and the first stage weighs the ancestors by that linear-Gaussian model's
  predictive likelihood. On a linear-Gaussian model the second stage's weights are all equal.

Every role applies (``tl-rpf-defensive``, ``robust-tl-rpf-defensive``, ...; a TL one listens to
``source-<its kind>``), without lost-track recovery, on the local process pool (its workers are
forked with the kinds registered). Each kind draws ``rpf``'s random streams (``streams_of``), so
its runs are paired with ``rpf``'s draw for draw. Usage: ``tltrack`` and a command,
or the arguments of ``divergent_runs.py`` (its ``--rerun`` names the variants to rerun):

    .venv/bin/python papers/rpf/proposals.py \\
        papers/rpf/results/losses-rpf-10000/arasaratnam-haykin-random/results.json \\
        --particles 6000 --compare "" \\
        --rerun rpf-linearised,tl-rpf-linearised,robust-tl-rpf-linearised
    .venv/bin/python papers/rpf/proposals.py tltrack experiment --scenario ct \\
        --preset arasaratnam-haykin --truth random \\
        --filters rpf-defensive,tl-rpf-defensive,robust-tl-rpf-defensive \\
        --particles 6000 --runs 10000 --primary-intensity 4 --seed 1 --out /tmp/defensive
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence

import divergent_runs
import numpy as np
from numba import njit
from numpy.typing import NDArray
from tltrack.app import app
from tltrack.filters.auxiliary import BETA, AuxiliaryParticleFilter, Draw, Proposal
from tltrack.filters.kinds import FILTERS
from tltrack.models.base import MotionModel
from tltrack.models.observation import Observation

Array = NDArray[np.float64]

#: defensive: every M-th slot is drawn at C times the prior's standard deviation
M, C = 10, 3.0
#: linearised: the finite-difference step along each column of L
EPS = 1e-3


class Defensive:
    """The defensive mixture: the prior's draw, every M-th slot's noise scaled by C."""

    def draw(self, apf: AuxiliaryParticleFilter, observations: Sequence[Observation]) -> Draw:
        la = apf.look_ahead(apf.anchors, observations)
        anc, ok = apf.first_stage(la, apf.beta)
        x = apf.propagated(anc)
        E = apf.gaussians()  # (r, B, N): slot i's e_i
        N, r = apf.N, E.shape[0]
        wide = slice(0, N, M)
        x[:, :, wide] += (C - 1.0) * np.tensordot(apf.model.Q_sqrt, E[:, :, wide], axes=1)
        a = len(range(0, N, M)) / N
        v2 = (E**2).sum(axis=0)
        v2[:, wide] *= C * C
        log_pq = -np.log((1 - a) + a * C ** (-r) * np.exp(0.5 * v2 * (1 - 1 / C**2)))
        return Draw(anc, la, apf.beta, ok, x, log_pq)


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


class Linearised:
    """The optimal proposal linearised at the transition's mean; the first stage at beta = 1."""

    def draw(self, apf: AuxiliaryParticleFilter, observations: Sequence[Observation]) -> Draw:
        m, L = apf.anchors, apf.model.Q_sqrt
        B, N, r = apf.batch, apf.N, L.shape[1]
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
        anc, ok = apf.first_stage(lp, 1.0)
        xi = apf.gaussians().transpose(1, 2, 0)  # (B, N, r)
        rows, a = np.arange(B)[:, None], anc[:, :N]
        e = mu[rows, a] + np.einsum("bnjk,bnk->bnj", chol[rows, a], xi)
        x = np.take_along_axis(m, a[None], axis=2) + np.einsum("ij,bnj->ibn", L, e)
        # log N(e; 0, I) - log N(e; mu, Lambda^-1), where e - mu = chol xi
        log_pq = -0.5 * (e**2).sum(-1) + 0.5 * (xi**2).sum(-1) - 0.5 * logdet[rows, a]
        return Draw(anc, lp, 1.0, ok, np.ascontiguousarray(x), log_pq)


class _WithProposal(AuxiliaryParticleFilter):
    """``rpf`` with a ``proposal_class`` in place of the transition prior, drawing ``rpf``'s
    random numbers (paired with it run by run)."""

    proposal_class: type[Proposal]
    streams_of = "rpf"

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
    ) -> AuxiliaryParticleFilter:
        assert rngs is not None, "a particle filter draws from one stream per run"
        beta = params.get("rpf_beta", BETA)  # the linearised one declares none: its own is 1
        return cls(model, x0_hat, P0, particles, rngs, beta, proposal=cls.proposal_class())


@FILTERS.register
class DefensiveRPF(_WithProposal):
    kind = "rpf-defensive"
    parameters = tuple(p for p in AuxiliaryParticleFilter.parameters if p.name == "rpf_beta")
    proposal_class = Defensive


@FILTERS.register
class LinearisedRPF(_WithProposal):
    kind = "rpf-linearised"
    parameters = ()
    proposal_class = Linearised


def main() -> None:
    if sys.argv[1:2] == ["tltrack"]:
        app(sys.argv[2:])
    else:
        divergent_runs.main()


if __name__ == "__main__":
    main()
