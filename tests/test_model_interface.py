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
from tltrack.engine.registry import KINDS, build, parse
from tltrack.filters.decision import TransferPolicy
from tltrack.filters.transfer import Primary, Source
from tltrack.models import (
    ConstantVelocity,
    CoordinatedTurn,
    Layout,
    MeasurementModel,
    Observation,
    PositionFix,
    RangeBearing,
)

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


ROLES = ["isolated", "source", "tl", "robust", "fusion"]


@pytest.mark.parametrize(
    ("kind", "role"),
    [(k, r) for k in KINDS for r in ROLES if r != "fusion" or k == "pf"],  # fusion: a PF only
)
def test_a_new_sensor_runs_through_every_filter_kind_and_role(kind: str, role: str) -> None:
    model = cv_model()
    primary, source = PositionSensor(sigma=10.0), PositionSensor(sigma=5.0)
    R_p, R_s = primary.R(1.0), source.R(1.0)
    truth, z_p, z_s = _scenario()
    x0_hat = np.repeat(X0[:, None], B, 1)
    runs = list(range(B))

    def make(name: str) -> object:
        return build(parse(name), CFG, model, x0_hat, runs, source_id="s1")

    src = Source(make(f"source-{kind}"), source, R_s)  # type: ignore[arg-type]
    prefix = {"isolated": "", "tl": "tl-", "robust": "robust-tl-", "fusion": "fusion-"}
    if role == "source":
        prim = None
    elif role == "robust":
        twin = Primary(make(kind))  # type: ignore[arg-type]
        prim = Primary(make(f"robust-tl-{kind}"), TransferPolicy(), twin=twin)  # type: ignore[arg-type]
    else:
        prim = Primary(make(f"{prefix[role]}{kind}"))  # type: ignore[arg-type]
    transfer = None
    errors = []
    for k in range(1, K + 1):
        own = Observation.broadcast(primary, z_p[k - 1], R_p)
        theirs = Observation.broadcast(source, z_s[k - 1], R_s)
        est_s, upcoming = src.step(theirs)
        if prim is None:
            est = est_s
        else:
            extra = {"isolated": [], "fusion": [theirs]}.get(role, [transfer] if transfer else [])
            est = prim.step(own, extra)
        transfer = upcoming
        assert upcoming.mean.shape == (2, B) and upcoming.cov.shape == (B, 2, 2)
        errors.append(np.linalg.norm(est.mean[:, [0, 2]] - truth[k][:, [0, 2]], axis=1))
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
    filt = build(parse(kind), CFG, model, x0_hat, list(range(B)))
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
