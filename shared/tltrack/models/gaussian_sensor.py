"""What every sensor with additive Gaussian noise shares, given which components are angles.

A concrete sensor subclasses :class:`GaussianSensor` and supplies ``h``, ``H`` and ``R`` (and its
``kind``, ``components``, ``angular`` and ``parameters`` declarations); residuals, sample means,
noisy draws and its construction from a config follow from those.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.models.angles import circular_mean, wrap_angle
from tltrack.models.base import Layout

Array = NDArray[np.float64]


class GaussianSensor(abc.ABC):
    """Generic parts of a :class:`~tltrack.models.base.MeasurementModel`.

    Subclasses are frozen dataclasses with a ``position`` and a ``layout`` field.
    """

    kind: ClassVar[str]
    #: each component's name with its unit
    components: ClassVar[tuple[str, ...]]
    #: which components are angles (wrapped, circular means)
    angular: ClassVar[tuple[bool, ...]]
    #: its noise parameters: the fields a config or a transfer gives beside ``kind``
    parameters: ClassVar[tuple[Parameter, ...]] = ()

    position: tuple[float, float]
    layout: Layout

    @classmethod
    def build(
        cls, params: dict[str, float], layout: Layout, position: tuple[float, float]
    ) -> GaussianSensor:
        """The sensor of these parameter values, reading states of ``layout``, at ``position``."""
        return cls(layout=layout, position=position, **params)  # type: ignore[call-arg]

    @property
    def n_z(self) -> int:
        return len(self.components)

    @abc.abstractmethod
    def R(self, intensity: float) -> Array:
        """Q_w at noise ``intensity``."""

    @abc.abstractmethod
    def h(self, x: Array) -> Array:
        """The noiseless measurement of states ``x``."""

    def residual(self, z: Array, zhat: Array) -> Array:
        """z - zhat with the angle components wrapped; components on the first axis."""
        d = np.asarray(z, dtype=float) - zhat
        for i, is_angle in enumerate(self.angular):
            if is_angle:
                d[i] = wrap_angle(d[i])
        return d

    def mean(self, Z: Array, axis: int, weights: Array | None = None) -> Array:
        """Sample mean of measurements along ``axis``, weighted by ``weights`` (shaped as one
        component of Z, summing to 1 along ``axis``) if given; the angles' is circular."""
        if weights is None:
            return np.stack(
                [
                    circular_mean(Z[i], axis - 1) if is_angle else Z[i].mean(axis=axis - 1)
                    for i, is_angle in enumerate(self.angular)
                ]
            )
        a = axis - 1
        return np.stack(
            [
                np.arctan2((weights * np.sin(Z[i])).sum(a), (weights * np.cos(Z[i])).sum(a))
                if is_angle
                else (weights * Z[i]).sum(a)
                for i, is_angle in enumerate(self.angular)
            ]
        )

    def draw(
        self, x: Array, intensity: float, rng: np.random.Generator, offset: Array | None = None
    ) -> Array:
        """h(x_k) + w_k for states ``x`` (K, n_x), w_k ~ N(0, R) from ``rng``; angles wrapped."""
        L = np.linalg.cholesky(self.R(intensity))
        eps = rng.standard_normal((x.shape[0], self.n_z))
        z = self.h(x.T).T + eps @ L.T
        for i, is_angle in enumerate(self.angular):
            shifted = z[:, i] if offset is None else z[:, i] + offset[i]
            z[:, i] = wrap_angle(shifted) if is_angle else shifted
        return z
