import numpy as np
import pytest
from tltrack.config import make_config
from tltrack.engine.setup import Setup
from tltrack.models import CoordinatedTurn, RangeBearing, wrap_angle

pytestmark = pytest.mark.unit


def test_wrap_angle_lands_in_half_open_interval():
    a = np.array([np.pi, -np.pi, 3 * np.pi, 0.1 - 2 * np.pi, 7.0])
    w = wrap_angle(a)
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    assert w[1] == pytest.approx(np.pi)


@pytest.mark.parametrize("scenario", ["cv", "ct"])
def test_q_sqrt_is_an_exact_square_root_of_the_singular_q(scenario):
    m = Setup(make_config(scenario=scenario)).motion
    np.testing.assert_allclose(m.Q_sqrt @ m.Q_sqrt.T, m.Q, atol=1e-15)
    assert np.linalg.matrix_rank(m.Q) < m.n
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(m.Q[:4, :4])  # why the square root exists


def test_ct_is_continuous_through_zero_turn_rate():
    m = Setup(make_config(scenario="ct")).motion
    x = np.array([1000.0, 300.0, 1000.0, 20.0, 0.0])
    near = x.copy()
    near[4] = 1e-7
    np.testing.assert_allclose(m.f(x), m.f(near), rtol=0, atol=1e-3)
    np.testing.assert_allclose(m.f(x)[:4], [1300.0, 300.0, 1020.0, 20.0])


@pytest.mark.parametrize("w", [-0.05, 1e-9, 0.2])
def test_jacobians_match_finite_differences(w):
    m = Setup(make_config(scenario="ct")).motion
    s = RangeBearing(10.0, 3e-3, CoordinatedTurn.layout, position=(50.0, -20.0))
    x = np.array([1000.0, 300.0, -400.0, 20.0, w])
    eps = 1e-6
    basis = np.eye(5)
    F = np.stack([(m.f(x + eps * e) - m.f(x - eps * e)) / (2 * eps) for e in basis], axis=1)
    H = np.stack([(s.h(x + eps * e) - s.h(x - eps * e)) / (2 * eps) for e in basis], axis=1)
    np.testing.assert_allclose(m.F(x), F, atol=1e-5)
    np.testing.assert_allclose(s.H(x), H, atol=1e-7)


def test_bearing_residual_and_mean_across_the_cut():
    s = RangeBearing(10.0, 3e-3, CoordinatedTurn.layout)
    z = np.array([100.0, np.pi - 0.01])
    zhat = np.array([100.0, -np.pi + 0.01])
    assert s.residual(z, zhat)[1] == pytest.approx(-0.02)
    Z = np.array([[1.0, 1.0], [np.pi - 0.01, -np.pi + 0.01]])
    assert abs(s.mean(Z, axis=1)[1]) == pytest.approx(np.pi)
