"""The Stone Soup plugin: reached through Stone Soup's plugin group, its models, the transfer in
Stone Soup's types, and a Stone Soup UKF pipeline that gives tltrack's engine's estimates."""

from __future__ import annotations

import datetime
from pathlib import Path

import numpy as np
import pytest
from stonesoup.predictor.kalman import UnscentedKalmanPredictor
from stonesoup.predictor.particle import ParticlePredictor
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import GaussianState, ParticleState
from stonesoup.updater.kalman import UnscentedKalmanUpdater
from stonesoup.updater.particle import ParticleUpdater
from tltrack.config import make_config
from tltrack.engine.montecarlo import trace_run
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import PRIMARY, Setup, sensor_spec
from tltrack.engine.track import write_estimates
from tltrack.interop.stonesoup import (
    UKF_POINTS,
    Angle,
    Motion,
    Sensor,
    detection,
    from_tracks,
    predicted_observation,
    stacked,
    timestamp,
    to_tracks,
    transfer_message,
    write_csv,
)
from tltrack.wire.messages import Transfer, decode, encode

pytestmark = pytest.mark.unit

CFG = make_config(scenario="ct", preset="arasaratnam-haykin", runs=1)
SETUP = Setup(CFG)
LAYOUT = SETUP.motion.layout


def sensor(sensor_id: str, noise: np.ndarray | None = None) -> Sensor:
    """The config's sensor ``sensor_id`` as a Stone Soup model."""
    return Sensor(
        spec=sensor_spec(CFG, sensor_id),
        ndim_state=CFG.n_x,
        mapping=LAYOUT.pos,
        velocity_mapping=LAYOUT.vel,
        noise_covar=SETUP.sensors[sensor_id].R if noise is None else noise,
    )


def test_the_plugin_is_reached_through_stone_soups_plugin_group() -> None:
    from stonesoup.plugins import tltrack as plugin

    assert plugin.Sensor is Sensor
    assert plugin.__name__ == "tltrack.interop.stonesoup"


def test_a_sensor_is_tltracks_sensor_with_typed_angles() -> None:
    s = sensor(PRIMARY)
    x = np.array([[1000.0, -1000.0], [0.0, 0.0], [1000.0, -1.0], [0.0, 0.0], [0.0, 0.0]])
    z = s.function(GaussianState(StateVectors(x), np.eye(5)))
    np.testing.assert_allclose(np.asarray(z, dtype=float), SETUP.sensor(PRIMARY).h(x))
    assert isinstance(z[1, 0], Angle) and not isinstance(z[0, 0], Angle)
    # its likelihood is tltrack's, the bearing's residual wrapped across the cut at +-pi
    near_cut = Detection(StateVector([1000.0, np.pi - 1e-4]), measurement_model=s)
    r, b = np.hypot(-1000.0, -1.0), np.arctan2(-1.0, -1000.0)  # just past -pi
    d = np.array([1000.0 - r, (np.pi - 1e-4 - b + np.pi) % (2 * np.pi) - np.pi])
    R = np.asarray(s.covar(), dtype=float)
    want = -0.5 * (d @ np.linalg.solve(R, d) + np.log(np.linalg.det(2 * np.pi * R)))
    assert abs(d[1]) < 2e-3
    got = s.logpdf(near_cut, GaussianState(StateVector(x[:, 1]), np.eye(5)))
    assert got == pytest.approx(want, rel=1e-12)


def test_angles_average_about_the_first_across_the_cut() -> None:
    a = [np.pi - 0.1, -np.pi + 0.1, np.pi - 0.05]
    assert float(Angle.average(a, weights=[0.5, 0.25, 0.25])) == pytest.approx(
        np.pi - 0.1 + 0.25 * 0.2 + 0.25 * 0.05
    )


