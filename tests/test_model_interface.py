"""The model interfaces, proved by a sensor the package has never heard of.

tests/doubles.PositionSensor is written against the MeasurementModel Protocol alone. It runs through
every filter kind in every role, and on the linear-Gaussian model it makes (constant velocity,
position fixes) the sigma-point filters equal the Kalman filter.
"""

from __future__ import annotations

import numpy as np
import pytest
from doubles import PositionSensor, cv_model, kalman
from tltrack.config import make_config
from tltrack.engine.driver import Driver, StepRecord
from tltrack.engine.registry import build, parse
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.filters.kinds import FILTERS
from tltrack.models import (
    ConstantVelocity,
    CoordinatedTurn,
    Layout,
    MeasurementModel,
    Observation,
    PositionFix,
    RangeBearing,
)

pytestmark = pytest.mark.unit

CFG = make_config(scenario="cv", particles=2000)
X0 = np.array(CFG.x0)
P0 = np.diag(CFG.P0_diag)
B, K = 3, 25


def test_the_shipped_and_the_test_sensors_implement_the_protocols() -> None:
    for s in (PositionSensor(), RangeBearing(10.0, 1e-3, CoordinatedTurn.layout)):
        assert isinstance(s, MeasurementModel) and isinstance(s, PositionFix)
        assert s.n_z == len(s.components) == 2


def test_each_motion_model_names_its_position_and_velocity() -> None:
    for model in (ConstantVelocity(T=1.0, q=0.1), CoordinatedTurn(T=1.0, q1=0.1, q2=1e-4)):
        x = np.arange(float(model.n))
        assert model.layout == Layout(pos=(0, 2), vel=(1, 3))
        np.testing.assert_array_equal(model.layout.position(x), [x[0], x[2]])


def _scenario(seed: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A CV truth (K + 1, B, 4) and both sensors' position fixes (K, 2, B)."""
    rng = np.random.default_rng(seed)
    model = cv_model()
    x = np.empty((K + 1, B, 4))
    x[0] = X0
    for k in range(1, K + 1):
        x[k] = (model.A @ x[k - 1].T).T + (model.Q_sqrt @ rng.standard_normal((2, B))).T
    pos = x[1:, :, [0, 2]].transpose(0, 2, 1)
    return x, pos + rng.normal(0, 10.0, pos.shape), pos + rng.normal(0, 5.0, pos.shape)


ROLES = {
    "isolated": "",
    "source": "source-",
    "tl": "tl-",
    "robust": "robust-tl-",
    "fusion": "fusion-",
}


@pytest.mark.parametrize(
    ("kind", "role"),
    [(k, r) for k in FILTERS.names() for r in ROLES if r != "fusion" or FILTERS.get(k).particle],
)
def test_a_new_sensor_runs_through_every_filter_kind_and_role(kind: str, role: str) -> None:
    """Named by its import path in a config, the double steps through the step driver."""
    cfg = make_config(
        scenario="cv",
        particles=2000,
        primary_intensity=1.0,
        primary_sensor={"kind": "doubles:PositionSensor", "sigma": 10.0},
        sources=[{"id": "s1", "sensor": {"kind": "doubles:PositionSensor", "sigma": 5.0}}],
        trusted=True,
    )
    setup = Setup(cfg)
    assert isinstance(setup.sensor(PRIMARY), PositionSensor)
    truth, z_p, z_s = _scenario()
    name = f"{ROLES[role]}{kind}"
    estimates: dict[str, list[np.ndarray]] = {}
    transfers: list[Observation] = []

    def collect(r: StepRecord) -> None:
        estimates.setdefault(r.name, []).append(r.estimate.mean)
        if r.transfer is not None:
            transfers.append(r.transfer)

    x0_hat = np.repeat(X0[:, None], B, 1)
    driver = Driver([setup], [name], x0_hat, list(range(B)), collectors=[[collect]])
    for k in range(1, K + 1):
        own, theirs = setup.sensors[PRIMARY], setup.sensors["s1"]
        driver.step(k, [{PRIMARY: own.observe(z_p[k - 1]), "s1": theirs.observe(z_s[k - 1])}])
    assert all(t.mean.shape == (2, B) and t.cov.shape == (B, 2, 2) for t in transfers)
    est = np.array(estimates[name])  # (K, B, n)
    errors = np.linalg.norm(est[:, :, [0, 2]] - truth[1:][:, :, [0, 2]], axis=2)
    assert np.all(np.isfinite(errors))
    # position fixes of 10 m (5 m for the source): a filter that works ends well within that
    assert np.sqrt(np.mean(np.square(errors[-10:]))) < 10.0


@pytest.mark.parametrize("kind", ["ukf", "ckf3", "ckf5"])
@pytest.mark.parametrize("with_transfer", [False, True])
def test_sigma_point_filters_equal_the_kalman_filter_with_the_new_sensor(
    kind: str, with_transfer: bool
) -> None:
    """Linear-Gaussian (CV, position fixes): every rule is exact, TL's stacked update too."""
    model = cv_model()
    sensor = PositionSensor(sigma=10.0)
    R = sensor.R(1.0)
    _, z_p, z_s = _scenario(seed=9)
    P_eta = np.diag([30.0, 40.0])  # a transferred statement about the position
    x0_hat = np.repeat(X0[:, None], B, 1)
    filt = build(parse(kind), Setup(CFG), x0_hat, list(range(B)))
    for k in range(K):
        obs = [Observation.broadcast(sensor, z_p[k], R)]
        if with_transfer:
            obs.append(Observation.broadcast(sensor, z_s[k], P_eta))
        filt.predict()
        filt.update(obs)
    est = filt.estimate()
    for b in range(B):
        zs = [[z_p[k][:, b], *([z_s[k][:, b]] if with_transfer else [])] for k in range(K)]
        Rs = [[R, *([P_eta] if with_transfer else [])] for _ in range(K)]
        m, P = kalman(model, sensor, X0, P0, zs, Rs)[-1]
        np.testing.assert_allclose(est.mean[b], m, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(est.cov[b], P, rtol=1e-9, atol=1e-9)
