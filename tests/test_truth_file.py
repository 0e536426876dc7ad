"""Recorded tracks as truth (tltrack.config.truth_file): refusals, resampling, the frame, states."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest
from tltrack.config.truth_file import (
    StateLayout,
    TruthFileError,
    check_clearance,
    full_state,
    geodetic_to_local,
    load_truth,
    local_to_geodetic,
    read_track,
    resample,
    to_local,
)
from tltrack.models.kinds import MOTIONS

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "examples" / "tracks" / "ais-nyharbor-2020-06-30-mmsi-367370920.csv"
DEFAULT_SENSORS = {"primary": (0.0, 0.0), "s1": (0.0, 0.0)}

# WGS84, for references computed independently of the module
A, F = 6378137.0, 1 / 298.257223563
E2 = F * (2 - F)


def _write(tmp_path: Path, text: str, name: str = "track.csv") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


GOOD_XY = "t,x,y\n0,1000,1000\n60,1300,1000\n130,1600,1100\n"


# ------------------------------------------------------------------------------------- refusals


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        ("", 1, "empty"),
        ("0,1000,1000\n60,1300,1000\n120,1600,1100\n", 1, "header"),
        ("t,x,z\n0,1,2\n1,2,3\n2,3,4\n", 1, "header"),
        ("t,x,y,z\n0,1,2,3\n", 1, "header"),
        ("t,x,y\n0,1000,1000\n60,1300\n120,1600,1100\n", 3, "2 fields"),
        ("t,x,y\n0,1000,1000\n60,1300,1000,5\n120,1600,1100\n", 3, "4 fields"),
        ("t,x,y\n0,1000,1000\n60,abc,1000\n120,1600,1100\n", 3, "not a number"),
        ("t,x,y\n0,1000,1000\n60,,1000\n120,1600,1100\n", 3, "not a number"),
        ("t,x,y\n0,1000,1000\n60,1300,1000\n120,nan,1100\n", 4, "not finite"),
        ("t,x,y\n0,1000,1000\n60,1300,inf\n120,1600,1100\n", 3, "not finite"),
        ("t,x,y\n0,1000,1000\n-inf,1300,1000\n120,1600,1100\n", 3, "not finite"),
        ("t,x,y\n0,1000,1000\n60,1300,1000\n60,1600,1100\n", 4, "does not increase"),
        ("t,x,y\n0,1000,1000\n60,1300,1000\n30,1600,1100\n", 4, "does not increase"),
        ("t,x,y\n0,1000,1000\n60,1300,1000\n", 3, "at least 3"),
        ("t,x,y\n0,1000,1000\n", 2, "at least 3"),
        ("t,x,y\n", 1, "at least 3"),
        ("t,x,y\n0,1000,1000\n\n60,1300,1000\n120,1600,1100\n", 3, "blank line"),
        ("t,x,y\n0,1000,1000\n60,1300,1000\n180.5,1600,1100\n", 4, "gap of 120.5 s since line 3"),
        ("t,lat,lon\n0,40.1,-74\n60,90.5,-74\n120,40.2,-74\n", 3, "lat = 90.5"),
        ("t,lat,lon\n0,40.1,-74\n60,40.15,-74\n120,40.2,-180.01\n", 4, "lon = -180.01"),
    ],
)
def test_a_bad_file_is_refused_whole_naming_the_file_and_the_line(tmp_path, text, line, words):
    path = _write(tmp_path, text, "bad.csv")
    with pytest.raises(TruthFileError) as err:
        read_track(path)
    message = str(err.value)
    assert message.startswith(f"{path}: line {line}: "), message
    assert words in message


def test_the_gap_limit_is_a_parameter_and_a_gap_of_exactly_the_limit_passes(tmp_path):
    path = _write(tmp_path, "t,x,y\n0,1000,1000\n120,1300,1000\n150,1600,1100\n")
    assert len(read_track(path).t) == 3
    with pytest.raises(TruthFileError, match="line 3: gap of 120 s since line 2"):
        read_track(path, max_gap_s=100.0)


def test_an_unreadable_file_is_refused_naming_it(tmp_path):
    with pytest.raises(TruthFileError, match=r"missing\.csv: cannot read"):
        read_track(tmp_path / "missing.csv")
    bad = tmp_path / "binary.csv"
    bad.write_bytes(b"t,x,y\n0,\xff,1\n")
    with pytest.raises(TruthFileError, match="not UTF-8"):
        read_track(bad)


def test_header_case_spaces_a_bom_crlf_and_trailing_blank_lines_are_accepted(tmp_path):
    path = tmp_path / "ok.csv"
    path.write_bytes(b"\xef\xbb\xbfT, X ,Y\r\n0,1000,1000\r\n60,1300,1000\r\n130,1600,1100\r\n\r\n")
    track = read_track(path)
    assert not track.geographic
    np.testing.assert_array_equal(track.t, [0, 60, 130])
    np.testing.assert_array_equal(track.lines, [2, 3, 4])
    assert track.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()


def test_k_follows_the_file_may_shorten_it_and_never_lengthens_it(tmp_path):
    path = _write(tmp_path, GOOD_XY)  # 130 s
    full = load_truth(path, Ts=1.0)
    assert full.K == 130 and full.positions.shape == (131, 2)
    assert load_truth(path, Ts=3.0).K == 43  # floor(130 / 3)
    short = load_truth(path, Ts=1.0, K=50)
    assert short.K == 50
    np.testing.assert_array_equal(short.positions, full.positions[:51])
    with pytest.raises(TruthFileError, match=r"K = 131 .* at most K = 130"):
        load_truth(path, Ts=1.0, K=131)
    with pytest.raises(TruthFileError, match="need K >= 2"):
        load_truth(path, Ts=1.0, K=1)
    with pytest.raises(TruthFileError, match="need K >= 2"):
        load_truth(path, Ts=100.0)  # 130 s holds one step of 100 s


def test_both_interpolants_pass_through_the_reports(tmp_path):
    path = _write(tmp_path, GOOD_XY)
    for method in ("cubic", "linear"):
        pos = load_truth(path, Ts=1.0, method=method).positions
        np.testing.assert_allclose(pos[[0, 60, 130]], [[1000, 1000], [1300, 1000], [1600, 1100]])
    with pytest.raises(ValueError, match="unknown interpolation"):
        resample(np.array([0.0, 1, 2]), np.zeros((3, 2)), 0.5, method="quadratic")


# ------------------------------------------------------------------------- resampling, full state


def test_an_irregularly_sampled_circle_is_recovered(tmp_path):
    """A ship on a 1 km circle at 5 m/s (Omega = 0.005 rad/s, counter-clockwise, two turns, so
    the heading crosses +-pi four times), reported at AIS-like times 30-90 s apart.

    Tolerances, all over every step of the cubic spline at Ts = 1 s: position 1 m, velocity
    1.5% of the speed, Omega 10% (2% RMS), acceleration 12% of the centripetal V Omega.
    """
    R, V = 1000.0, 5.0
    w = V / R
    rng = np.random.default_rng(0)
    t = np.cumsum(np.r_[0.0, rng.uniform(30.0, 90.0, 47)])
    rows = "".join(
        f"{tt:.17g},{R * math.cos(w * tt):.17g},{R * math.sin(w * tt):.17g}\n" for tt in t
    )
    truth = load_truth(_write(tmp_path, "t,x,y\n" + rows), Ts=1.0)

    k = np.arange(truth.K + 1.0)
    c, s = np.cos(w * k), np.sin(w * k)
    assert math.floor(t[-1]) == truth.K and w * truth.K > 4 * math.pi
    np.testing.assert_array_less(np.hypot(*(truth.positions - np.c_[R * c, R * s]).T), 1.0)

    ct = full_state(truth.positions, 1.0, "ct")
    ca = full_state(truth.positions, 1.0, "ca")
    velocity_error = np.hypot(ct[:, 1] + V * s, ct[:, 3] - V * c)
    np.testing.assert_array_less(velocity_error, 0.015 * V)
    np.testing.assert_array_equal(ca[:, [1, 4]], ct[:, [1, 3]])
    omega_error = np.abs(ct[:, 4] - w)
    assert omega_error.max() < 0.10 * w and np.sqrt(np.mean(omega_error**2)) < 0.02 * w
    accel_error = np.hypot(ca[:, 2] + w * V * c, ca[:, 5] + w * V * s)
    np.testing.assert_array_less(accel_error, 0.12 * V * w)


def test_the_difference_formulas_on_exact_circle_samples():
    """Central differences keep the heading exact on a circle: Omega exact at k = 2..K-2, and
    the speed V sin(w Ts) / (w Ts), as the module docstring says."""
    R, Ts, w = 300.0, 2.0, -0.05  # clockwise
    k = np.arange(200.0)
    p = np.c_[R * np.cos(w * Ts * k), R * np.sin(w * Ts * k)]
    x = full_state(p, Ts, "ct")
    np.testing.assert_allclose(x[2:-2, 4], w, rtol=1e-9)
    np.testing.assert_allclose(x[[0, 1, -2, -1], 4], w, rtol=5e-3)
    speed = np.hypot(x[1:-1, 1], x[1:-1, 3])
    np.testing.assert_allclose(speed, abs(R * w) * math.sin(w * Ts) / (w * Ts), rtol=1e-12)
    a = full_state(p, Ts, "ca")[1:-1][:, [2, 5]]
    np.testing.assert_allclose(a, -p[1:-1] * (2 - 2 * math.cos(w * Ts)) / Ts**2, atol=1e-12)


def test_turn_rate_is_zero_where_the_object_is_at_rest():
    p = np.zeros((10, 2))
    p[5:, 0] = np.arange(5) * 3.0  # still, then 3 m/s east
    x = full_state(p, 1.0, "ct")
    assert np.all(np.isfinite(x)) and np.all(x[:4, 4] == 0.0)


def test_state_layouts_place_every_component():
    p = np.c_[np.arange(5.0) ** 2, 2 * np.arange(5.0)]  # x = t^2, y = 2 t
    cv, ct, ca = (full_state(p, 1.0, kind) for kind in ("cv", "ct", "ca"))
    assert (cv.shape, ct.shape, ca.shape) == ((5, 4), (5, 5), (5, 6))
    np.testing.assert_allclose(cv[:, 0], p[:, 0])
    np.testing.assert_allclose(cv[:, 1], 2 * np.arange(5.0))  # exact for a quadratic
    np.testing.assert_allclose(ca[:, [0, 3]], p)
    np.testing.assert_allclose(ca[:, 2], 2.0)
    np.testing.assert_allclose(ca[:, 5], 0.0, atol=1e-12)
    custom = StateLayout(n=4, pos=(2, 3), vel=(0, 1))
    np.testing.assert_allclose(full_state(p, 1.0, custom)[:, [2, 3, 0, 1]], cv)
    with pytest.raises(ValueError, match="exactly once"):
        StateLayout(n=5, pos=(0, 2), vel=(1, 3))
    assert StateLayout.of(MOTIONS.get("ca").components).acc == (2, 5)


# -------------------------------------------------------------------------------------- the frame


def _meridian_arc(lat1: float, lat2: float) -> float:
    """Meridian arc length between two latitudes (degrees), by Simpson's rule on M(phi)."""
    phi = np.radians(np.linspace(lat1, lat2, 201))
    M = A * (1 - E2) / (1 - E2 * np.sin(phi) ** 2) ** 1.5
    h = (phi[-1] - phi[0]) / 200
    return float(h / 3 * (M[0] + M[-1] + 4 * M[1:-1:2].sum() + 2 * M[2:-1:2].sum()))