def test_a_motion_model_runs_over_any_interval() -> None:
    m = Motion(model=SETUP.motion)
    x = GaussianState(StateVector(CFG.x0), np.eye(5))
    two = datetime.timedelta(seconds=2.0)
    np.testing.assert_array_equal(
        np.asarray(m.function(x, time_interval=two), dtype=float)[:, 0],
        SETUP.motion.with_period(2.0).f(np.asarray(CFG.x0)),
    )
    np.testing.assert_array_equal(m.covar(time_interval=two), SETUP.motion.with_period(2.0).Q)


def test_a_motion_model_refuses_to_predict_backwards_or_without_a_time() -> None:
    """Backwards, CT's noise was NaN in both filters' covariance; with no timestamp, an
    AttributeError."""
    m = Motion(model=SETUP.motion)
    x = GaussianState(StateVector(CFG.x0), np.eye(5))
    for bad in (datetime.timedelta(seconds=-5.0), None):
        with pytest.raises(ValueError, match="predicts forward in time"):
            m.covar(time_interval=bad)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="predicts forward in time"):
            m.function(x, time_interval=bad)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("noise", "says"),
    [
        (np.diag([-500.0, -1.0]), "positive-definite"),  # went out as near certainty (1e-9)
        (np.full((2, 2), np.nan), "finite 2 x 2"),
        (np.eye(3), "finite 2 x 2"),
    ],
    ids=["negative", "nan", "3x3"],
)
def test_a_sensor_refuses_a_noise_covariance_that_is_none(noise: np.ndarray, says: str) -> None:
    with pytest.raises(ValueError, match=says):
        sensor("s1", noise)


def test_a_sensor_refuses_a_state_layout_it_cannot_read() -> None:
    """Stone Soup's [x, y, vx, vy] with mapping (0, 1) took (1, 2) as the velocity: a Doppler
    sensor read y as vx, silently; (0,) or (0, 7) raised IndexError at the first update."""
    doppler = {"kind": "range-bearing-doppler", "sigma_r": 10.0, "sigma_bearing": 1e-3}
    for mapping, says in (((0,), "mapping: two distinct"), ((0, 7), "mapping: two distinct")):
        with pytest.raises(ValueError, match=says):
            Sensor(spec=doppler, ndim_state=4, mapping=mapping)
    with pytest.raises(ValueError, match=r"velocity_mapping \(1, 2\) overlaps"):
        Sensor(spec=doppler, ndim_state=4, mapping=(0, 1))
    assert (
        Sensor(spec=doppler, ndim_state=4, mapping=(0, 1), velocity_mapping=(2, 3)).ndim_meas == 3
    )
    radar = {"kind": "range-bearing", "sigma_r": 10.0, "sigma_bearing": 1e-3}
    assert Sensor(spec=radar, ndim_state=4, mapping=(0, 1)).ndim_meas == 2  # reads no velocity


@pytest.mark.filterwarnings("ignore::UserWarning", "ignore::RuntimeWarning")  # Stone Soup's own
def test_a_broken_prediction_sends_no_transfer() -> None:
    """Its covariance floored for the wire, a NaN or negative one went out as near certainty."""
    prediction = GaussianState(StateVector(CFG.x0), CovarianceMatrix(-np.diag(CFG.P0_diag)))
    with pytest.raises(ValueError, match="covariance is broken"):
        transfer_message(prediction, sensor("s1"), episode="e1", source="s1", k=4, t_sensor=12.5)


