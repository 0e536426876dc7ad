"""Your own sensor, in one file: a range-only transponder, z = |p - s| + w.

A sensor is one class (docs/models.md): declare its kind, its components (each name ending in
its unit) and its parameters (with units, defaults and bounds), write h, its Jacobian H, its
noise covariance R and how a miscalibration shifts it, and every filter, role, the PCRLB, the
config files, the CLI and the live services take it. Name it in a config by its import path,
``kind = "range_only:RangeOnly"``, with this folder on ``PYTHONPATH``:

    PYTHONPATH=examples/range_only tltrack experiment \\
        --config examples/range_only/primary.toml --filters pf,tl-pf --runs 20 --out /tmp/ro
    PYTHONPATH=examples/range_only tltrack demo --config examples/range_only/source.toml

It has no compiled kernel, so the particle filters run it on their generic NumPy path.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from tltrack.declare import Parameter
from tltrack.models import GaussianSensor, Layout


@dataclass(frozen=True)
class RangeOnly(GaussianSensor):
    """z = |p - s| + w: a transponder's round-trip time, say, from a station at ``position``."""

    kind: ClassVar[str] = "range-only"
    components: ClassVar[tuple[str, ...]] = ("range_m",)
    angular: ClassVar[tuple[bool, ...]] = (False,)
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter("sigma_r", "m", "range noise std at I_w = 1", default=10.0, gt=0),
    )

    sigma_r: float
    layout: Layout
    position: tuple[float, float] = (0.0, 0.0)

    def R(self, intensity: float) -> np.ndarray:
        return intensity * np.array([[self.sigma_r**2]])

    def h(self, x: np.ndarray) -> np.ndarray:
        ix, iy = self.layout.pos
        return np.hypot(x[ix] - self.position[0], x[iy] - self.position[1])[None]

    def H(self, x: np.ndarray) -> np.ndarray:
        ix, iy = self.layout.pos
        dx, dy = float(x[ix]) - self.position[0], float(x[iy]) - self.position[1]
        r = np.hypot(dx, dy)
        J = np.zeros((1, len(x)))
        J[0, ix], J[0, iy] = dx / r, dy / r
        return J

    def miscalibration(self, sigmas: float, intensity: float) -> np.ndarray:
        return np.array([sigmas * self.sigma_r * np.sqrt(intensity)])
