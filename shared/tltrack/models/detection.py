"""The detection process of any sensor: missed detections, false alarms and a field of view.

The paper's sensors report exactly one measurement of the target per step. A real sensor reports
a *scan*: the target's measurement with probability ``pd`` when it lies in the field of view,
plus a Poisson number (mean ``clutter_rate``) of false alarms spread uniformly over the field of
view in the sensor's own measurement coordinates (Bar-Shalom, Willett & Tian 2011, sec. 3.4). The
false alarms' density is then

    lambda_c = clutter_rate / V,   V = the field of view's volume,

in the units of 1 / (product of the components' units): the same units as a measurement
likelihood g(z | x), which is why the two can be added (:mod:`tltrack.filters.association`).

The process is declared once, here, for every sensor kind, keyed by the sensor's component names
(``range_m``, ``bearing_rad``, ...): a new sensor gets it for free. A component the table of
default bounds does not know has no field of view unless given one, and such a sensor refuses
false alarms (their density would be undefined).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tltrack.models.angles import wrap_angle
from tltrack.models.base import MeasurementModel

Array = NDArray[np.float64]

#: the field of view of a component nobody bounded
DEFAULT_FOV: dict[str, tuple[float, float]] = {
    "range_m": (0.0, 20_000.0),
    "bearing_rad": (-math.pi, math.pi),
    "x_m": (-20_000.0, 20_000.0),
    "y_m": (-20_000.0, 20_000.0),
    "range_rate_mps": (-500.0, 500.0),
}


def is_angle(component: str) -> bool:
    """Is this component an angle (its interval may wrap across +-pi)?"""
    return component.endswith("_rad")


@dataclass(frozen=True)
class Detection:
    """pd, the false-alarm rate and the field of view of one sensor (``fov``: component ->
    [lo, hi]; an angle's interval with lo > hi is a sector across +-pi)."""

    components: tuple[str, ...]
    pd: float = 1.0
    clutter_rate: float = 0.0
    fov: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not 0.0 < self.pd <= 1.0:
            raise ValueError(f"pd must be in (0, 1], got {self.pd}")
        if not (self.clutter_rate >= 0.0 and math.isfinite(self.clutter_rate)):
            raise ValueError(f"clutter_rate must be finite and >= 0, got {self.clutter_rate}")
        for name, (lo, hi) in self.fov.items():
            where = f"fov.{name}"
            if name not in self.components:
                own = ", ".join(self.components)
                raise ValueError(f"{where}: the sensor has no such component (its: {own})")
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise ValueError(f"{where}: bounds must be finite")
            if is_angle(name):
                if not (-math.pi <= lo <= math.pi and -math.pi <= hi <= math.pi) or lo == hi:
                    raise ValueError(f"{where}: angles need -pi <= lo, hi <= pi and lo != hi")
            elif not lo < hi:
                raise ValueError(f"{where}: empty or inverted interval [{lo}, {hi}]")
        unbounded = [c for c in self.components if c not in self.bounds]
        if self.clutter_rate > 0 and unbounded:
            raise ValueError(
                f"clutter_rate > 0 needs a field of view: give fov.{unbounded[0]} "
                "(false alarms are uniform over it)"
            )

    @classmethod
    def of(cls, sensor: MeasurementModel, **given: object) -> Detection:
        """The detection process of ``sensor`` with the given pd, clutter_rate and fov."""
        return cls(tuple(sensor.components), **given)  # type: ignore[arg-type]

    @property
    def trivial(self) -> bool:
        """The paper's sensor: every scan holds the target's measurement and nothing else."""
        return self.pd == 1.0 and self.clutter_rate == 0.0 and not self.fov

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        """Each component's interval: the given one, else the default (if it has one)."""
        out = {c: DEFAULT_FOV[c] for c in self.components if c in DEFAULT_FOV}
        return {**out, **self.fov}

    def _width(self, name: str) -> float:
        lo, hi = self.bounds[name]
        return hi - lo if hi > lo else hi - lo + 2.0 * math.pi

    @property
    def volume(self) -> float:
        """V: the field of view's volume in measurement coordinates."""
        return math.prod(self._width(c) for c in self.components)

    @property
    def density(self) -> float:
        """lambda_c: false alarms per unit measurement volume (0 without clutter)."""
        return self.clutter_rate / self.volume if self.clutter_rate > 0 else 0.0

    def inside(self, z: Array) -> NDArray[np.bool_]:
        """Which measurements ``z`` (n_z, ...) fall inside the field of view."""
        ok = np.ones(np.shape(z)[1:], dtype=bool)
        for i, c in enumerate(self.components):
            if c not in self.bounds:
                continue
            lo, hi = self.bounds[c]
            v = z[i]
            ok &= ((v >= lo) & (v <= hi)) if hi > lo else ((v >= lo) | (v <= hi))
        return ok

    def pd_at(self, z: Array) -> Array:
        """pd(x) at measurements ``z`` (n_z, ...): pd inside the field of view, 0 outside."""
        return np.where(self.inside(z), self.pd, 0.0)

    def scan(
        self, z_target: Array, seen: bool, rng: np.random.Generator
    ) -> tuple[Array, NDArray[np.bool_]]:
        """One scan: the target's noisy ``z_target`` (n_z,) if detected, plus false alarms, in a
        random order; and which detections are false alarms (scoring only, no filter sees it).

        ``seen``: whether the noise-free measurement lies in the field of view. The draws are,
        in order: detected, how many false alarms, where, the shuffle.
        """
        detected = bool(rng.random() < self.pd) and seen
        n_c = int(rng.poisson(self.clutter_rate)) if self.clutter_rate > 0 else 0
        clutter = np.empty((n_c, len(self.components)))
        for i, c in enumerate(self.components):
            lo, _hi = self.bounds[c]
            v = lo + self._width(c) * rng.random(n_c)
            clutter[:, i] = wrap_angle(v) if is_angle(c) else v
        Z = np.vstack([z_target[None, :], clutter]) if detected else clutter
        is_clutter = np.r_[np.zeros(int(detected), bool), np.ones(n_c, bool)]
        order = rng.permutation(len(Z))
        return Z[order], is_clutter[order]
