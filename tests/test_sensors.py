"""The bearing-only, position and Doppler sensors, and the constant-acceleration model (issue #15).

Each sensor is checked against the MeasurementModel Protocol on every state layout (CV's, CT's and
CA's, whose position sits at (0, 3)): its Jacobian against finite differences, its angles across
the +-pi cut, its noise against R, and its position fix where it has one. On the linear-Gaussian
pair (constant acceleration, position fixes) the sigma-point filters are the Kalman filter.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from doubles import kalman
from tltrack.filters.decision import TransferPolicy
from tltrack.filters.sigma_point import SigmaPointFilter, SigmaRule, cubature3, unscented
from tltrack.models import (
    ConstantVelocity,
    CoordinatedTurn,
    Layout,
    MeasurementModel,
    Observation,
    PositionFix,
    RangeBearing,
)
from tltrack.models.bearing import Bearing
from tltrack.models.constant_acceleration import ConstantAcceleration
from tltrack.models.position import Position
from tltrack.models.range_bearing_doppler import RangeBearingDoppler

pytestmark = pytest.mark.unit

SENSOR_AT = (50.0, -20.0)
Sensor = Bearing | Position | RangeBearingDoppler
SENSORS: dict[str, Callable[[Layout], Sensor]] = {
    "bearing": lambda lay: Bearing(3e-3, lay, SENSOR_AT),
    "position": lambda lay: Position(lay, SENSOR_AT, sigma_pos=7.0),
    "doppler": lambda lay: RangeBearingDoppler(10.0, 3e-3, lay, SENSOR_AT, sigma_rr=1.5),
}
#: each state layout with its state dimension
LAYOUTS = {
    "cv": (ConstantVelocity.layout, 4),
    "ct": (CoordinatedTurn.layout, 5),
    "ca": (ConstantAcceleration.layout, 6),
}
#: (position, velocity) of test targets; the second's bearing from the sensor is pi - 0.001
TARGETS = [
    ((1000.0, 300.0), (12.0, -7.0)),
    ((SENSOR_AT[0] - 1000.0, SENSOR_AT[1] + 1.0), (-300.0, 20.0)),
    ((-200.0, -3000.0), (0.0, 0.0)),
    ((30.0, 60.0), (5.0, 5.0)),
]
CUT = 1  #: the index in TARGETS of the target just above the -x axis, seen from the sensor
CASES = [(s, lay) for s in SENSORS for lay in LAYOUTS]


def _state(
    layout: Layout, n: int, pos: tuple[float, float], vel: tuple[float, float]
) -> np.ndarray:
    """A state with this position and velocity; its other components (CT's turn rate, CA's
    accelerations) are small non-zero numbers, which no sensor may depend on."""
    x = 0.01 * np.arange(1.0, n + 1.0)
    x[list(layout.pos)] = pos
    x[list(layout.vel)] = vel
    return x


def _sensor(name: str, layout_name: str) -> tuple[Sensor, Layout, int]:
    layout, n = LAYOUTS[layout_name]
    return SENSORS[name](layout), layout, n


@pytest.mark.parametrize("layout_name", LAYOUTS)
def test_the_sensors_implement_the_protocols_and_fix_a_position_unless_bearing_only(
    layout_name: str,
) -> None:
    layout, _ = LAYOUTS[layout_name]
    b, p, d = (SENSORS[k](layout) for k in ("bearing", "position", "doppler"))
    for s in (b, p, d):
        assert isinstance(s, MeasurementModel)
        assert s.n_z == len(s.components) == len(s.angular)
    assert isinstance(p, PositionFix) and isinstance(d, PositionFix)
    assert not isinstance(b, PositionFix)
    assert (b.kind, p.kind, d.kind) == ("bearing", "position", "range-bearing-doppler")
    assert b.components == ("bearing_rad",)
    assert p.components == ("x_m", "y_m")
    assert d.components == ("range_m", "bearing_rad", "range_rate_mps")


def test_the_measurements_are_what_each_sensor_sees() -> None:
    layout, n = LAYOUTS["ca"]
    sx, sy = SENSOR_AT
    x = _state(layout, n, (sx + 300.0, sy + 400.0), (6.0, 8.0))  # r = 500, moving radially
    b, p, d = (SENSORS[k](layout) for k in ("bearing", "position", "doppler"))
    np.testing.assert_allclose(b.h(x), [np.arctan2(400.0, 300.0)])
    np.testing.assert_allclose(p.h(x), [sx + 300.0, sy + 400.0])  # absolute, not from the sensor
    np.testing.assert_allclose(d.h(x), [500.0, np.arctan2(400.0, 300.0), 10.0])
    x[list(layout.vel)] = (-8.0, 6.0)  # across the line of sight: no range rate
    assert abs(d.h(x)[2]) < 1e-12
    x[list(layout.pos)] = SENSOR_AT  # on the sensor: finite, as the bearing's atan2(0, 0) = 0
    np.testing.assert_array_equal(d.h(x), [0.0, 0.0, 0.0])


@pytest.mark.parametrize(("name", "layout_name"), CASES)
def test_h_is_batched_over_trailing_axes(name: str, layout_name: str) -> None:
    s, layout, n = _sensor(name, layout_name)
    X = np.stack([_state(layout, n, p, v) for p, v in TARGETS], axis=1)  # (n, 4)
    cloud = np.repeat(X[:, :, None], 3, axis=2)  # (n, B=4, N=3)
    Z = s.h(cloud)
    assert Z.shape == (s.n_z, len(TARGETS), 3)
    for i in range(len(TARGETS)):
        np.testing.assert_allclose(Z[:, i, 1], s.h(X[:, i]), rtol=1e-15)


@pytest.mark.parametrize(("name", "layout_name"), CASES)
@pytest.mark.parametrize("target", range(len(TARGETS)))
def test_H_matches_central_finite_differences(name: str, layout_name: str, target: int) -> None:
    s, layout, n = _sensor(name, layout_name)
    x = _state(layout, n, *TARGETS[target])
    eps = 1e-4
    # through the wrapped residual, so that a bearing at the cut differentiates correctly
    fd = np.stack(
        [s.residual(s.h(x + eps * e), s.h(x - eps * e)) / (2 * eps) for e in np.eye(n)], axis=1
    )
    H = s.H(x)
    assert H.shape == (s.n_z, n)
    # rounding: each h carries a few ulps of |h|, divided by 2 eps; truncation (eps^2 h''' / 6)
    # is far below it at these ranges, and a wrong derivative is off by its own size
    rounding = 16 * np.finfo(float).eps * np.maximum(np.abs(s.h(x)), 1.0) / eps
    assert np.all(np.abs(H - fd) <= 1e-6 * np.abs(fd) + rounding[:, None])


@pytest.mark.parametrize("name", SENSORS)
def test_the_residual_wraps_angles_across_the_cut_and_nothing_else(name: str) -> None:
    s = SENSORS[name](LAYOUTS["cv"][0])
    ang = np.array(s.angular)[:, None]
    z = np.broadcast_to(np.where(ang, np.pi - 0.01, 5.0), (s.n_z, 3))
    zhat = np.broadcast_to(np.where(ang, -np.pi + 0.01, 2.0), (s.n_z, 3))
    np.testing.assert_allclose(s.residual(z, zhat), np.where(ang, -0.02, 3.0) + 0 * z)
    np.testing.assert_allclose(s.residual(zhat, z), np.where(ang, 0.02, -3.0) + 0 * z)


@pytest.mark.parametrize("name", SENSORS)
def test_the_mean_is_circular_for_angles_and_arithmetic_otherwise(name: str) -> None:
    s = SENSORS[name](LAYOUTS["cv"][0])
    ang = np.array(s.angular)[:, None, None]
    near_cut = np.array([np.pi - 0.01, -np.pi + 0.01, np.pi - 0.03, -np.pi + 0.03])
    Z = np.broadcast_to(np.where(ang, near_cut, np.arange(1.0, 5.0)), (s.n_z, 2, 4))
    m = s.mean(Z, axis=2)  # over the particles of B = 2 runs
    assert m.shape == (s.n_z, 2)
    for i, is_angle in enumerate(s.angular):
        if is_angle:
            np.testing.assert_allclose(np.abs(m[i]), np.pi)  # the naive mean would be 0
        else:
            np.testing.assert_allclose(m[i], 2.5)


def test_R_is_the_intensity_times_each_channels_variance() -> None:
    layout = LAYOUTS["cv"][0]
    b, p, d = (SENSORS[k](layout) for k in ("bearing", "position", "doppler"))
    np.testing.assert_allclose(b.R(4.0), [[4.0 * 9e-6]])
    np.testing.assert_allclose(p.R(4.0), 4.0 * 49.0 * np.eye(2))
    np.testing.assert_allclose(d.R(4.0), 4.0 * np.diag([100.0, 9e-6, 2.25]))
    assert Position(layout).sigma_pos == 10.0
    assert RangeBearingDoppler(10.0, 1e-3, layout).sigma_rr == 1.0


#: draws per statistical check, and its two-sided level in standard errors (p ~ 6e-7 per entry)
DRAWS, Z_SE = 20_000, 5.0


def _draw_residuals(
    s: Sensor, x: np.ndarray, intensity: float, seed: int, offset: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``DRAWS`` measurements (DRAWS, n_z) of the one state x, and their residuals (n_z, DRAWS)."""
    Z = s.draw(np.repeat(x[None], DRAWS, axis=0), intensity, np.random.default_rng(seed), offset)
    return Z, s.residual(Z.T, s.h(x)[:, None])


