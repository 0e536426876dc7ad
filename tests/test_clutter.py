"""Detections in clutter: the detection process, the measurement-set likelihood, PDA, and every
filter and role on cluttered scans."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tltrack.config import ConfigError, make_config
from tltrack.engine.montecarlo import run_batch
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import Setup
from tltrack.filters.association import CLOUD_GATE_SIGMAS, associate, gate_volume, scan_loglik
from tltrack.filters.likelihood import gaussian_loglik
from tltrack.filters.sigma_point import UnscentedKalmanFilter, unscented
from tltrack.models.detection import Detection
from tltrack.models.observation import Observation
from tltrack.models.scan import Scan

pytestmark = pytest.mark.unit


@pytest.fixture(scope="module")
def radar() -> Setup:
    return Setup(make_config(preset="paper"))


@pytest.mark.parametrize(
    ("given", "says"),
    [
        ({"pd": 0.0}, "primary_detection.pd"),
        ({"pd": 1.5}, "primary_detection.pd"),
        ({"clutter_rate": -1.0}, "primary_detection.clutter_rate"),
        ({"fov": {"x_m": [0, 1]}}, "fov.x_m: the sensor has no such component"),
        ({"fov": {"range_m": [5, 1]}}, "fov.range_m: empty or inverted"),
        ({"fov": {"bearing_rad": [0, 4]}}, "fov.bearing_rad: angles need"),
    ],
)
def test_a_bad_detection_process_is_refused_naming_the_field(given: dict, says: str) -> None:
    with pytest.raises(ConfigError, match=says.replace(".", r"\.")):
        make_config(primary_detection=given)


def test_a_sensor_without_field_of_view_bounds_refuses_false_alarms() -> None:
    with pytest.raises(ValueError, match=r"needs a field of view: give fov\.tof_s"):
        Detection(("tof_s",), clutter_rate=1.0)
    assert Detection(("tof_s",), pd=0.5).density == 0.0  # misses alone need no bounds
    assert Detection(("tof_s",), clutter_rate=1.0, fov={"tof_s": (0.0, 2.0)}).density == 0.5


def test_a_sector_across_the_cut_is_inside_on_both_sides() -> None:
    d = Detection(("bearing_rad",), fov={"bearing_rad": (3.0, -3.0)})
    assert d.inside(np.array([[3.1, -3.1, 0.0]])).tolist() == [True, True, False]
    assert d.volume == pytest.approx(2 * math.pi - 6.0)


def test_scans_hold_the_target_with_pd_and_poisson_false_alarms_uniform_in_the_fov() -> None:
    d = Detection(("range_m", "bearing_rad"), pd=0.7, clutter_rate=3.0)
    g = np.random.default_rng(1)
    target = np.array([5000.0, 0.5])
    hits, counts, clutter = 0, [], []
    for _ in range(4000):
        Z, is_clutter = d.scan(target, True, g)
        hits += int((~is_clutter).sum())
        counts.append(int(is_clutter.sum()))
        clutter.append(Z[is_clutter])
    c = np.vstack(clutter)
    assert hits / 4000 == pytest.approx(0.7, abs=0.03)
    assert np.mean(counts) == pytest.approx(3.0, abs=0.1)
    assert np.var(counts) == pytest.approx(3.0, rel=0.1)  # Poisson
    assert c[:, 0].min() >= 0 and c[:, 0].max() <= 20_000
    assert np.mean(c[:, 0]) == pytest.approx(10_000, rel=0.02)
    assert np.mean(c[:, 1]) == pytest.approx(0.0, abs=0.05)
    absent = [d.scan(target, False, g)[1] for _ in range(500)]  # a target outside the fov
    assert all(c.all() for c in absent) and sum(c.size for c in absent) > 1000


def test_the_target_is_anywhere_in_a_scan() -> None:
    d = Detection(("range_m", "bearing_rad"), clutter_rate=4.0)
    g = np.random.default_rng(2)
    where = [
        int(np.flatnonzero(~c)[0])
        for Z, c in (d.scan(np.zeros(2), True, g) for _ in range(300))
        if len(c) > 1
    ]
    assert len(set(where)) > 3


def test_scans_leave_the_targets_measurements_as_the_clean_sensors(radar: Setup) -> None:
    cluttered = Setup(radar.cfg.with_(primary_detection={"pd": 0.8, "clutter_rate": 5.0}))
    clean, run = simulate(radar, 3), simulate(cluttered, 3)
    assert np.array_equal(clean.z["primary"], run.z["primary"])
    assert "primary" in run.scans and "s1" not in run.scans
    scans = run.scans["primary"]
    for k, (Z, c) in enumerate(zip(scans.detections, scans.is_clutter, strict=True)):
        if (~c).any():
            assert np.array_equal(Z[~c][0], run.z["primary"][k])


def _cloud(radar: Setup, B: int = 2, N: int = 300) -> np.ndarray:
    g = np.random.default_rng(0)
    x0 = np.asarray(radar.cfg.x0)
    return x0[:, None, None] + np.sqrt(radar.cfg.P0_diag)[:, None, None] * g.standard_normal(
        (len(x0), B, N)
    )


def test_one_detection_without_clutter_weighs_as_the_papers_likelihood(radar: Setup) -> None:
    own = radar.sensors["primary"]
    x = _cloud(radar)
    z = own.model.h(x[:, :, 0]) + np.array([[30.0], [0.01]])
    detection = Detection(own.model.components)
    el = scan_loglik(Scan.pack(own.model, list(z.T[:, None, :]), own.R, detection), x)
    gauss = gaussian_loglik(Observation.broadcast(own.model, z, own.R), x)
    diff = el - gauss  # a constant per run: the Gaussian's normaliser
    assert np.allclose(diff - diff[:, :1], 0.0, atol=1e-9)


def test_the_clouds_gate_drops_only_detections_that_cannot_matter(radar: Setup) -> None:
    own = radar.sensors["primary"]
    x = _cloud(radar, B=1)
    detection = Detection(own.model.components, pd=0.9, clutter_rate=1000.0)
    g = np.random.default_rng(5)
    near = own.model.h(x[:, 0, :5]).T + g.normal(0, 5, (5, 2)) * [1, 1e-3]
    far = np.c_[g.uniform(0, 20_000, 1000), g.uniform(-math.pi, math.pi, 1000)]
    Z = np.vstack([near, far])
    scan = Scan.pack(own.model, [Z], own.R, detection)
    got = scan_loglik(scan, x)[0]
    brute = _brute(own.model, own.R, detection, Z, x[:, 0, :])  # every detection, no gate
    assert np.allclose(got, brute, rtol=1e-9, atol=1e-9)
    # a sensor that does not declare its angles takes the NumPy path, to the same numbers
    undeclared = Scan.pack(_Undeclared(own.model), [Z], own.R, detection)
    assert np.allclose(scan_loglik(undeclared, x)[0], brute, rtol=1e-9, atol=1e-9)


class _Undeclared:
    """A sensor model without its ``angular`` declaration (a plugin may leave it out)."""

    def __init__(self, model: object) -> None:
        self._model = model

    def __getattr__(self, name: str) -> object:
        if name == "angular":
            raise AttributeError(name)
        return getattr(self._model, name)


def _ukf(radar: Setup) -> UnscentedKalmanFilter:
    x0 = np.asarray(radar.cfg.x0)[:, None].repeat(2, axis=1)
    f = UnscentedKalmanFilter(radar.motion, unscented(5, 2.0), x0, np.diag(radar.cfg.P0_diag))
    f.predict()
    return f


def test_pda_of_one_sure_detection_is_the_kalman_update(radar: Setup) -> None:
    own = radar.sensors["primary"]
    a, b = _ukf(radar), _ukf(radar)
    z = own.model.h(a.m) + np.array([[20.0], [0.01]])
    a.update([Observation.broadcast(own.model, z, own.R)])
    b.update([Scan.pack(own.model, list(z.T[:, None, :]), own.R, Detection(own.model.components))])
    assert np.allclose(a.m, b.m, rtol=1e-12) and np.allclose(a.P, b.P, rtol=1e-9)


def test_pda_ignores_false_alarms_outside_the_gate_and_weighs_those_inside(radar: Setup) -> None:
    own = radar.sensors["primary"]
    a, b, c = _ukf(radar), _ukf(radar), _ukf(radar)
    zhat = own.model.h(a.m)
    d = Detection(own.model.components, pd=0.9, clutter_rate=50.0)
    far = zhat.T[:, None, :] + np.array([[[5000.0, 1.0]]])
    target = zhat.T[:, None, :] + np.array([[[5.0, 0.001]]])
    a.update([Scan.pack(own.model, list(target), own.R, d)])
    b.update([Scan.pack(own.model, list(np.concatenate([target, far], axis=1)), own.R, d)])
    assert np.allclose(a.m, b.m) and np.allclose(a.P, b.P)
    assert np.isfinite(a.loglik).all()
    decoy = zhat.T[:, None, :] + np.array([[[-30.0, -0.004]]])
    c.update([Scan.pack(own.model, list(np.concatenate([target, decoy], axis=1)), own.R, d)])
    assert not np.allclose(c.m, a.m)  # a second detection in the gate shares the weight
    assert (np.linalg.eigvalsh(c.P) > 0).all()


def test_an_empty_scan_is_a_prediction(radar: Setup) -> None:
    own = radar.sensors["primary"]
    a, before = _ukf(radar), _ukf(radar)
    scan = Scan.pack(
        own.model, [np.empty((0, 2))] * 2, own.R, Detection(own.model.components, pd=0.5)
    )
    a.update([scan])
    assert np.array_equal(a.m, before.m) and np.array_equal(a.P, before.P)
    assoc = associate(scan, a.predicted_observation(own.model, own.R))
    assert (assoc.beta0 == 1.0).all() and not assoc.any.any()


def test_every_filter_and_role_runs_on_cluttered_scans_with_finite_estimates() -> None:
    det = {"pd": 0.9, "clutter_rate": 10.0}
    cfg = make_config(
        preset="arasaratnam-haykin",
        particles=300,
        K=15,
        primary_detection=det,
        sources=[{"id": "s1", "intensity": 1.0, "detection": {"pd": 0.95, "clutter_rate": 1.0}}],
        recovery=True,
    )
    kinds = ["pf", "rpf", "ukf", "ckf3", "ckf5"]
    roles = ["{}", "tl-{}", "robust-tl-{}", "source-{}"]
    names = [r.format(k) for k in kinds for r in roles] + ["fusion-pf", "fusion-rpf"]
    out = run_batch(cfg, names, range(2))
    assert len(out) == 22
    for name, s in out.items():
        assert np.isfinite(s.sq_err).all(), name
        assert s.nis_count > 0, name


def test_the_cli_sets_each_operators_detection_over_the_config_files(tmp_path) -> None:
    from tltrack.app.common import build_config

    toml = tmp_path / "c.toml"
    toml.write_text("primary_detection = {pd = 0.8, fov = {range_m = [0.0, 5000.0]}}\n")
    cfg = build_config(toml, clutter_rate=3.0, source_pd=0.95)
    assert cfg.primary_detection is not None and cfg.primary_detection.pd == 0.8
    assert cfg.primary_detection.clutter_rate == 3.0
    assert cfg.primary_detection.fov == {"range_m": (0.0, 5000.0)}
    assert all(s.detection is not None and s.detection.pd == 0.95 for s in cfg.sources)


def _brute(sensor, R, detection, Z: np.ndarray, x: np.ndarray) -> np.ndarray:
    """log(lambda (1 - pd(x)) + pd(x) sum_j N(z_j; h(x), R)) over every detection, (N,)."""
    Zx = sensor.h(x)  # (n_z, N)
    nu = sensor.residual(Z.T[:, None, :], Zx[:, :, None])  # (n_z, N, M)
    q = np.einsum("inm,ij,jnm->nm", nu, np.linalg.inv(R), nu)
    g = np.exp(-0.5 * q) / np.sqrt(np.linalg.det(2 * math.pi * R))
    pd = detection.pd_at(Zx)
    return np.log(detection.density * (1 - pd) + pd * g.sum(axis=1))


@pytest.mark.parametrize(
    ("kind", "params", "centre", "spread"),
    [
        ("bearing", {"sigma_bearing": 0.01}, [-4000.0, 10.0], 300.0),  # a cloud across +-pi
        ("range-bearing", {}, [-3000.0, -5.0], 2000.0),  # a cloud round the sensor
        ("range-bearing-doppler", {}, [3000.0, 200.0], 50.0),  # three components
        ("position", {"sigma_pos": 5.0}, [100.0, 100.0], 40.0),
    ],
)
def test_the_grid_finds_every_detection_that_matters(kind, params, centre, spread) -> None:
    cfg = make_config(scenario="cv", primary_sensor={"kind": kind, **params})
    setup = Setup(cfg)
    own = setup.sensors["primary"]
    g = np.random.default_rng(11)
    N = 400
    x = np.zeros((4, 1, N))
    x[0, 0] = centre[0] + spread * g.standard_normal(N)
    x[2, 0] = centre[1] + spread * g.standard_normal(N)
    x[1, 0], x[3, 0] = 30.0, -20.0
    d = Detection(own.model.components, pd=0.8, clutter_rate=500.0)
    bounds = d.bounds
    Z = np.column_stack([g.uniform(*bounds[c], 500) for c in own.model.components])
    hits = (
        own.model.h(x[:, 0, :40]).T
        + g.standard_normal((40, own.model.n_z)) @ np.linalg.cholesky(own.R).T
    )
    Z = np.vstack([Z, own.model.residual(hits.T, np.zeros((own.model.n_z, 1))).T])
    got = scan_loglik(Scan.pack(own.model, [Z], own.R, d), x)[0]
    # each term left out is under exp(-CLOUD_GATE_SIGMAS^2 / 2) of a hit's peak
    peak = d.pd / np.sqrt(np.linalg.det(2 * math.pi * own.R))
    bound = len(Z) * peak * math.exp(-(CLOUD_GATE_SIGMAS**2) / 2)
    assert np.abs(np.exp(got) - np.exp(_brute(own.model, own.R, d, Z, x[:, 0, :]))).max() < bound
    assert np.isfinite(got).all()


def test_the_clutter_example_puts_a_fifth_of_a_false_alarm_in_the_gate() -> None:
    """docs/howto/clutter.md's figure for examples/clutter.toml."""
    from pathlib import Path

    from tltrack.config import load_config

    cfg = load_config(Path(__file__).parents[1] / "examples" / "clutter.toml")
    own = Setup(cfg).sensors["primary"]
    gate = gate_volume(own.R)
    assert own.detection.clutter_rate * gate / own.detection.volume == pytest.approx(0.2, abs=0.01)
    assert own.detection.pd == 0.9
    assert Setup(cfg).sensors["s1"].detection.pd == 0.95
