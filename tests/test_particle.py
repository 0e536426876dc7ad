import numpy as np
import pytest
from doubles import PositionSensor, cv_model, kalman
from tltrack.engine.streams import streams
from tltrack.filters.particle import ParticleFilter
from tltrack.filters.resampling import systematic_indices
from tltrack.models.observation import Observation

pytestmark = pytest.mark.unit

R = np.diag([25.0, 25.0])
P0 = np.diag([50.0, 1.0, 50.0, 1.0])
X0 = np.array([100.0, 10.0, 100.0, 10.0])


def _measurements(steps=8, seed=3):
    rng = np.random.default_rng(seed)
    model, x, zs = cv_model(), X0.copy(), []
    for _ in range(steps):
        x = model.A @ x + model.Q_sqrt @ rng.standard_normal(2)
        zs.append(model.layout.position(x) + rng.normal(0, 5.0, 2))
    return zs


def test_systematic_resampling_keeps_offspring_within_one_of_n_w():
    rng = np.random.default_rng(0)
    w = rng.random((3, 50)) ** 4
    w /= w.sum(axis=1, keepdims=True)
    idx = systematic_indices(w, [np.random.default_rng(i) for i in range(3)])
    for b in range(3):
        counts = np.bincount(idx[b], minlength=50)
        assert np.all(np.abs(counts - 50 * w[b]) < 1.0 + 1e-9)


def test_pf_mean_approaches_the_kalman_mean_as_n_grows():
    model, sensor, zs = cv_model(), PositionSensor(), _measurements()
    kf = kalman(model, sensor, X0, P0, [[z] for z in zs], [[R]] * len(zs))
    errors = {}
    for n in (300, 30_000):
        B = 12
        pf = ParticleFilter(
            model, np.repeat(X0[:, None], B, 1), P0, n, streams(1, range(B), f"pf{n}")
        )
        for z, _ in zip(zs, kf, strict=True):
            pf.predict()
            pf.update([Observation.broadcast(sensor, np.repeat(z[:, None], B, 1), R)])
        est = pf.estimate()
        m_kf = kf[-1][0]
        errors[n] = np.sqrt(np.mean((est.mean - m_kf) ** 2 / np.diag(kf[-1][1])))
    assert errors[30_000] < errors[300] / 4  # ~ sqrt(100) = 10 in expectation
    assert errors[30_000] < 0.05


def test_tl_with_a_vague_transfer_is_the_isolated_pf():
    model, sensor, zs = cv_model(), PositionSensor(), _measurements()
    x0 = np.repeat(X0[:, None], 4, 1)
    iso = ParticleFilter(model, x0, P0, 2000, streams(5, range(4), "same"))
    tl = ParticleFilter(model, x0, P0, 2000, streams(5, range(4), "same"))
    vague = Observation.broadcast(sensor, np.array([0.0, 0.0]), 1e14 * np.eye(2))
    for z in zs:
        obs = Observation.broadcast(sensor, z, R)
        for pf, statements in ((iso, [obs]), (tl, [obs, vague])):
            pf.predict()
            pf.update(statements)
    np.testing.assert_allclose(iso.estimate().mean, tl.estimate().mean, atol=1e-9)


def test_two_sharp_likelihoods_never_give_nan():
    """Linear-space weights would underflow to 0/0 here; log-weights must not."""
    model, sensor = cv_model(), PositionSensor()
    pf = ParticleFilter(model, np.repeat(X0[:, None], 2, 1), P0, 500, streams(0, range(2), "x"))
    far = Observation.broadcast(sensor, np.array([5000.0, -5000.0]), 1e-4 * np.eye(2))
    pf.predict()
    pf.update([far, far])
    assert np.all(np.isfinite(pf.estimate().mean))


def test_mask_leaves_unmasked_runs_untouched():
    model, sensor = cv_model(), PositionSensor()
    x0 = np.repeat(X0[:, None], 2, 1)
    a = ParticleFilter(model, x0, P0, 1000, streams(2, range(2), "m"))
    b = ParticleFilter(model, x0, P0, 1000, streams(2, range(2), "m"))
    z = Observation.broadcast(sensor, np.array([110.0, 111.0]), R)
    extra = Observation(
        sensor,
        np.array([[150.0, 150.0], [150.0, 150.0]]),
        np.broadcast_to(R, (2, 2, 2)),
        mask=np.array([True, False]),
    )
    for f, obs in ((a, [z, extra]), (b, [z])):
        f.predict()
        f.update(obs)
    ea, eb = a.estimate().mean, b.estimate().mean
    np.testing.assert_allclose(ea[1], eb[1], atol=1e-12)
    assert abs(ea[0, 0] - eb[0, 0]) > 1.0


def test_predicted_observation_covers_the_source_noise():
    model, sensor = cv_model(), PositionSensor()
    pf = ParticleFilter(model, np.repeat(X0[:, None], 1, 1), P0, 20_000, streams(0, [0], "s"))
    pf.predict()
    obs = pf.predicted_observation(sensor, R)
    P_pred = model.A @ P0 @ model.A.T + model.Q
    expected = np.array([[P_pred[0, 0], P_pred[0, 2]], [P_pred[2, 0], P_pred[2, 2]]]) + R
    np.testing.assert_allclose(obs.cov[0], expected, rtol=0.05, atol=1.0)
    np.testing.assert_allclose(obs.mean[:, 0], [X0[0] + 10, X0[2] + 10], atol=0.5)
    assert obs.cov.shape == (1, 2, 2)