def test_one_minute_of_latitude_is_a_nautical_mile():
    """1' of latitude is 1852 m near 45 degrees (1842.9 m at the equator, 1861.6 m at the poles).

    The frame's stated error, s - R sin(s / R) ~ s^3 / (6 R^2), is 26 um at 1852 m and 4 mm at
    10 km; both are checked against the meridian arc.
    """
    east, north = geodetic_to_local(np.array(45.0 + 1 / 60), np.array(7.0), (45.0, 7.0))
    assert abs(east) < 1e-6 and abs(north - 1852.0) < 0.5
    assert abs(north - _meridian_arc(45.0, 45.0 + 1 / 60)) < 1e-4
    for lat in (0.0, 40.6, 60.0, -33.9):
        _, north = geodetic_to_local(np.array(lat + 1 / 60), np.array(0.0), (lat, 0.0))
        assert abs(north - _meridian_arc(lat, lat + 1 / 60)) < 1e-4
        assert 1842.0 < north < 1862.0
    s = _meridian_arc(40.0, 40.09)  # about 10 km north
    _, north = geodetic_to_local(np.array(40.09), np.array(-74.0), (40.0, -74.0))
    assert 0.0 < s - north < 0.006


def test_one_minute_of_longitude_is_the_parallels_arc():
    for lat in (0.0, 40.6, 60.0):
        phi = math.radians(lat)
        N = A / math.sqrt(1 - E2 * math.sin(phi) ** 2)
        east, north = geodetic_to_local(np.array(lat), np.array(10 + 1 / 60), (lat, 10.0))
        assert abs(east - N * math.cos(phi) * math.radians(1 / 60)) < 1e-3
        # the parallel bends towards the pole, away from the east axis, by about d^2 tan(lat) / 2N
        assert 0.0 <= north < 0.15 and (lat > 0.0 or north < 1e-9)


