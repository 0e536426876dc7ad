"""Does the filter's model fit the target? The NIS of its own measurements, over a window.

A filter that knows its target well predicts its own next measurement z_k as N(z_hat_k, S_k):
for a sigma-point filter, its innovation's moments; for a particle filter, the predicted cloud's
measurement moments plus R. The normalised innovation squared

    NIS_k = (z_k - z_hat_k)' S_k^-1 (z_k - z_hat_k)  ~  chi2(n_z)

needs no truth, so a deployment can watch it. Averaged over a sliding window of W steps, its mean
lies in the band chi2_{W n_z}(0.005) / W ... chi2_{W n_z}(0.995) / W about 99% of the time
(Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4). A window mean above the band in many steps says
the filter is surprised more than it admits: its motion model's noise is too low for the target
(the recorded aircraft that every filter lost with the paper's noise said nothing; this does).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

from tltrack.filters import chi2
from tltrack.models.observation import Observation

Array = NDArray[np.float64]

#: the window, in steps
WINDOW = 20
#: the band's tails
TAILS = (0.005, 0.995)
#: the share of steps above the band from which the filter's model is said not to fit
WARN_SHARE = 0.5


def nis(z: Observation, predicted: Observation) -> Array:
    """(z - z_hat)' S^-1 (z - z_hat) per run (B,), for the statement ``predicted`` = N(z_hat, S)
    of the same sensor; NaN where S is not finite."""
    d = z.sensor.residual(z.mean, predicted.mean).T  # (B, n_z)
    S = predicted.cov
    ok = np.isfinite(S).all(axis=(1, 2)) & np.isfinite(d).all(axis=1)
    out = np.full(d.shape[0], np.nan)
    if ok.any():
        out[ok] = np.einsum("bi,bi->b", d[ok], np.linalg.solve(S[ok], d[ok][:, :, None])[:, :, 0])
    return out


def band(n_z: int, window: int = WINDOW) -> tuple[float, float]:
    """The 99% band of a window's mean NIS for measurements of n_z components."""
    lo, hi = (chi2.quantile(q, window * n_z) / window for q in TAILS)
    return lo, hi


class Window:
    """The last ``window`` NIS of each run, and their mean (NaN until the window is full)."""

    def __init__(self, window: int = WINDOW) -> None:
        self.window = window
        self._last: deque[Array] = deque(maxlen=window)

    def push(self, values: Array) -> Array:
        """Add one step's NIS (B,); the window's mean per run."""
        self._last.append(values)
        if len(self._last) < self.window:
            return np.full(len(values), np.nan)
        return np.asarray(np.mean(self._last, axis=0))


def verdict(above: float, below: float) -> str | None:
    """What a user should be told of a filter whose window mean was above its band in a share
    ``above`` of the steps (and below it in ``below``); None when nothing stands out."""
    if above >= WARN_SHARE:
        return (
            f"NIS above its 99% band in {above:.0%} of steps: the motion model's noise is too "
            "low for this target (a target class preset, or tltrack fit, gives it noise that fits)"
        )
    if below >= WARN_SHARE:
        return (
            f"NIS below its 99% band in {below:.0%} of steps: the filter is more uncertain than "
            "its errors (its noise is higher than this target needs)"
        )
    return None
