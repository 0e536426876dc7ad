"""The auxiliary particle filter (``rpf``): exact weights, the Kalman limit, and the track kept
where the bootstrap filter loses it."""

from __future__ import annotations

import numpy as np
import pytest
from doubles import PositionSensor, cv_model, kalman
from tltrack.config import ConfigError, make_config
from tltrack.engine.montecarlo import run_batch, run_experiment
from tltrack.engine.streams import streams
from tltrack.filters.auxiliary import AuxiliaryParticleFilter
from tltrack.filters.auxiliary import _weighted_moments as _moments
from tltrack.models import ConstantVelocity, Observation

pytestmark = pytest.mark.unit

X0 = np.array([100.0, 10.0, 100.0, 10.0])
P0 = np.diag([50.0, 1.0, 50.0, 1.0])


def _zs(steps: int, seed: int = 5) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    model, x, zs = cv_model(), X0.copy(), []
    for _ in range(steps):
        x = model.A @ x + model.Q_sqrt @ rng.standard_normal(2)
        zs.append(model.layout.position(x) + rng.normal(0, 5.0, 2))
    return zs


@pytest.mark.parametrize("fast", [True, False])
def test_on_a_linear_gaussian_model_it_approaches_the_kalman_filter_as_n_grows(fast: bool) -> None:
    """CV with position fixes: the posterior is Gaussian, the KF exact. The error of the rpf's
    mean and covariance, over 8 runs, shrinks as N grows (fast path and generic path alike)."""
    model, sensor = cv_model(), PositionSensor(sigma=5.0)
    if not fast:  # the same model under a type the fast path does not list
        model = type("SlowCV", (ConstantVelocity,), {})(T=1.0, q=0.1)
    zs, R = _zs(10), sensor.R(1.0)
    m_kf, P_kf = kalman(model, sensor, X0, P0, [[z] for z in zs], [[R]] * 10)[-1]
    errors = []
    for N in (300, 3000, 30000):
        B = 8
        apf = AuxiliaryParticleFilter(
            model, np.repeat(X0[:, None], B, 1), P0, N, streams(1, range(B), "a")
        )
        for z in zs:
            apf.predict()
            apf.update([Observation.broadcast(sensor, np.repeat(z[:, None], B, 1), R)])
        est = apf.estimate()
        cov = est.cov - model.Q  # the filter reports the posterior's spread plus Q_v
        errors.append(
            (np.abs(est.mean - m_kf).mean(), np.abs(cov - P_kf).mean() / np.abs(P_kf).mean())
        )
    mean_err, cov_err = zip(*errors, strict=True)
    assert mean_err[2] < mean_err[0] / 3 and cov_err[2] < cov_err[0] / 3, errors
    assert mean_err[2] < 0.1 and cov_err[2] < 0.05, errors


def test_where_the_proposal_is_exact_the_incremental_weights_are_equal() -> None:
    """No process noise and beta = 1: the look-ahead l_k(f(x_{k-1})) is l_k(x_k) itself, so the
    second stage divides every particle's likelihood by itself: equal weights, exactly."""
    model, sensor = ConstantVelocity(T=1.0, q=0.0), PositionSensor(sigma=5.0)
    apf = AuxiliaryParticleFilter(model, X0[:, None], P0, 500, streams(2, [0], "a"), beta=1.0)
    for z in _zs(5):
        apf.predict()
        apf.update([Observation.broadcast(sensor, z, sensor.R(1.0))])
        np.testing.assert_allclose(apf._logw, -np.log(500), rtol=0, atol=1e-12)


def test_the_same_seed_gives_the_same_result_whatever_the_batch_size() -> None:
    cfg = make_config(preset="paper", particles=300, K=30, runs=3)
    names = ["rpf", "tl-rpf", "robust-tl-rpf", "fusion-rpf"]
    together = run_batch(cfg, names, [0, 1, 2], keep_tracks=True)
    alone = [run_batch(cfg, names, [r], keep_tracks=True) for r in range(3)]
    for name in together:  # each run's every estimate: exactly, but where batched BLAS in the
        for r in range(3):  # robust policy may round the last bit differently per batch shape
            got, want = together[name].tracks[0][:, r], alone[r][name].tracks[0][:, 0]
            rtol = 1e-12 if name.startswith("robust") else 0.0
            np.testing.assert_allclose(got, want, rtol=rtol, atol=0, err_msg=name)


def test_a_sharp_likelihood_the_bootstrap_filter_loses_and_the_rpf_keeps() -> None:
    """The paper's own parameters, N = 2000: the bootstrap source loses runs; the auxiliary
    filter, on the same data and random numbers, keeps every track within 100 m to the end."""
    cfg = make_config(preset="paper", truth="fixed", particles=2000, runs=10, seed=3)
    res = run_experiment(cfg, ["tl-pf", "tl-rpf"], workers=1, time_steps=False)
    assert res["source-pf"].lost_fraction >= 0.1, res["source-pf"]
    for name in ("source-rpf", "tl-rpf"):
        assert res[name].lost_fraction == 0.0, (name, res[name])
    assert res["tl-rpf"].rmse_overall < 25.0, res["tl-rpf"]


