"""Test doubles: a sensor and a Kalman filter, linear-Gaussian stand-ins where the KF is exact,
a service that is never opened, to drive a service's handlers in-process, and the episode
announcements those handlers need.

:class:`PositionSensor` is a whole new sensor written against the
:class:`~tltrack.models.base.MeasurementModel` Protocol, outside the package, and named in a
config by its import path (``doubles:PositionSensor``): that it runs through every filter kind
and role (tests/test_model_interface.py) is what proves the interface.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import zenoh
from livestack import SIM_DEFAULTS
from tltrack.config import make_config
from tltrack.declare import Parameter
from tltrack.live.service import Service
from tltrack.models.base import Layout
from tltrack.models.constant_velocity import ConstantVelocity
from tltrack.models.gaussian_sensor import GaussianSensor
from tltrack.wire import keys
from tltrack.wire.messages import EpisodeEnd, EpisodeStart, Message, encode
from tltrack.wire.transport import Received, ZenohSettings

CV_LAYOUT = ConstantVelocity.layout
#: the paper's radar at the origin, as a transfer describes it
RADAR = {"kind": "range-bearing", "position": (0.0, 0.0), "sigma_r": 10.0, "sigma_bearing": 3e-3}


@dataclass(frozen=True)
class PositionSensor(GaussianSensor):
    """z = [x, y] + w, w ~ N(0, I_w sigma^2 I): a GNSS-like fix, linear, no angle."""

    kind: ClassVar[str] = "test-position"
    components: ClassVar[tuple[str, ...]] = ("x_m", "y_m")
    angular: ClassVar[tuple[bool, ...]] = (False, False)
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter("sigma", "m", "noise std per axis at I_w = 1", default=5.0, gt=0),
    )

    sigma: float = 5.0
    layout: Layout = CV_LAYOUT
    position: tuple[float, float] = (0.0, 0.0)

    def R(self, intensity: float) -> np.ndarray:
        return intensity * self.sigma**2 * np.eye(2)

    def h(self, x: np.ndarray) -> np.ndarray:
        return self.layout.position(x)

    def H(self, x: np.ndarray) -> np.ndarray:
        H = np.zeros((2, len(x)))
        H[0, self.layout.pos[0]] = H[1, self.layout.pos[1]] = 1.0
        return H

    def miscalibration(self, sigmas: float, intensity: float) -> np.ndarray:
        return np.array([sigmas * self.sigma * np.sqrt(intensity), 0.0])

    def to_position(self, z: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(z, dtype=float), np.asarray(P, dtype=float)

    def from_position(self, z: np.ndarray, S: np.ndarray) -> np.ndarray:
        return S


def cv_model(q: float = 0.1) -> ConstantVelocity:
    return ConstantVelocity(T=1.0, q=q)


def kalman(model, sensor, x0, P0, zs, Rs):
    """Textbook KF; ``zs[k]`` is a list of measurements at step k with covariances ``Rs[k]``."""
    m, P = np.array(x0, float), np.array(P0, float)
    out = []
    for z_list, R_list in zip(zs, Rs, strict=True):
        m = model.A @ m
        P = model.A @ P @ model.A.T + model.Q
        for z, R in zip(z_list, R_list, strict=True):
            H = sensor.H(m)
            S = H @ P @ H.T + R
            K = P @ H.T @ np.linalg.inv(S)
            m = m + K @ (z - H @ m)
            P = P - K @ S @ K.T
        out.append((m.copy(), P.copy()))
    return out


class Offline(Service):
    """A real :class:`~tltrack.live.service.Service` that is never opened: it counts and rejects as
    in a process, and keeps what it would publish."""

    def __init__(self, name: str, operator: str = keys.PRIMARY) -> None:
        super().__init__(name, operator, ZenohSettings())
        self.published: list[tuple[str, Message]] = []

    def publish(self, key: str, msg: Message | Callable[[], Message]) -> None:
        self.published.append((key, msg() if callable(msg) else msg))


def received(key: str, payload: bytes) -> Received:
    """A sample as a subscriber hands it over."""
    return Received(key, payload, zenoh.SampleKind.PUT, time.time())


def episode_start(e: str, K: int) -> bytes:
    """sensor_sim's start of episode ``e`` (run 0, K steps, the live stack's defaults), encoded."""
    cfg = make_config(**SIM_DEFAULTS, K=K, particles=50).model_dump(mode="json")
    start = EpisodeStart(
        episode=e, sender="sensor_sim", k=0, t_sensor=time.time(), run=0, config=cfg, K=K,
        steps_per_sec=0.0,
    )  # fmt: skip
    return encode(start)


def episode_end(e: str, K: int) -> bytes:
    """sensor_sim's end of episode ``e`` after its K steps, encoded."""
    return encode(EpisodeEnd(episode=e, sender="sensor_sim", k=K, t_sensor=0.0, steps_sent=K))