def test_local_to_geodetic_inverts_the_projection():
    for east, north, origin in [
        (3000.0, -4000.0, (40.6, -74.0)),
        (-50e3, 80e3, (-33.9, 151.2)),
        (-1000.0, 1000.0, (0.0, 179.999)),  # across the antimeridian
    ]:
        lat, lon = local_to_geodetic(east, north, origin)
        back = geodetic_to_local(np.array(lat), np.array(lon), origin)
        np.testing.assert_allclose(back, [east, north], atol=1e-6)


def test_an_origin_puts_the_frame_there_and_is_refused_for_a_metric_file(tmp_path):
    path = _write(tmp_path, "t,lat,lon\n0,40.5,-74.0\n60,40.501,-74.0\n120,40.502,-74.001\n")
    truth = load_truth(path, Ts=1.0, origin=(40.5, -74.0))
    assert truth.origin == (40.5, -74.0)
    np.testing.assert_allclose(truth.positions[0], [0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(truth.positions[60], [0.0, 111.04], atol=0.01)  # 0.001 deg north
    with pytest.raises(TruthFileError, match=r"sensor 'primary' .* step 0"):
        check_clearance(truth.positions, DEFAULT_SENSORS, name=path.name)
    with pytest.raises(TruthFileError, match="only to a t,lat,lon file"):
        to_local(read_track(_write(tmp_path, GOOD_XY, "xy.csv")), origin=(40.5, -74.0))
    with pytest.raises(TruthFileError, match="not a"):
        load_truth(path, Ts=1.0, origin=(-74.0, 400.0))


def test_the_default_origin_sits_the_standoff_south_west_of_the_track(tmp_path):
    path = _write(
        tmp_path,
        "t,lat,lon\n0,40.50,-74.00\n60,40.502,-73.998\n120,40.506,-73.999\n180,40.507,-74.004\n",
    )
    for standoff in (2000.0, 500.0):
        truth = load_truth(path, Ts=1.0, standoff_m=standoff)
        distance = np.hypot(*truth.reports.T)
        assert abs(distance.min() - standoff) < 1e-3
        sw = truth.reports[np.argmin(truth.reports.sum(axis=1))]
        np.testing.assert_allclose(sw, [standoff / math.sqrt(2)] * 2, atol=1e-6)
        # the whole track lies beyond the line through that report, square to the south-west
        assert np.all(truth.reports.sum(axis=1) >= math.sqrt(2) * standoff - 1e-6)


def test_a_sensor_near_the_track_is_refused_naming_it_and_the_step():
    k = np.arange(101.0)
    positions = np.c_[10.0 * k, np.full(101, 500.0)]  # east along y = 500 m
    check_clearance(positions, {"primary": (0.0, 0.0), "s1": (500.0, 399.0)})
    with pytest.raises(TruthFileError) as err:
        check_clearance(positions, {"primary": (0.0, 0.0), "s2": (500.0, 450.0)}, name="x.csv")
    message = str(err.value)
    assert message.startswith("x.csv: sensor 's2' at (500, 450)")
    assert "at step 42 " in message and "closest 50.0 m at step 50" in message
    with pytest.raises(TruthFileError, match="step 0"):
        check_clearance(positions, {"near": (0.0, 0.0)}, min_distance=600.0)


# ---------------------------------------------------------------------------------- shipped track


def test_the_shipped_track_loads_clear_of_the_default_sensors():
    truth = load_truth(SHIPPED, Ts=1.0)
    assert truth.K == 2850 and truth.K > 20 and truth.origin is not None
    assert len(truth.reports) == 32
    check_clearance(truth.positions, DEFAULT_SENSORS, name=truth.name)
    assert abs(np.hypot(*truth.reports.T).min() - 2000.0) < 1e-3
    assert np.hypot(*truth.positions.T).min() > 1900.0
    for kind in ("cv", "ct", "ca"):
        x = full_state(truth.positions, truth.Ts, kind)
        assert x.shape == (2851, len(MOTIONS.get(kind).components)) and np.all(np.isfinite(x))
    ct = full_state(truth.positions, truth.Ts, "ct")
    speed = np.hypot(ct[:, 1], ct[:, 3])
    assert speed.min() > 1.0 and speed.max() < 6.0  # 3.2-10.4 kn reported
    assert np.abs(ct[:, 4]).max() < 0.05  # rad/s: a harbour vessel, not an aircraft


def test_the_readme_describes_the_shipped_file():
    readme = (SHIPPED.parent / "README.md").read_text()
    assert SHIPPED.name in readme and "367370920" in readme
    assert hashlib.sha256(SHIPPED.read_bytes()).hexdigest() in readme
    assert "National Technology and Engineering" in readme
