"""Sigma-point rules and filters: exactness, the Kalman limit, bearings, masks and PD repair."""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import product

import numpy as np
import pytest
from tltrack.filters.sigma_point import SigmaPointFilter, SigmaRule, cubature3, cubature5, unscented
from tltrack.models import ConstantVelocity, CoordinatedTurn, RangeBearing, wrap_angle
from tltrack.models.observation import Observation

pytestmark = pytest.mark.unit

RULES = {
    "ukf": lambda n: unscented(n, 2.0),
    "ckf3": cubature3,
    "ckf5": cubature5,
}


def gaussian_moment(a: tuple[int, ...]) -> float:
    """E[prod x_i^a_i] under N(0, I): prod (a_i - 1)!! for even a_i, else 0."""
    out = 1.0
    for ai in a:
        if ai % 2:
            return 0.0
        out *= float(np.prod(np.arange(ai - 1, 0, -2))) if ai else 1.0
    return out


def assert_exact_to_degree(rule: SigmaRule, degree: int) -> None:
    for a in product(range(degree + 1), repeat=rule.n):
        if sum(a) <= degree:
            approx = rule.w @ np.prod(rule.xi ** np.array(a)[:, None], axis=0)
            assert approx == pytest.approx(gaussian_moment(a), abs=1e-12), a


def test_point_counts_and_negative_axis_weight() -> None:
    assert unscented(5, 2.0).xi.shape == (5, 11)
    assert cubature3(5).xi.shape == (5, 10)
    rule = cubature5(5)
    assert rule.xi.shape == (5, 51)
    assert rule.w[1] == pytest.approx(-1.0 / 98.0)
    assert rule.w.sum() == pytest.approx(1.0)


def test_cubature5_is_exact_to_degree_5() -> None:
    assert_exact_to_degree(cubature5(5), 5)
    assert_exact_to_degree(cubature5(3), 5)


@pytest.mark.parametrize("rule", [unscented(5, 2.0), cubature3(5), unscented(4, -1.0)])
def test_third_degree_rules_are_exact_to_degree_3(rule: SigmaRule) -> None:
    assert_exact_to_degree(rule, 3)


# --- the linear-Gaussian limit --------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class LinearModel:
    """x_k = A x_{k-1} + v, the f/F/Q interface of the motion models."""

    A: np.ndarray
    Q: np.ndarray
    n: int = field(init=False)
    Q_sqrt: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "n", self.A.shape[0])
        object.__setattr__(self, "Q_sqrt", np.linalg.cholesky(self.Q))

    def f(self, x: np.ndarray) -> np.ndarray:
        return np.tensordot(self.A, x, axes=1)

    def F(self, x: np.ndarray) -> np.ndarray:
        return self.A


@dataclass(frozen=True, eq=False)
class LinearSensor:
    """z = C x + w for any C: a linear sensor of any dimension (duck-typed, for the rules)."""

    C: np.ndarray

    @property
    def n_z(self) -> int:
        return self.C.shape[0]

    def h(self, x: np.ndarray) -> np.ndarray:
        return np.tensordot(self.C, x, axes=1)

    def H(self, x: np.ndarray) -> np.ndarray:
        return self.C

    def residual(self, z: np.ndarray, zhat: np.ndarray) -> np.ndarray:
        return z - zhat


def kalman_step(m, P, A, Q, Cs, Rs, zs):
    """Textbook KF predict + update on the stacked measurement (one run)."""
    m, P = A @ m, A @ P @ A.T + Q
    if not Cs:
        return m, P
    C = np.vstack(Cs)
    R = np.zeros((C.shape[0], C.shape[0]))
    i = 0
    for Rj in Rs:
        R[i : i + len(Rj), i : i + len(Rj)] = Rj
        i += len(Rj)
    S = C @ P @ C.T + R
    K = P @ C.T @ np.linalg.inv(S)
    m = m + K @ (np.concatenate(zs) - C @ m)
    P = P - K @ S @ K.T
    return m, P