@pytest.mark.parametrize(("name", "layout_name"), CASES)
def test_draws_have_covariance_R_and_wrapped_angles(name: str, layout_name: str) -> None:
    s, layout, n = _sensor(name, layout_name)
    x = _state(layout, n, *TARGETS[CUT])  # bearing pi - 0.001, bearing noise 0.006: draws wrap
    intensity = 4.0
    R = s.R(intensity)
    Z, d = _draw_residuals(s, x, intensity, seed=11)
    assert Z.shape == (DRAWS, s.n_z)
    # standard errors of a Gaussian sample's mean and covariance: sqrt(R_ii / K) and
    # sqrt((R_ii R_jj + R_ij^2) / K)
    var = np.diag(R)
    assert np.all(np.abs(d.mean(axis=1)) <= Z_SE * np.sqrt(var / DRAWS))
    C = np.cov(d)
    se = np.sqrt((np.outer(var, var) + R**2) / DRAWS)
    assert np.all(np.abs(np.atleast_2d(C) - R) <= Z_SE * se)
    for i, is_angle in enumerate(s.angular):
        if is_angle:
            assert np.all((Z[:, i] > -np.pi) & (Z[:, i] <= np.pi))
            # on both sides of the cut
            assert (Z[:, i] < 0).mean() > 0.3 and (Z[:, i] > 0).mean() > 0.3


