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
slow drift long before it shows in a single step.

No test can tell a slow drift from noise before the primary's own data resolve it, so three more
measures, in the spirit of Papež & Quinn's robust transfer, bound what an undetected fault costs:

1. tempering: P_eta_eta is scaled by the window's mean NIS over its ``temper_quantile`` under
   honesty, when that exceeds 1 (an overconfident source);
2. discounting: P_eta_eta grows by an estimate of b b' for a constant bias b between source and
   primary, the positive part of d_bar d_bar' - S_bar / n (in the source's coordinates): near zero
   for an honest source, and growing with a drifting one before any gate shuts;
3. rollback: when the window's evidence against a source that a run has used passes the far
   stricter ``rollback_probability``, the run rolls back to the primary's isolated twin
   (:attr:`TransferPolicy.forget`), so the fault leaves no lasting harm.

The window (20 steps), the discount's form, the tempering quantile and the rollback level were
chosen among a few candidates on seed 1 (``tltrack study robust --seed 1``);
papers/robust/README.md reports seed 0.

Optionally a communication budget caps the share of steps that use a transfer: a step may use one
while the run's count stays within ``fraction * k`` (a token bucket, so savings carry over).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tltrack.filters import chi2
from tltrack.models.base import MeasurementModel, PositionFix
from tltrack.models.observation import Observation

Array = NDArray[np.float64]


class NotComparableError(ValueError):
    """Robust transfer was asked of sensors whose measurements it cannot compare."""


def position_fix(sensor: MeasurementModel) -> PositionFix:
    """``sensor`` as a :class:`PositionFix`, or :class:`NotComparableError` naming its kind.

    The policy compares a transfer with the primary's own measurement without any filter prior
    (see the module docstring), so both must fix a position on their own: a bearing-only
    sensor's does not, and such a pair is refused at start rather than judged blindly.
    """
    if not isinstance(sensor, PositionFix):
        raise NotComparableError(
            f"robust transfer compares each transfer with the primary's measurement as "
            f"positions, without a filter prior; a {sensor.kind} sensor's measurement fixes no "
            "position, so use tl- (unjudged transfer) with it"
        )
    return sensor


def disagreement(transfer: Observation, z: Observation) -> tuple[Array, Array]:
    """d_k (B, 2) and S_k (B, 2, 2) between a transfer and the primary's z_k, in x-y."""
    p_t, S_t = position_fix(transfer.sensor).to_position(transfer.mean, transfer.cov)
    p_z, S_z = position_fix(z.sensor).to_position(z.mean, z.cov)
    return (p_t - p_z).T, S_t + S_z


def nis(d: Array, S: Array) -> Array:
    """d' S^-1 d per run."""
    return np.einsum("bi,bi->b", d, np.linalg.solve(S, d[:, :, None])[:, :, 0])


#: The window's evidence per run: mean NIS, mean disagreement d_bar, mean S_bar.
Evidence = tuple[Array, Array, Array]


def evidence(hist: Sequence[tuple[Array, Array]]) -> Evidence:
    return (
        np.mean([nis(d, S) for d, S in hist], axis=0),
        np.mean([d for d, _ in hist], axis=0),
        np.mean([S for _, S in hist], axis=0),
    )


def bias_second_moment(d_bar: Array, S_bar: Array, n: int) -> Array:
    """An estimate of b b' for a constant bias b between source and primary, in x-y (B, 2, 2).

    E[d_bar d_bar'] = b b' + S_bar / n, so d_bar d_bar' - S_bar / n is unbiased; its positive
    part keeps it a covariance. An honest source's is near zero, so it keeps its precision.
    """
    M = np.einsum("bi,bj->bij", d_bar, d_bar) - S_bar / n
    w, V = np.linalg.eigh(M)
    return (V * np.maximum(w, 0.0)[:, None, :]) @ V.transpose(0, 2, 1)


@dataclass
class TransferPolicy:
    """Which transfers a primary uses, and which runs must forget the transfers they used.

    A single inconsistent step only skips that transfer, and so does a window whose evidence is
    against the source at ``probability``. When that evidence passes the far stricter
    ``rollback_probability``, in a run that used the source since its last rollback,
    :attr:`forget` marks the run: whatever the source taught the filter is suspect, so the primary
    rolls back to its isolated twin (see :class:`~tltrack.filters.transfer.Primary`). A false
    alarm then costs an honest source a skipped step, rarely its whole gain.
    """

    probability: float = 0.999  #: of an honest transfer passing each gate
    budget: float | None = None  #: at most this share of steps with a transfer
    window: int = 20
    min_evidence: int = 3
    rollback_probability: float = 1.0 - 1e-6
    temper_quantile: float = 0.9  #: mean NIS above this quantile of chi2(2n)/n tempers
    steps: int = 0
    used: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    forget: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    _history: dict[str, deque[tuple[Array, Array]]] = field(default_factory=dict)
    _taught: dict[str, NDArray[np.bool_]] = field(default_factory=dict)

    @staticmethod
    def _consistent(w: Evidence, n: int, p: float) -> NDArray[np.bool_]:
        """Per run: is the window's evidence that of an honest source, at level p?"""
        mean_nis, d_bar, S_bar = w
        return (mean_nis <= chi2.quantile(p, 2 * n) / n) & (
            n * nis(d_bar, S_bar) <= chi2.quantile(p, 2)
        )

    def select(self, z: Observation | None, transfers: Sequence[Observation]) -> list[Observation]:
        """The transfers to use at this step, each with a mask of the runs that use it."""
        self.steps += 1
        B = transfers[0].mean.shape[1]
        if self.used.shape[0] != B:
            self.used = np.zeros(B, dtype=np.int64)
        self.forget = np.zeros(B, dtype=bool)
        judged = []
        for i, t in enumerate(transfers):
            origin = t.origin or f"#{i}"
            hist = self._history.setdefault(origin, deque(maxlen=self.window))
            taught = self._taught.setdefault(origin, np.zeros(B, dtype=bool))
            keep = np.ones(B, dtype=bool) if t.mask is None else t.mask.copy()
            if z is not None:
                d, S = disagreement(t, z)
                keep &= nis(d, S) <= chi2.quantile(self.probability, 2)
                hist.append((d, S))
            n = len(hist)
            cov = t.cov
            if n < self.min_evidence:
                keep[:] = False  # not enough evidence about this source yet
            else:
                w = evidence(hist)
                keep &= self._consistent(w, n, self.probability)
                self.forget |= taught & ~self._consistent(w, n, self.rollback_probability)
                mean_nis, d_bar, S_bar = w
                temper = np.maximum(
                    1.0, mean_nis / (chi2.quantile(self.temper_quantile, 2 * n) / n)
                )
                bias = position_fix(t.sensor).from_position(
                    t.mean, bias_second_moment(d_bar, S_bar, n)
                )
                cov = t.cov * temper[:, None, None] + bias
            judged.append((origin, t, keep, cov))
        out = []
        for origin, t, keep, cov in judged:
            keep &= ~self.forget  # a run rolled back this step takes no transfer at all
            if self.budget is not None:
                keep &= self.used + 1 <= self.budget * self.steps
            self.used += keep
            taught = self._taught[origin]
            taught &= ~self.forget
            taught |= keep
            out.append(Observation(t.sensor, t.mean, cov, keep, t.origin))
        return out