def test_a_transfer_goes_out_and_comes_back_as_a_detection() -> None:
    s = sensor("s1")
    prediction = GaussianState(StateVector(CFG.x0), CovarianceMatrix(np.diag(CFG.P0_diag)))
    msg = transfer_message(prediction, s, episode="e1", source="s1", k=4, t_sensor=12.5)
    back = decode(encode(msg), Transfer)
    assert (back.k_apply, back.sender, back.sensor) == (5, "s1", s.spec)
    det = detection(back, ndim_state=5, mapping=LAYOUT.pos, velocity_mapping=LAYOUT.vel)
    assert (det.k_apply, det.source, det.timestamp) == (5, "s1", timestamp(12.5))
    steps = (timestamp(100.0), datetime.timedelta(seconds=2.0))  # the primary's step grid
    dated = detection(back, ndim_state=5, mapping=LAYOUT.pos, steps=steps)
    assert dated.timestamp == timestamp(110.0)  # its step 5, whatever the source's clock said
    off_clock = back.model_copy(update={"k": 7, "t_apply": 10.0})  # k_apply: the primary's sample
    dated = detection(off_clock, ndim_state=5, mapping=LAYOUT.pos, steps=steps)
    assert dated.timestamp == timestamp(110.0)  # was a ValueError: t_apply needed `when`
    skewed = back.model_copy(update={"P_eta": [[1e4, 0.010001], [0.01, 1e-5]]})  # the wire's
    assert decode(encode(skewed), Transfer) == skewed  # tolerance takes it, and so does a Sensor
    detection(skewed, ndim_state=5, mapping=LAYOUT.pos)
    np.testing.assert_allclose(np.asarray(det.state_vector, dtype=float)[:, 0], back.eta)
    np.testing.assert_allclose(det.measurement_model.covar(), back.P_eta)
    assert det.measurement_model.spec == s.spec


def test_a_stacked_detection_is_the_product_of_its_likelihoods() -> None:
    own = Detection(StateVector([1400.0, 0.8]), measurement_model=sensor(PRIMARY))
    eta = Detection(StateVector([1410.0, 0.79]), measurement_model=sensor("s1", np.diag([9, 1e-4])))
    with pytest.raises(ValueError, match=r"detection\(s\) \[1\] have no measurement model"):
        stacked([own, Detection(StateVector([1410.0, 0.79]))])  # an AttributeError's traceback
    both = stacked([own, eta])
    x = GaussianState(StateVector(CFG.x0), np.eye(5))
    total = both.measurement_model.logpdf(both, x)
    parts = own.measurement_model.logpdf(own, x) + eta.measurement_model.logpdf(eta, x)
    assert total == pytest.approx(parts, rel=1e-12)


def test_a_particle_transfer_is_the_clouds_moments() -> None:
    """eta_hat and P_eta_eta of an equally weighted cloud: tltrack's particle source's (circular
    mean, wrapped deviations over N) to the particles' own spread."""
    rng = np.random.default_rng(3)
    s = sensor("s1")
    cloud = np.asarray(CFG.x0)[:, None] + rng.normal(0.0, 5.0, (5, 2000)) * [
        [1],
        [0.1],
        [1],
        [0.1],
        [0],
    ]
    prediction = ParticleState(StateVectors(cloud), log_weight=np.full(2000, -np.log(2000)))
    eta, P = predicted_observation(prediction, s)
    Z = SETUP.sensor("s1").h(cloud)
    want = SETUP.sensor("s1").mean(Z, axis=1)
    d = SETUP.sensor("s1").residual(Z, want[:, None])
    np.testing.assert_allclose(eta, want, rtol=1e-9)
    np.testing.assert_allclose(P, d @ d.T / 2000 + SETUP.sensors["s1"].R, rtol=1e-6)