@pytest.mark.parametrize(
    ("name", "shifted"), [("bearing", [1.0]), ("position", [1.0, 0.0]), ("doppler", [0, 1.0, 0])]
)
def test_a_miscalibration_shifts_the_documented_component(name: str, shifted: list[float]) -> None:
    s, layout, n = _sensor(name, "ca")
    intensity = 4.0
    offset = s.miscalibration(10.0, intensity)
    sd = np.sqrt(np.diag(s.R(intensity)))
    np.testing.assert_allclose(offset, 10.0 * sd * np.array(shifted))
    x = _state(layout, n, *TARGETS[CUT])  # the shifted bearing crosses the cut: still wrapped
    Z, d = _draw_residuals(s, x, intensity, seed=12, offset=offset)
    assert np.all(np.abs(d.mean(axis=1) - offset) <= Z_SE * sd / np.sqrt(DRAWS))
    for i, is_angle in enumerate(s.angular):
        if is_angle:
            assert np.all((Z[:, i] > -np.pi) & (Z[:, i] <= np.pi))


def _spd(rng: np.random.Generator, B: int, scales: list[float]) -> np.ndarray:
    """B random symmetric positive-definite matrices with these standard deviations."""
    k = len(scales)
    C = np.empty((B, k, k))
    for b in range(B):
        A = rng.standard_normal((k, k + 2))
        corr = A @ A.T
        d = 1.0 / np.sqrt(np.diag(corr))
        C[b] = np.outer(scales, scales) * corr * np.outer(d, d)
    return C


@pytest.mark.parametrize("layout_name", LAYOUTS)
def test_the_position_sensors_fix_is_its_measurement(layout_name: str) -> None:
    s, layout, n = _sensor("position", layout_name)
    assert isinstance(s, Position)
    X = np.stack([_state(layout, n, p, v) for p, v in TARGETS], axis=1)
    z = s.h(X)
    P = _spd(np.random.default_rng(5), len(TARGETS), [7.0, 9.0])
    pos, S = s.to_position(z, P)
    np.testing.assert_array_equal(pos, layout.position(X))
    np.testing.assert_array_equal(S, P)
    np.testing.assert_array_equal(s.from_position(z, S), P)


