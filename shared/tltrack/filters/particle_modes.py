"""The mode each particle carries, for the particle filters of a jump-Markov motion model.

The jump-Markov multiple-model particle filter: a particle is a state and a motion mode, the
mode follows the modes' Markov chain from one step to the next, and the state moves as its mode
says (:class:`~tltrack.models.modes.MotionModes`). :class:`ParticleModes` keeps the modes (B, N),
draws their transitions from a child of each run's random stream (so the run's own stream, and
with it the propagation's noise, is that of the single-model filter), and propagates a cloud: a
run whose particles share one mode through that mode's compiled kernel (so one mode is the
single-model filter bit for bit), a run of mixed modes through the compiled kernel of the modes
(:func:`~tltrack.filters.fastpath.modes_propagator`) when they have one, else mode by mode
through each mode's f and Q_sqrt in NumPy.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from tltrack.filters import fastpath
from tltrack.filters.kernels import propagation
from tltrack.models.modes import MotionModes

Array = NDArray[np.float64]
Modes = NDArray[np.int64]


class ParticleModes:
    """The modes of B runs' clouds of N particles."""

    def __init__(self, modes: MotionModes, rngs: Sequence[np.random.Generator], N: int) -> None:
        self.modes, self.N = modes, N
        self.rngs = [g.spawn(1)[0] for g in rngs]
        self._cdf = np.cumsum(np.asarray(modes.transition, dtype=float), axis=1)
        self._cdf[:, -1] = 1.0
        first = np.cumsum(np.asarray(modes.initial, dtype=float))
        first[-1] = 1.0
        #: (B, N): each particle's mode
        self.of = np.stack([np.searchsorted(first, g.random(N), side="right") for g in self.rngs])
        self._propagators = [fastpath.propagator(m, N) for m in modes.models]
        self._mixed = fastpath.modes_propagator(modes.models, N)
        self._u = np.empty((len(rngs), N))  # the switches' uniforms (scratch)
        self._L = [fastpath.f64(m.Q_sqrt) for m in modes.models]
        #: (M, n, n): each mode's Q
        self.Qs = np.stack([m.Q for m in modes.models])

    def switch(self, previous: Modes) -> Modes:
        """Each particle's next mode (B, N) given its mode ``previous`` (B, N): one uniform per
        particle from each run's mode stream, by the inverse CDF of its row of the chain."""
        for b, g in enumerate(self.rngs):
            g.random(out=self._u[b])
        out = np.empty(previous.shape, dtype=np.int64)
        propagation.switch_modes(
            self._u, np.ascontiguousarray(previous, dtype=np.int64), self._cdf, out
        )
        return out

    def gather(self, modes: Modes, anc: NDArray[np.int64]) -> Modes:
        """modes[b, anc[b, i]] (B, N): each slot's ancestor's mode (``anc`` may carry a scratch
        column past N). Not ``np.take_along_axis``: at B = 1 the index arrays it builds cost three
        times this, and a step gathers once or twice."""
        out = np.empty((modes.shape[0], self.N), dtype=np.int64)
        for b in range(modes.shape[0]):
            np.take(modes[b], anc[b, : self.N], out=out[b])
        return out

    def probabilities(self, modes: Modes, weights: Array | None = None) -> Array:
        """(M, B): each mode's share of the cloud (weighted by ``weights`` (B, N) if given); a
        mode that holds every particle has exactly 1."""
        B, M = modes.shape[0], self.modes.M
        w = np.ones(modes.shape) if weights is None else weights
        slot = (modes + M * np.arange(B)[:, None]).ravel()  # run b's mode j: bin b M + j
        shares = np.bincount(slot, weights=w.ravel(), minlength=B * M).reshape(B, M).T
        return np.asarray(shares / shares.sum(axis=0))  # one mode's share: exactly 1

    def means(self, x: Array, modes: Modes) -> Array:
        """f_m(x) of every particle (n, B, N) under its own mode (B, N): a run whose particles
        share one mode with a compiled kernel takes that kernel."""
        out = np.empty_like(x)
        fast = x.dtype == np.float64 and x.flags.c_contiguous
        for b in range(x.shape[1]):
            kernel = self._propagators[int(modes[b, 0])] if _one_mode(modes[b]) and fast else None
            if kernel is not None:
                run = np.empty((x.shape[0], 1, x.shape[2]))
                kernel.mean(np.ascontiguousarray(x[:, b : b + 1]), run)
                out[:, b] = run[:, 0]
                continue
            if self._mixed is not None and fast:
                run = np.empty((x.shape[0], 1, x.shape[2]))
                self._mixed.mean(np.ascontiguousarray(x[:, b : b + 1]), modes[b : b + 1], run)
                out[:, b] = run[:, 0]
                continue
            for j, model in enumerate(self.modes.models):
                sel = modes[b] == j
                if sel.any():
                    out[:, b, sel] = model.f(x[:, b, sel])
        return out

    def propagate(
        self,
        src: Array,
        anc: NDArray[np.int64],
        modes: Modes,
        U: Array,
        gaussians: Callable[[], Array],
    ) -> Array:
        """out[:, b, i] = f_m(src[:, b, anc[b, i]]) + L_m eps_i with m = modes[b, i], eps the
        step's Gaussians (``gaussians()``: (r, B, N), from the uniforms ``U`` (B, ...))."""
        n, B = src.shape[0], src.shape[1]
        out = np.empty((n, B, self.N))
        slow = []
        fast = src.dtype == np.float64 and src.flags.c_contiguous
        modes = np.ascontiguousarray(modes, dtype=np.int64)
        for b in range(B):
            kernel = self._propagators[int(modes[b, 0])] if _one_mode(modes[b]) else None
            if kernel is not None and fast:
                kernel(src, anc, U[b : b + 1], out, b)  # the whole run in one mode's kernel
            elif self._mixed is not None and fast:
                self._mixed(src, anc, modes, U[b : b + 1], out, b)
            else:
                slow.append(b)
        if slow:
            E = gaussians()  # (r, B, N)
            for b in slow:
                x = src[:, b, anc[b, : self.N]]
                for j, model in enumerate(self.modes.models):
                    sel = modes[b] == j
                    if sel.any():
                        out[:, b, sel] = model.f(x[:, sel]) + self._L[j] @ E[:, b, sel]
        return out


def _one_mode(run: Modes) -> bool:
    return bool((run == run[0]).all())