def test_estimates_become_stone_soup_tracks_and_tltracks_csv(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    rows = [(k, n, rng.normal(size=5), np.eye(5) * k) for k in (1, 2, 3) for n in ("ukf", "tl-ukf")]
    start, period = datetime.datetime(2026, 1, 1), datetime.timedelta(seconds=5)
    tracks = to_tracks(rows, start=start, period=period)
    assert set(tracks) == {"ukf", "tl-ukf"} and len(tracks["ukf"]) == 3
    assert tracks["ukf"][-1].timestamp == start + 3 * period
    write_csv(tmp_path / "ss.csv", tracks, scenario="ct", start=start, period=period)
    write_estimates(tmp_path / "tl.csv", "ct", sorted(rows, key=lambda r: (r[0], r[1])))
    assert (tmp_path / "ss.csv").read_text() == (tmp_path / "tl.csv").read_text()
    from stonesoup.types.state import State
    from stonesoup.types.track import Track

    x = StateVector(np.zeros(5))
    for bad, says in (
        ([State(x, timestamp=start + period)], "a time and a covariance"),  # AttributeError
        ([GaussianState(x, np.eye(5))], "a time and a covariance"),  # TypeError
        # 0.6 and 1.4 periods were both step 1: duplicate rows
        ([GaussianState(x, np.eye(5), timestamp=start + period * 0.6)], "whole number of periods"),
        ([GaussianState(x, np.eye(5), timestamp=start + period)] * 2, "a second state at step 1"),
    ):
        with pytest.raises(ValueError, match=says):
            write_csv(tmp_path / "x.csv", {"ukf": Track(bad)}, scenario="ct", start=start,
                      period=period)  # fmt: skip
    thirtieth = datetime.timedelta(seconds=1 / 30)  # 33333 us: k periods drift off k / 30 s
    frames = Track(
        [
            GaussianState(x, np.eye(5), timestamp=start + datetime.timedelta(seconds=k / 30))
            for k in range(200)
        ]
    )
    read = from_tracks({"ukf": frames}, start=start, period=thirtieth)
    assert [k for k, *_ in read] == list(range(200))


def test_a_stone_soup_ukf_pipeline_gives_the_engines_estimates() -> None:
    """Scenario 2 (CT, range-bearing): the source UKF, the isolated UKF and the TL-UKF, in Stone
    Soup's predictor and updater with the plugin's models and transfer, agree with tltrack's
    engine at every step to 1e-9 relative."""
    engine = trace_run(CFG, ["source-ukf", "ukf", "tl-ukf"], run=0)
    sim = simulate(SETUP, 0)
    own, src_sensor = sensor(PRIMARY), sensor("s1")
    predictor = UnscentedKalmanPredictor(Motion(model=SETUP.motion), **UKF_POINTS)
    updater = UnscentedKalmanUpdater(None, **UKF_POINTS)
    T, t0 = datetime.timedelta(seconds=SETUP.motion.T), timestamp(0.0)
    x0 = GaussianState(
        StateVector(sim.x0_hat), CovarianceMatrix(np.diag(CFG.P0_diag)), timestamp=t0
    )
    state = {"source-ukf": x0, "ukf": x0, "tl-ukf": x0}
    got: dict[str, list[np.ndarray]] = {name: [] for name in state}
    sent: Transfer | None = None
    for k in range(1, CFG.K + 1):
        t = t0 + k * T
        z = Detection(StateVector(sim.z[PRIMARY][k - 1]), timestamp=t, measurement_model=own)
        zs = Detection(StateVector(sim.z["s1"][k - 1]), timestamp=t, measurement_model=src_sensor)
        with_transfer = z
        if sent is not None:  # the source's transfer for step k, as a primary receives it
            back = decode(encode(sent), Transfer)
            eta = detection(back, ndim_state=5, mapping=LAYOUT.pos, steps=(t0, T))
            assert eta.timestamp == t  # dated at the step it is for, not the source's k - 1
            with_transfer = stacked([z, eta])
        for name, d in (("source-ukf", zs), ("ukf", z), ("tl-ukf", with_transfer)):
            prediction = predictor.predict(state[name], timestamp=t)
            state[name] = updater.update(SingleHypothesis(prediction, d))
            got[name].append(np.asarray(state[name].state_vector, dtype=float)[:, 0])
        ahead = predictor.predict(state["source-ukf"], timestamp=t + T)
        sent = transfer_message(ahead, src_sensor, episode="e", source="s1", k=k, t_sensor=k)
    for name, estimates in got.items():
        np.testing.assert_allclose(np.array(estimates), engine[name], rtol=1e-9, atol=1e-9)


def test_a_stone_soup_particle_filter_takes_a_transfer() -> None:
    """Stone Soup's own particle updater conditions on [z; eta] through the stacked model: the
    transfer from a sharper source pulls the cloud's spread below the isolated one's."""
    rng = np.random.default_rng(1)
    sim = simulate(SETUP, 0)
    N = 500
    cloud = sim.x0_hat[:, None] + np.sqrt(np.asarray(CFG.P0_diag))[:, None] * rng.standard_normal(
        (5, N)
    )
    prior = ParticleState(
        StateVectors(cloud), log_weight=np.full(N, -np.log(N)), timestamp=timestamp(0)
    )
    predictor = ParticlePredictor(Motion(model=SETUP.motion))
    t = timestamp(float(SETUP.motion.T))
    prediction = predictor.predict(prior, timestamp=t)
    z = Detection(StateVector(sim.z[PRIMARY][0]), timestamp=t, measurement_model=sensor(PRIMARY))
    sent = transfer_message(prediction, sensor("s1"), episode="e", source="s1", k=0, t_sensor=0)
    eta = detection(sent, ndim_state=5, mapping=LAYOUT.pos)
    updater = ParticleUpdater(None)
    alone = updater.update(SingleHypothesis(prediction, z))
    helped = updater.update(SingleHypothesis(prediction, stacked([z, eta], when=t)))
    assert np.trace(helped.covar[:4:2, :4:2]) < np.trace(alone.covar[:4:2, :4:2])


def test_a_sensor_takes_its_description_as_a_config_gives_it_and_names_a_bad_one() -> None:
    radar = {"kind": "range-bearing", "position": [10.0, 0.0], "sigma_r": 5.0}
    with pytest.raises(ValueError, match=r"a range-bearing sensor needs sigma_bearing \[rad\]"):
        Sensor(spec=radar, ndim_state=4, mapping=(0, 2))
    full = Sensor(spec={**radar, "sigma_bearing": 0.01}, ndim_state=4, mapping=(0, 2))
    assert full.spec.params == {"sigma_r": 5.0, "sigma_bearing": 0.01}
    np.testing.assert_allclose(full.covar(), np.diag([25.0, 1e-4]))
    with pytest.raises(ValueError, match="sigma_x is not a parameter of a range-bearing sensor"):
        Sensor(spec={**radar, "sigma_x": 1.0}, ndim_state=4, mapping=(0, 2))


def test_stone_soups_extended_updater_and_associator_take_a_transfer() -> None:
    """The extended Kalman updater linearises the stacked model with tltrack's Jacobians, and a
    distance hypothesiser with a nearest-neighbour associator picks the transfer out of a set of
    detections, as it would any detection."""
    from stonesoup.dataassociator.neighbour import NearestNeighbour
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.measures import Mahalanobis
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    t0, t1 = timestamp(0.0), timestamp(1.0)
    prior = GaussianState(StateVector(CFG.x0), CovarianceMatrix(np.diag(CFG.P0_diag)), timestamp=t0)
    predictor = ExtendedKalmanPredictor(Motion(model=SETUP.motion))
    prediction = predictor.predict(prior, timestamp=t1)
    sent = transfer_message(prediction, sensor("s1"), episode="e", source="s1", k=0, t_sensor=0)
    eta = detection(sent, ndim_state=5, mapping=LAYOUT.pos, when=t1)
    far = Detection(StateVector([eta.state_vector[0, 0] + 5000.0, 0.1]), t1, sensor("s1"))

    updater = ExtendedKalmanUpdater(None)
    x = np.asarray(prediction.state_vector, dtype=float)[:, 0]
    z = Detection(StateVector(SETUP.sensor(PRIMARY).h(x)), t1, sensor(PRIMARY))
    alone = updater.update(SingleHypothesis(prediction, z))
    helped = updater.update(SingleHypothesis(prediction, stacked([z, eta])))
    assert np.trace(helped.covar[:4:2, :4:2]) < np.trace(alone.covar[:4:2, :4:2])

    track = Track([prior])
    hypothesiser = DistanceHypothesiser(predictor, updater, Mahalanobis(), missed_distance=30)
    chosen = NearestNeighbour(hypothesiser).associate({track}, {far, eta}, t1)[track]
    assert chosen.measurement is eta