@pytest.mark.parametrize("layout_name", LAYOUTS)
def test_the_doppler_radars_fix_comes_from_range_and_bearing_and_round_trips(
    layout_name: str,
) -> None:
    s, layout, n = _sensor("doppler", layout_name)
    assert isinstance(s, RangeBearingDoppler)
    X = np.stack([_state(layout, n, p, v) for p, v in TARGETS], axis=1)
    z = s.h(X)
    B = len(TARGETS)
    P = _spd(np.random.default_rng(6), B, [10.0, 3e-3, 1.5])
    pos, S = s.to_position(z, P)
    np.testing.assert_allclose(pos, layout.position(X), rtol=1e-12, atol=1e-9)
    assert S.shape == (B, 2, 2)
    # the same fix as the paper's radar's from (range, bearing), whatever the range rate says
    rb = RangeBearing(10.0, 3e-3, layout, SENSOR_AT)
    rb_pos, rb_S = rb.to_position(z[:2], P[:, :2, :2])
    np.testing.assert_array_equal(pos, rb_pos)
    np.testing.assert_array_equal(S, rb_S)
    back = s.from_position(z, S)
    assert back.shape == (B, 3, 3)
    np.testing.assert_allclose(back[:, :2, :2], P[:, :2, :2], rtol=1e-9, atol=1e-15)
    assert np.all(back[:, 2, :] == 0.0) and np.all(back[:, :, 2] == 0.0)  # see from_position
    np.testing.assert_allclose(s.to_position(z, back)[1], S, rtol=1e-9)


def test_the_bias_discount_inflates_a_doppler_transfers_bearing_and_not_its_range_rate() -> None:
    """The consumer of from_position: a position primary, a bearing-biased Doppler source."""
    layout, n = LAYOUTS["cv"]
    primary = Position(layout, sigma_pos=10.0)
    source = RangeBearingDoppler(10.0, 1e-3, layout, (-3000.0, -5000.0))
    x = _state(layout, n, (1500.0, 800.0), (10.0, -5.0))
    B = 300
    R_p = primary.R(1.0)
    P_eta = source.R(1.0) + np.diag([30.0, 2e-6, 0.5])
    bias = source.miscalibration(10.0, 1.0)
    rng = np.random.default_rng(7)
    policy = TransferPolicy()
    for _ in range(30):
        z = primary.h(x)[:, None] + np.linalg.cholesky(R_p) @ rng.standard_normal((2, B))
        eta = source.h(x)[:, None] + np.linalg.cholesky(P_eta) @ rng.standard_normal((3, B))
        t = Observation(source, eta + bias[:, None], np.broadcast_to(P_eta, (B, 3, 3)))
        out = policy.select(Observation.broadcast(primary, z, R_p), [t])[0]
    assert out.cov.shape == (B, 3, 3)
    assert np.all(np.linalg.eigvalsh(out.cov) > 0)
    assert out.mask is not None and out.mask.mean() < 0.01  # shut out
    temper = out.cov[:, 2, 2] / P_eta[2, 2]  # the range rate is only tempered, not discounted
    assert np.all(temper >= 1.0)
    assert np.all(out.cov[:, 1, 1] / P_eta[1, 1] > 2.0 * temper)  # the bearing is discounted


# --- constant acceleration ---------------------------------------------------------------------

CA = ConstantAcceleration(T=2.0, q=0.05)


def test_ca_q_sqrt_is_an_exact_square_root_of_the_singular_wiener_acceleration_q() -> None:
    np.testing.assert_array_equal(CA.Q_sqrt @ CA.Q_sqrt.T, CA.Q)
    assert CA.Q_sqrt.shape == (6, 2) and np.linalg.matrix_rank(CA.Q) == 2
    T, q = CA.T, CA.q
    block = q * np.array(
        [[T**4 / 4, T**3 / 2, T**2 / 2], [T**3 / 2, T**2, T], [T**2 / 2, T, 1.0]]
    )  # Bar-Shalom, Li & Kirubarajan (2001), sec. 6.3.3
    np.testing.assert_allclose(CA.Q[:3, :3], block, rtol=1e-15)
    np.testing.assert_allclose(CA.Q[3:, 3:], block, rtol=1e-15)
    assert np.all(CA.Q[:3, 3:] == 0.0)
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(CA.Q)


