"""Deciding, at each step, whether a transfer is used: the paper's "hybrid system" future work.

The paper assumes the source is honest and better. A biased, diverged or stale source sends an
eta_hat_k that disagrees with the primary's own fresh measurement z_k beyond what both stated
uncertainties allow. Both are statements about the object's position at k, so they are compared
in Cartesian coordinates, linearised (which also covers sensors at different places):

    d_k = p(eta_hat_k) - p(z_k),   S_k = J_eta P_eta_eta,k J_eta' + J_z Q_w J_z',
    NIS_k = d_k' S_k^-1 d_k  ~  chi2(2) for an honest source.

The test uses no filter prior on purpose: gating against the primary's own prediction lets a
biased source that got in once drag the prior along and then always look consistent. A step uses a
transfer when three chi-square gates at ``probability`` pass, once ``min_evidence`` steps have been
seen: its own NIS; the mean NIS over the last ``window`` steps (an overconfident P_eta); and the
mean disagreement over the window, n d_bar' S_bar^-1 d_bar ~ chi2(2), which catches a bias or a
slow drift long before it shows in a single step. A transfer that passes is still tempered in
the spirit of Papež & Quinn's robust transfer: P_eta_eta is inflated by the window's mean NIS
over its expected value 2, when that exceeds 1, so a drifting source pulls less and less before
the gate shuts.

Optionally a communication budget caps the share of steps that use a transfer: a step may use one
while the run's count stays within ``fraction * k`` (a token bucket, so savings carry over).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from tltrack.models.observation import Observation

Array = NDArray[np.float64]


def disagreement(transfer: Observation, z: Observation) -> tuple[Array, Array]:
    """d_k (B, 2) and S_k (B, 2, 2) between a transfer and the primary's z_k, in x-y."""
    p_t, S_t = transfer.sensor.to_position(transfer.mean, transfer.cov)
    p_z, S_z = z.sensor.to_position(z.mean, z.cov)
    return (p_t - p_z).T, S_t + S_z


def nis(d: Array, S: Array) -> Array:
    """d' S^-1 d per run."""
    return np.einsum("bi,bi->b", d, np.linalg.solve(S, d[:, :, None])[:, :, 0])


@dataclass
class TransferPolicy:
    """Which transfers a primary uses: consistency gates, and an optional budget."""

    probability: float = 0.999  #: of an honest transfer passing each gate
    budget: float | None = None  #: at most this share of steps with a transfer
    window: int = 40
    min_evidence: int = 3
    steps: int = 0
    used: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    _history: dict[int, deque[tuple[Array, Array]]] = field(default_factory=dict)

    def select(self, z: Observation | None, transfers: Sequence[Observation]) -> list[Observation]:
        """The transfers to use at this step, each with a mask of the runs that use it."""
        self.steps += 1
        out = []
        for i, t in enumerate(transfers):
            B = t.mean.shape[1]
            if self.used.shape[0] != B:
                self.used = np.zeros(B, dtype=np.int64)
            hist = self._history.setdefault(i, deque(maxlen=self.window))
            keep = np.ones(B, dtype=bool) if t.mask is None else t.mask.copy()
            gate = chi2.ppf(self.probability, 2)
            if z is not None:
                d, S = disagreement(t, z)
                keep &= nis(d, S) <= gate
                hist.append((d, S))
            n = len(hist)
            if n < self.min_evidence:
                keep[:] = False  # not enough evidence about this source yet
                mean_nis = np.full(B, 2.0)
            else:
                mean_nis = np.mean([nis(d, S) for d, S in hist], axis=0)
                keep &= mean_nis <= chi2.ppf(self.probability, 2 * n) / n
                d_bar = np.mean([d for d, _ in hist], axis=0)
                S_bar = np.mean([S for _, S in hist], axis=0)
                keep &= n * nis(d_bar, S_bar) <= gate
            if self.budget is not None:
                keep &= self.used + 1 <= self.budget * self.steps
            self.used += keep
            temper = np.maximum(1.0, mean_nis / 2.0)[:, None, None]
            out.append(Observation(t.sensor, t.mean, t.cov * temper, keep))
        return out