def test_robust_tl_rpf_fed_by_a_source_pf_that_diverges_by_itself() -> None:
    """A bootstrap source under the paper's parameters loses its own track in some runs; the
    robust primary hears it out, keeps its own track and is no worse than the isolated rpf."""
    cfg = make_config(
        preset="paper", truth="fixed", particles=2000, runs=10, seed=3,
        sources=[{"id": "s1", "filter": "pf"}],
    )  # fmt: skip
    res = run_experiment(cfg, ["rpf", "robust-tl-rpf"], workers=1, time_steps=False)
    assert res["source-pf"].lost_fraction >= 0.1, res["source-pf"]
    assert res["robust-tl-rpf"].lost_fraction == 0.0
    d = np.asarray(res["robust-tl-rpf"].run_rmse) - np.asarray(res["rpf"].run_rmse)
    assert d.mean() < 2 * d.std(ddof=1) / np.sqrt(len(d)) + 1e-9, d


def test_a_bad_source_filter_is_refused_naming_the_field() -> None:
    with pytest.raises(ConfigError, match=r"sources\.0\.filter"):
        make_config(sources=[{"id": "s1", "filter": "sir"}])


def test_regularisation_keeps_the_clouds_weighted_mean_and_covariance() -> None:
    """The Liu-West kernel shrinks each particle towards the mean as much as its jitter spreads
    it: the redrawn cloud has the weighted cloud's first two moments (up to Monte-Carlo error),
    and every particle is new."""
    model, N = cv_model(), 40_000
    apf = AuxiliaryParticleFilter(model, X0[:, None], P0, N, streams(4, [0], "a"), bandwidth=0.5)
    apf._logw[0] = np.log(np.random.default_rng(0).uniform(0.1, 1.0, N))  # unequal weights
    apf._logw[0] -= np.log(np.exp(apf._logw[0]).sum())
    x, w = apf._x, apf._weights()
    mean, cov = (v[0] for v in _moments(x, w))
    new = apf._regularise(x, np.array([True]))
    mean2, cov2 = (v[0] for v in _moments(new, w))
    sd = np.sqrt(np.diag(cov))
    shift_sd = 0.5 * sd * np.sqrt((w[0] ** 2).sum())  # h D times the weighted mean of N(0, I)
    assert np.all(np.abs(mean2 - mean) < 5 * shift_sd), (mean, mean2)
    assert np.all(np.abs(cov2 - cov) < 0.05 * np.outer(sd, sd)), (cov, cov2)
    assert not np.any(new == x) and apf.regularised.tolist() == [1]


def test_a_step_that_does_not_regularise_changes_no_number() -> None:
    """The kernel draws from its own stream, and only when it fires: a filter that never fires
    (ess_min = 0) gives the unregularised filter's numbers exactly."""
    model, sensor = cv_model(), PositionSensor(sigma=5.0)
    plain = AuxiliaryParticleFilter(model, X0[:, None], P0, 500, streams(2, [0], "a"))
    idle = AuxiliaryParticleFilter(
        model, X0[:, None], P0, 500, streams(2, [0], "a"), bandwidth=0.3, ess_min=0.0
    )
    for z in _zs(8):
        for f in (plain, idle):
            f.predict()
            f.update([Observation.broadcast(sensor, z, sensor.R(1.0))])
        np.testing.assert_array_equal(plain.x, idle.x)
    assert idle.regularised.tolist() == [0]


def test_regularisation_keeps_a_track_the_unregularised_rpf_loses() -> None:
    """arasaratnam-haykin, random truth, run 1273 of seed 0 (the 10,000-run table's second
    worst rpf run): the cloud's genealogy collapses to metres while the posterior spreads over
    tens of metres, and the rpf drifts off for good; with the kernel (h = 0.2) it keeps the
    track, on the same data and the same look-ahead numbers."""
    out = {}
    for h in (0.0, 0.2):
        cfg = make_config(
            scenario="ct", preset="arasaratnam-haykin", truth="random", particles=6000,
            primary_intensity=4, seed=0, rpf_bandwidth=h,
        )  # fmt: skip
        out[h] = float(np.sqrt(run_batch(cfg, ["rpf"], [1273])["rpf"].run_mse[0][0]))
    assert out[0.0] > 300 and out[0.2] < 50, out


@pytest.mark.parametrize("h", [-0.1, 1.0, float("nan")])
def test_a_bad_bandwidth_is_refused_naming_the_field(h: float) -> None:
    with pytest.raises(ConfigError, match="rpf_bandwidth"):
        make_config(rpf_bandwidth=h)
