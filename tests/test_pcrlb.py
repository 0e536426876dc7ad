"""The PCRLB: the Kalman covariance on a linear-Gaussian model, and more sensors bound lower."""

from __future__ import annotations

import numpy as np
import pytest
from doubles import PositionSensor
from tltrack.config import make_config
from tltrack.engine.pcrlb import pcrlb
from tltrack.engine.scenario import truth
from tltrack.engine.setup import Setup
from tltrack.models import ConstantVelocity, CoordinatedTurn, RangeBearing

pytestmark = pytest.mark.unit


def test_linear_gaussian_bound_is_the_kalman_covariance() -> None:
    """The singular white-noise-acceleration Q_v must not matter: the recursion never inverts it."""
    model = ConstantVelocity(T=1.0, q=0.1)
    sensor = PositionSensor(layout=model.layout)
    C = sensor.H(np.zeros(4))
    R = np.diag([25.0, 9.0])
    P0 = np.diag([50.0, 1.0, 50.0, 1.0])
    K = 20
    truths = np.random.default_rng(0).standard_normal((3, K + 1, 4))  # irrelevant when linear
    bound = pcrlb(model, [(sensor, R)], truths, P0)
    P = P0
    expected = []
    for _ in range(K):
        P = model.A @ P @ model.A.T + model.Q
        S = C @ P @ C.T + R
        P = P - P @ C.T @ np.linalg.solve(S, C @ P)
        expected.append(np.sqrt(P[0, 0] + P[2, 2]))
    np.testing.assert_allclose(bound, expected, rtol=1e-9)


def test_two_range_bearing_sensors_bound_below_one() -> None:
    cfg = make_config(scenario="ct", preset="arasaratnam-haykin", K=50, truth="random")
    model = CoordinatedTurn(T=cfg.Ts, q1=cfg.q1, q2=cfg.q2)
    truths = np.stack([truth(Setup(cfg), run) for run in range(4)])
    P0 = np.diag(cfg.P0_diag)
    primary = RangeBearing(cfg.sigma_r, cfg.sigma_bearing, model.layout)
    source = RangeBearing(cfg.sigma_r, cfg.sigma_bearing, model.layout, (2000.0, -1000.0))
    one = pcrlb(model, [(primary, primary.R(4.0))], truths, P0)
    two = pcrlb(model, [(primary, primary.R(4.0)), (source, source.R(1.0))], truths, P0)
    assert one.shape == two.shape == (cfg.K,)
    assert np.all(np.isfinite(one)) and np.all(two > 0.0)
    assert np.all(two < one)