def random_spd(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    G = rng.standard_normal((n, n))
    return scale * (G @ G.T / n + np.eye(n))


@pytest.mark.parametrize("name", sorted(RULES))
def test_linear_gaussian_equals_kalman(name: str) -> None:
    rng = np.random.default_rng(1)
    n, B, steps = 5, 3, 20
    A = np.eye(n) + 0.1 * rng.standard_normal((n, n))
    model = LinearModel(A, random_spd(rng, n, 0.1))
    s1, s2 = LinearSensor(rng.standard_normal((2, n))), LinearSensor(rng.standard_normal((3, n)))
    R1, R2 = random_spd(rng, 2), random_spd(rng, 3, 0.5)
    m0, P0 = rng.standard_normal((n, B)), random_spd(rng, n, 2.0)
    filt = SigmaPointFilter(model, RULES[name](n), m0, P0)
    ms, Ps = [m0[:, b] for b in range(B)], [P0] * B
    for k in range(steps):
        z1, z2 = rng.standard_normal((2, B)), rng.standard_normal((3, B))
        obs = [Observation.broadcast(s1, z1, R1)]
        if k % 2:  # a stacked two-observation update every other step
            obs.append(Observation.broadcast(s2, z2, R2))
        filt.predict()
        filt.update(obs)
        est = filt.estimate()
        for b in range(B):
            Cs, Rs, zs = [s1.C, s2.C][: len(obs)], [R1, R2][: len(obs)], [z1[:, b], z2[:, b]]
            ms[b], Ps[b] = kalman_step(ms[b], Ps[b], A, model.Q, Cs, Rs, zs[: len(obs)])
            np.testing.assert_allclose(est.mean[b], ms[b], rtol=0, atol=1e-9)
            np.testing.assert_allclose(est.cov[b], Ps[b], rtol=0, atol=1e-9)
    eta = filt.predicted_observation(s2, R2)
    for b in range(B):
        np.testing.assert_allclose(eta.mean[:, b], s2.C @ ms[b], atol=1e-9)
        np.testing.assert_allclose(eta.cov[b], s2.C @ Ps[b] @ s2.C.T + R2, atol=1e-9)
    assert not filt.repairs.any()


# --- bearings across the +-pi cut ----------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(RULES))
def test_bearing_across_pi_gives_a_small_innovation(name: str) -> None:
    """Behind the sensor (bearing ~ pi) an update must equal its mirror image at bearing ~ 0."""
    model = ConstantVelocity(T=1.0, q=0.1)
    sensor = RangeBearing(10.0, 1e-3, CoordinatedTurn.layout)
    R = sensor.R(1.0)
    P0 = np.diag([50.0, 1.0, 50.0, 1.0])
    mirror = np.array([-1.0, -1.0, 1.0, 1.0])  # x -> -x maps bearing b to pi - b
    m_back = np.array([-1010.0, 10.0, 0.5, 0.0])  # predicted bearing just below +pi
    z_back = np.array([1000.0, -np.pi + 0.002])  # measured just above -pi
    est = {}
    for label, m0, z in [
        ("back", m_back, z_back),
        ("front", mirror * m_back, np.array([z_back[0], wrap_angle(np.pi - z_back[1])])),
    ]:
        filt = SigmaPointFilter(model, RULES[name](4), m0[:, None], P0)
        filt.predict()
        eta = filt.predicted_observation(sensor, R)
        assert -np.pi < eta.mean[1, 0] <= np.pi
        filt.update([Observation.broadcast(sensor, z, R)])
        est[label] = filt.estimate()
    back, front = est["back"], est["front"]
    assert abs(back.mean[0, 2]) < 5.0  # y moved by metres, not by a 2*pi "innovation"
    np.testing.assert_allclose(back.mean[0], mirror * front.mean[0], atol=1e-8)
    np.testing.assert_allclose(back.cov[0], np.outer(mirror, mirror) * front.cov[0], atol=1e-8)


# --- masks ---------------------------------------------------------------------------------------


def test_masked_runs_skip_exactly_that_observation() -> None:
    rng = np.random.default_rng(2)
    model = ConstantVelocity(T=1.0, q=0.1)
    layout = CoordinatedTurn.layout
    s1 = RangeBearing(10.0, 3e-3, layout)
    s2 = RangeBearing(10.0, 3e-3, layout, (500.0, -200.0))
    R = s1.R(1.0)
    P0 = np.diag([50.0, 1.0, 50.0, 1.0])
    x0 = np.array([100.0, 10.0, 100.0, 10.0])
    B = 4
    m0 = x0[:, None] + 5.0 * rng.standard_normal((4, B))
    z1 = s1.h(model.f(x0)[:, None] + 1.0) + np.zeros((2, B))
    z2 = s2.h(model.f(x0)[:, None] - 1.0) + np.zeros((2, B))
    mask1 = np.array([True, True, False, False])
    mask2 = np.array([True, False, True, False])
    z1[:, ~mask1] = np.nan  # what a run does not receive must not matter
    z2[:, ~mask2] = np.nan
    filt = SigmaPointFilter(model, cubature5(4), m0, P0)
    filt.predict()
    prior = filt.estimate()
    filt.update(
        [
            Observation(s1, z1, np.broadcast_to(R, (B, 2, 2)), mask1),
            Observation(s2, z2, np.broadcast_to(R, (B, 2, 2)), mask2),
        ]
    )
    post = filt.estimate()
    np.testing.assert_array_equal(post.mean[3], prior.mean[3])  # no observation: untouched
    np.testing.assert_array_equal(post.cov[3], prior.cov[3])
    for b in range(3):
        single = SigmaPointFilter(model, cubature5(4), m0[:, b : b + 1], P0)
        single.predict()
        obs = [
            Observation.broadcast(s, z[:, b], R)
            for s, z, mask in [(s1, z1, mask1), (s2, z2, mask2)]
            if mask[b]
        ]
        single.update(obs)
        ref = single.estimate()
        np.testing.assert_allclose(post.mean[b], ref.mean[0], rtol=1e-12)
        np.testing.assert_allclose(post.cov[b], ref.cov[0], rtol=1e-10, atol=1e-12)


# --- positive-definiteness -----------------------------------------------------------------------


@dataclass(frozen=True)
class Spiky:
    """f(x)_0 = x_0^6: most of its spread sits on the 5th-degree rule's negative-weight axis."""

    n: int = 5
    Q: np.ndarray = field(default_factory=lambda: 1e-6 * np.eye(5))

    def f(self, x: np.ndarray) -> np.ndarray:
        y = x.copy()
        y[0] = x[0] ** 6
        return y


def test_indefinite_covariance_is_repaired_and_counted() -> None:
    """At x_0 = 0 the CKF5's predicted covariance is indefinite; at x_0 = 50, f is near-linear."""
    P0 = np.eye(5)
    m0 = np.zeros((5, 2))
    m0[0, 1] = 50.0  # run 1: x_0^6 nearly linear over +-sqrt(7)
    filt = SigmaPointFilter(Spiky(), cubature5(5), m0, P0)
    filt.predict()
    np.testing.assert_array_equal(filt.repairs, [1, 0])
    cov = filt.estimate().cov
    assert np.all(np.linalg.eigvalsh(cov) > 0.0)
    np.testing.assert_array_equal(cov, cov.swapaxes(-1, -2))
    filt.predict()  # sigma points from the repaired covariance are finite
    assert np.all(np.isfinite(filt.estimate().cov))
