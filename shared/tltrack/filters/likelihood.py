"""The log-likelihood of a cloud under a list of Gaussian statements about h(x_k).

The TL-PF weighs each particle by the product of one Gaussian likelihood per statement (seed,
eq. TL_tr_likelihood_2): the primary's z_k, each transfer, or (fusion) a source's raw z_k. Sensors
with compiled kernels (:mod:`~tltrack.filters.fastpath`) are weighed there; any other sensor by
:func:`gaussian_loglik`, in NumPy, with the same result.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tltrack.filters import fastpath
from tltrack.filters.association import scan_loglik
from tltrack.models.base import MeasurementModel
from tltrack.models.observation import Observation
from tltrack.models.scan import Scan

Array = NDArray[np.float64]


def gaussian_loglik(obs: Observation, x: Array) -> Array:
    """log N(obs.mean; h(x), obs.cov) up to a per-run constant, (B, N) (eq. TL_tr_likelihood_2).

    The generic path, for any sensor; a sensor with compiled kernels computes the same there.
    """
    d = obs.sensor.residual(obs.mean[:, :, None], obs.sensor.h(x))  # (n_z, B, N)
    rho = -0.5 * np.einsum("ibn,bij,jbn->bn", d, np.linalg.inv(obs.cov), d)
    if obs.mask is not None:
        rho = np.where(obs.mask[:, None], rho, 0.0)
    return rho


class Likelihood:
    """Sums statements' log-likelihoods over clouds of a batch of B runs, by kernel or NumPy."""

    def __init__(self, batch: int) -> None:
        self.batch = batch
        self._kernels: dict[type, fastpath.SensorKernels | None] = {}

    def kernels(self, sensor: MeasurementModel) -> fastpath.SensorKernels | None:
        """The compiled kernels of ``sensor``'s type, or None (cached per type)."""
        if type(sensor) not in self._kernels:
            self._kernels[type(sensor)] = fastpath.sensor_kernels(sensor, self.batch)
        return self._kernels[type(sensor)]

    def split(
        self, observations: Sequence[Observation | Scan], x: Array
    ) -> tuple[tuple[fastpath.SensorKernels, list[Observation]] | None, list[Observation | Scan]]:
        """The statements one compiled kernel takes (the first sensor type that has one, in one
        layout), and the others (generic path, and every scan). A cloud a kernel cannot read
        takes NumPy."""
        if not (x.dtype == np.float64 and x.flags.c_contiguous):
            return None, list(observations)
        fast: list[Observation] = []
        others: list[Observation | Scan] = []
        kernels = None
        for o in observations:
            if isinstance(o, Scan):
                others.append(o)
            elif not fast and (k := self.kernels(o.sensor)) is not None:
                kernels = k
                fast.append(o)
            elif fast and type(o.sensor) is type(fast[0].sensor) and _same_layout(o, fast[0]):
                fast.append(o)
            else:
                others.append(o)
        return (None if kernels is None else (kernels, fast)), others

    def into(self, x: Array, observations: Sequence[Observation | Scan], out: Array) -> None:
        """out (B, N) = the sum of every statement's log-likelihood over the clouds x."""
        fast, others = self.split(observations, x)
        if fast is not None:
            fast[0].loglik(x, fast[1], out)
        else:
            out[...] = 0.0
        for o in others:
            out += scan_loglik(o, x) if isinstance(o, Scan) else gaussian_loglik(o, x)


def _same_layout(a: Observation, b: Observation) -> bool:
    return bool(getattr(a.sensor, "layout", None) == getattr(b.sensor, "layout", None))