def test_ca_jacobian_is_its_transition_matrix() -> None:
    x = np.array([100.0, 3.0, -0.5, -40.0, 7.0, 0.25])
    np.testing.assert_array_equal(CA.F(x), CA.A)
    eps = 1e-3
    fd = np.stack([(CA.f(x + eps * e) - CA.f(x - eps * e)) / (2 * eps) for e in np.eye(6)], 1)
    np.testing.assert_allclose(fd, CA.A, atol=1e-9)
    assert CA.n == 6


def test_ca_moves_by_velocity_and_acceleration() -> None:
    T = CA.T
    x = np.array([100.0, 3.0, 0.0, -40.0, 7.0, 0.0])
    np.testing.assert_allclose(CA.f(x), [100.0 + 3.0 * T, 3.0, 0.0, -40.0 + 7.0 * T, 7.0, 0.0])
    x[[2, 5]] = -0.5, 0.25
    expected = [
        100.0 + 3.0 * T - 0.5 * T * T / 2,
        3.0 - 0.5 * T,
        -0.5,
        -40.0 + 7.0 * T + 0.25 * T * T / 2,
        7.0 + 0.25 * T,
        0.25,
    ]
    np.testing.assert_allclose(CA.f(x), expected)
    cloud = np.random.default_rng(8).standard_normal((6, 3, 5))
    np.testing.assert_allclose(CA.f(cloud)[:, 1, 2], CA.A @ cloud[:, 1, 2])


def test_ca_layout_picks_the_position_and_velocity() -> None:
    x = np.arange(6.0)
    assert CA.layout == Layout(pos=(0, 3), vel=(1, 4))
    np.testing.assert_array_equal(CA.layout.position(x), [0.0, 3.0])
    np.testing.assert_array_equal(x[list(CA.layout.vel)], [1.0, 4.0])


# --- the linear-Gaussian pair -------------------------------------------------------------------

X0_CA = np.array([0.0, 20.0, 0.5, 1000.0, -10.0, -0.2])
P0_CA = np.diag([100.0, 25.0, 1.0, 100.0, 25.0, 1.0])


@pytest.mark.parametrize("rule", [unscented(6, 2.0), cubature3(6)], ids=["ukf", "ckf3"])
@pytest.mark.parametrize("with_transfer", [False, True])
def test_sigma_point_filters_equal_the_kalman_filter_on_ca_with_position_fixes(
    rule: SigmaRule, with_transfer: bool
) -> None:
    model = ConstantAcceleration(T=1.0, q=0.01)
    sensor = Position(model.layout, sigma_pos=10.0)
    R, P_eta = sensor.R(1.0), np.diag([30.0, 40.0])
    B, K = 3, 25
    rng = np.random.default_rng(9)
    x = np.repeat(X0_CA[:, None], B, axis=1)
    z_p, z_s = [], []
    for _ in range(K):
        x = model.A @ x + model.Q_sqrt @ rng.standard_normal((2, B))
        z_p.append(sensor.h(x) + rng.normal(0.0, 10.0, (2, B)))
        z_s.append(sensor.h(x) + rng.normal(0.0, 6.0, (2, B)))
    filt = SigmaPointFilter(model, rule, np.repeat(X0_CA[:, None], B, axis=1), P0_CA)
    estimates = []
    for k in range(K):
        obs = [Observation.broadcast(sensor, z_p[k], R)]
        if with_transfer:
            obs.append(Observation.broadcast(sensor, z_s[k], P_eta))
        filt.predict()
        filt.update(obs)
        estimates.append(filt.estimate())
    assert np.all(filt.repairs == 0)
    for b in range(B):
        zs = [[z_p[k][:, b], *([z_s[k][:, b]] if with_transfer else [])] for k in range(K)]
        Rs = [[R, *([P_eta] if with_transfer else [])] for _ in range(K)]
        for est, (m, P) in zip(estimates, kalman(model, sensor, X0_CA, P0_CA, zs, Rs), strict=True):
            np.testing.assert_allclose(est.mean[b], m, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(est.cov[b], P, rtol=1e-9, atol=1e-9)
