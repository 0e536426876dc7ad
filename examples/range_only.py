"""Your own sensor, in plain NumPy: a range-only primary helped by the paper's radar.

A sensor is one class (docs/models.md): declare its components, write h, its Jacobian H, its
noise covariance R and how a miscalibration shifts it, and every filter, role and the PCRLB take
it. This one has no compiled kernel, so the particle filter runs it on its generic NumPy path.

    python examples/range_only.py            # 20 runs of the coordinated-turn scenario
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from tltrack.config import make_config
from tltrack.engine.pcrlb import pcrlb
from tltrack.engine.registry import build, parse
from tltrack.engine.scenario import initial_estimate, truth
from tltrack.engine.streams import stream
from tltrack.filters.transfer import Primary, Source
from tltrack.models import Layout, Observation, motion_model, sensor
from tltrack.models.gaussian_sensor import GaussianSensor


@dataclass(frozen=True)
class RangeOnly(GaussianSensor):
    """z = |p - s| + w: a transponder's round-trip time, say, from a station at ``position``."""

    kind: ClassVar[str] = "range-only"
    components: ClassVar[tuple[str, ...]] = ("range_m",)
    angular: ClassVar[tuple[bool, ...]] = (False,)

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--particles", type=int, default=2000)
    args = ap.parse_args()
    cfg = make_config(preset="arasaratnam-haykin", truth="fixed", particles=args.particles)
    model = motion_model(cfg)
    mine = RangeOnly(sigma_r=10.0, layout=model.layout, position=(2000.0, -3000.0))
    R_mine = mine.R(cfg.primary_intensity)
    radar = sensor(cfg, "s1")  # the paper's source: a range-bearing radar at the origin
    R_radar = radar.R(cfg.sources[0].intensity)
    sq: dict[str, list[np.ndarray]] = {"pf": [], "tl-pf": [], "source-pf": []}
    for run in range(args.runs):
        x = truth(cfg, run)
        z_mine = mine.draw(x[1:], cfg.primary_intensity, stream(cfg.seed, run, "meas/mine"))
        z_radar = radar.draw(x[1:], cfg.sources[0].intensity, stream(cfg.seed, run, "meas/s1"))
        x0 = initial_estimate(cfg, run)[:, None]
        filt = {n: build(parse(n), cfg, model, x0, [run], "s1") for n in sq}
        iso, tl = Primary(filt["pf"]), Primary(filt["tl-pf"])
        src = Source(filt["source-pf"], radar, R_radar)
        transfer: list[Observation] = []
        errors: dict[str, list[float]] = {n: [] for n in sq}
        for k in range(1, cfg.K + 1):
            own = Observation.broadcast(mine, z_mine[k - 1], R_mine)
            est_src, upcoming = src.step(Observation.broadcast(radar, z_radar[k - 1], R_radar))
            for name, est in (
                ("pf", iso.step(own)),
                ("tl-pf", tl.step(own, transfer)),
                ("source-pf", est_src),
            ):
                d = model.layout.position(est.mean[0] - x[k])
                errors[name].append(float(d @ d))
            transfer = [upcoming]
        for name, e in errors.items():
            sq[name].append(np.array(e))
    bound = pcrlb(model, [(mine, R_mine)], truth(cfg, 0)[None], np.diag(cfg.P0_diag))
    print(
        f"range-only primary at {mine.position}, radar source at {radar.position}, {args.runs} runs"
    )
    for name, e in sq.items():
        rmse = float(np.mean(np.sqrt(np.mean(e, axis=0))))
        print(f"{name:>10}: overall RMSE {rmse:8.2f} m")
    print(f"{'PCRLB':>10}: range-only alone {float(np.mean(bound)):8.2f} m")


if __name__ == "__main__":
    main()
