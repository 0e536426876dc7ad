"""The particle filter's fast path (numba kernels) against straightforward NumPy.

- a reference SIR, written the plain way and kept here, gives the same RMSE within Monte-Carlo error
  on a small coordinated-turn, range-bearing experiment (isolated, source and TL alike);
- the fast CT/CV propagation, range-bearing likelihood and predicted-observation moments equal the
  generic NumPy path on the same random numbers;
- the O(N) systematic resampler picks exactly what cumsum + searchsorted picks;
- the hand-written elementary functions are within a few ulp of NumPy's, and pass NaN through;
- results never depend on the batch size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from numba import njit
from scipy import stats
from tltrack.config import make_config
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.engine.streams import streams
from tltrack.filters.base import Estimate
from tltrack.filters.kernels import fastmath as kernels
from tltrack.filters.likelihood import gaussian_loglik
from tltrack.filters.particle import ParticleFilter
from tltrack.filters.resampling import systematic_indices, systematic_walk
from tltrack.filters.transfer import Primary, Source
from tltrack.models import ConstantVelocity, CoordinatedTurn, Observation, RangeBearing

pytestmark = pytest.mark.unit


class SlowCT(CoordinatedTurn):
    """The same model under another type: the filter takes its generic NumPy path."""


class SlowCV(ConstantVelocity):
    pass


@dataclass(frozen=True)
class SlowRB(RangeBearing):
    pass


# ---------------------------------------------------------------------------------------------
# the reference: a textbook SIR in plain NumPy


class ReferenceSIR:
    """Bootstrap SIR as the seed describes it, written the plain way: noise as Q_sqrt times
    ``standard_normal``, likelihoods through ``sensor.h``/``residual`` (hypot, arctan2, wrapped
    bearing), systematic resampling by cumsum + searchsorted, estimate = resampled mean and
    sample covariance + Q."""

    def __init__(self, model, x0_hat, P0, N, rngs):
        self.model, self.N, self.rngs = model, N, list(rngs)
        n = x0_hat.shape[0]
        eps = np.stack([g.standard_normal((n, N)) for g in self.rngs], axis=1)
        self.x = x0_hat[:, :, None] + np.tensordot(np.linalg.cholesky(P0), eps, axes=1)

    def predict(self):
        L = self.model.Q_sqrt
        eps = np.stack([g.standard_normal((L.shape[1], self.N)) for g in self.rngs], axis=1)
        self.x = self.model.f(self.x) + np.tensordot(L, eps, axes=1)

    def update(self, observations):
        logw = sum(gaussian_loglik(o, self.x) for o in observations)
        w = np.exp(logw - logw.max(axis=1, keepdims=True))
        w /= w.sum(axis=1, keepdims=True)
        cdf = np.cumsum(w, axis=1)
        cdf[:, -1] = 1.0
        idx = np.stack(
            [
                np.searchsorted(cdf[b], (np.arange(self.N) + g.random()) / self.N, side="right")
                for b, g in enumerate(self.rngs)
            ]
        )
        self.x = np.take_along_axis(self.x, np.minimum(idx, self.N - 1)[None], axis=2)

    def estimate(self):
        mean = self.x.mean(axis=2)
        d = self.x - mean[:, :, None]
        return Estimate(mean.T, np.einsum("ibn,jbn->bij", d, d) / self.N + self.model.Q)

    def predicted_observation(self, s, R):
        Z = s.h(self.x)
        eta = s.mean(Z, axis=2)
        d = s.residual(Z, eta[:, :, None])
        return Observation(s, eta, np.einsum("ibn,jbn->bij", d, d) / self.N + R)


def _experiment(make_filter, cfg, runs):
    """Per-run RMSE (over k) of source-pf, pf and tl-pf; ``make_filter(purpose)`` builds one."""
    sims = [simulate(Setup(cfg), r) for r in runs]
    truth = np.stack([s.truth for s in sims], axis=1)  # (K + 1, B, n)
    sid = cfg.sources[0].id
    sp, ss = Setup(cfg).sensor(PRIMARY), Setup(cfg).sensor(sid)
    Rp, Rs = sp.R(Setup(cfg).intensity(PRIMARY)), ss.R(Setup(cfg).intensity(sid))
    src = Source(make_filter("source"), ss, Rs)
    iso, tl = Primary(make_filter("pf")), Primary(make_filter("tl"))
    sq = {"source-pf": [], "pf": [], "tl-pf": []}
    transfer = None
    for k in range(1, cfg.K + 1):
        zp = Observation.broadcast(sp, np.stack([s.z[PRIMARY][k - 1] for s in sims], 1), Rp)
        zs = Observation.broadcast(ss, np.stack([s.z[sid][k - 1] for s in sims], 1), Rs)
        est_s, upcoming = src.step(zs)
        ests = {
            "source-pf": est_s,
            "pf": iso.step(zp),
            "tl-pf": tl.step(zp, [transfer] if transfer is not None else []),
        }
        for name, est in ests.items():
            d = est.mean - truth[k]
            sq[name].append(d[:, 0] ** 2 + d[:, 2] ** 2)
        transfer = upcoming
    return {name: np.sqrt(np.mean(v, axis=0)) for name, v in sq.items()}


def test_fast_path_has_the_reference_rmse_within_monte_carlo_error():
    cfg = make_config(preset="arasaratnam-haykin", truth="noise-free", K=30, particles=1000)
    runs = list(range(24))
    model = Setup(cfg).motion
    x0 = np.stack([simulate(Setup(cfg), r).x0_hat for r in runs], axis=1)
    P0 = np.diag(cfg.P0_diag)

    def fast(purpose):
        return ParticleFilter(model, x0, P0, cfg.particles, streams(1, runs, f"fast/{purpose}"))

    def ref(purpose):
        return ReferenceSIR(model, x0, P0, cfg.particles, streams(2, runs, f"ref/{purpose}"))

    a, b = _experiment(fast, cfg, runs), _experiment(ref, cfg, runs)
    for name in a:
        d = a[name] - b[name]  # paired: same truths and measurements
        se = d.std(ddof=1) / np.sqrt(len(d))
        assert abs(d.mean()) < 4 * se + 0.02 * b[name].mean(), (name, a[name], b[name])
        assert np.all(np.isfinite(a[name]))
    assert a["tl-pf"].mean() < a["pf"].mean()  # the transfer helps, as in the paper


# ---------------------------------------------------------------------------------------------
# fast path == generic path on the same random numbers


def _ct_pair(B=3, N=2001, seed=7):
    cfg = make_config(particles=N)
    fast_model = Setup(cfg).motion
    slow_model = SlowCT(T=cfg.Ts, q1=cfg.q1, q2=cfg.q2)
    x0 = np.repeat(np.asarray(cfg.x0)[:, None], B, 1)
    P0 = np.diag(cfg.P0_diag)
    f = ParticleFilter(fast_model, x0, P0, N, streams(seed, range(B), "x"))
    s = ParticleFilter(slow_model, x0, P0, N, streams(seed, range(B), "x"))
    return cfg, f, s


def test_ct_propagation_equals_the_generic_path():
    _, f, s = _ct_pair()
    assert f._propagate is not None and s._propagate is None  # fast and generic paths
    f.x[4, 1, :5] = [0.0, 1e-7, -3e-6, 2e6, -5e5]  # Taylor branch, and beyond the fast sin/cos
    s.x[4, 1, :5] = f.x[4, 1, :5]
    f.predict()
    s.predict()
    np.testing.assert_allclose(f.x, s.x, rtol=1e-11, atol=1e-9)


def test_cv_propagation_equals_the_generic_path():
    model, slow = ConstantVelocity(T=1.0, q=0.1), SlowCV(T=1.0, q=0.1)
    x0 = np.repeat(np.array([100.0, 10.0, 100.0, 10.0])[:, None], 2, 1)
    P0 = np.diag([50.0, 1.0, 50.0, 1.0])
    f = ParticleFilter(model, x0, P0, 999, streams(3, range(2), "cv"))
    s = ParticleFilter(slow, x0, P0, 999, streams(3, range(2), "cv"))
    assert f._propagate is not None
    for _ in range(3):
        f.predict()
        s.predict()
    np.testing.assert_allclose(f.x, s.x, rtol=1e-12, atol=1e-9)


def test_range_bearing_likelihood_and_moments_equal_the_generic_path():
    cfg, f, _ = _ct_pair()
    f.predict()
    rb = Setup(cfg).sensor()
    slow = SlowRB(rb.sigma_r, rb.sigma_bearing, rb.layout, (150.0, -40.0))
    fast = RangeBearing(rb.sigma_r, rb.sigma_bearing, rb.layout, (150.0, -40.0))
    # bearings near the +-pi cut, a correlated covariance, and one run masked out
    mean = np.array([[1500.0, 1400.0, 1300.0], [3.1, -3.13, 0.4]])
    cov = np.array([[[400.0, 0.05], [0.05, 1e-4]]] * 3)
    mask = np.array([True, False, True])
    f.x[0, 0, :] = -f.x[0, 0, :]  # run 0 sits on the far side, where the bearing wraps
    for m in (None, mask):
        got = f.log_weights([Observation(fast, mean, cov, m)])
        want = gaussian_loglik(Observation(slow, mean, cov, m), f.x)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
    # two statements from one place share a range and a bearing per particle; a third is elsewhere
    mean2 = np.array([[1450.0, 1350.0, 1250.0], [-3.14, 3.135, 0.45]])
    far = RangeBearing(rb.sigma_r, rb.sigma_bearing, rb.layout, (-500.0, 800.0))
    stmts = [
        Observation(fast, mean, cov, mask),
        Observation(fast, mean2, 3 * cov),
        Observation(far, mean2, 2 * cov),
    ]
    got = f.log_weights(stmts)
    want = sum(
        gaussian_loglik(
            Observation(
                SlowRB(
                    o.sensor.sigma_r, o.sensor.sigma_bearing, o.sensor.layout, o.sensor.position
                ),
                o.mean,
                o.cov,
                o.mask,
            ),
            f.x,
        )
        for o in stmts
    )
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
    R = fast.R(2.0)
    got_o, want_o = f.predicted_observation(fast, R), f.predicted_observation(slow, R)
    np.testing.assert_allclose(got_o.mean, want_o.mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got_o.cov, want_o.cov, rtol=1e-9, atol=1e-15)


def test_estimate_from_offspring_counts_is_the_resampled_clouds_moments():
    cfg, f, _ = _ct_pair()
    f.predict()
    z = Observation.broadcast(
        Setup(cfg).sensor(), np.array([1300.0, 0.75]), Setup(cfg).sensor().R(4.0)
    )
    f.update([z])
    est = f.estimate()  # by counts
    x = f.x  # gathered on request
    mean = x.mean(axis=2).T
    d = x - mean.T[:, :, None]
    np.testing.assert_allclose(est.mean, mean, rtol=1e-12)
    np.testing.assert_allclose(
        est.cov, np.einsum("ibn,jbn->bij", d, d) / f.N + f.model.Q, rtol=1e-9, atol=1e-9
    )


def test_reading_x_changes_nothing():
    """x is gathered lazily after update; asking for it must not change any later number."""
    cfg, a, _ = _ct_pair(seed=11)
    _, b, _ = _ct_pair(seed=11)
    s = Setup(cfg).sensor()
    for k in range(4):
        z = Observation.broadcast(s, np.array([1300.0 + 300 * k, 0.75]), s.R(4.0))
        for f in (a, b):
            f.predict()
            f.update([z])
        _ = b.x  # only b is ever looked at
        np.testing.assert_array_equal(a.estimate().mean, b.estimate().mean)
    np.testing.assert_array_equal(a.x, b.x)


# ---------------------------------------------------------------------------------------------
# randomness, determinism, failure


def test_gaussians_are_standard_normal_and_independent():
    _, f, _ = _ct_pair(B=2, N=20_001)
    E = f.gaussians()  # (3, B, N)
    z = E.reshape(-1)
    assert abs(z.mean()) < 0.01 and abs(z.std() - 1.0) < 0.01
    assert stats.kstest(z, "norm").pvalue > 1e-3
    c = np.corrcoef(E.reshape(3, -1))
    assert np.all(np.abs(c - np.eye(3)) < 0.01)
    assert np.all(np.isfinite(z))


@pytest.mark.parametrize("N", [500, 501])
def test_results_do_not_depend_on_the_batch_size(N):
    cfg = make_config(particles=N, K=6)
    model = Setup(cfg).motion
    runs = list(range(7))
    sims = [simulate(Setup(cfg), r) for r in runs]
    s = Setup(cfg).sensor()
    R = s.R(4.0)

    def track(batch):
        out = {}
        for start in range(0, len(runs), batch):
            rs = runs[start : start + batch]
            x0 = np.stack([sims[r].x0_hat for r in rs], axis=1)
            P0 = np.diag(cfg.P0_diag)
            src = Source(ParticleFilter(model, x0, P0, N, streams(5, rs, "src")), s, R)
            tl = Primary(ParticleFilter(model, x0, P0, N, streams(5, rs, "tl")))
            transfer, means = None, []
            for k in range(1, cfg.K + 1):
                zs = np.stack([sims[r].z[PRIMARY][k - 1] for r in rs], axis=1)
                _, up = src.step(Observation.broadcast(s, zs, R))
                est = tl.step(Observation.broadcast(s, zs, R), [transfer] if transfer else [])
                means.append(est.mean)
                transfer = up
            for i, r in enumerate(rs):
                out[r] = np.stack([m[i] for m in means])
        return out

    one, three, seven = track(1), track(3), track(7)
    for r in runs:
        np.testing.assert_array_equal(one[r], three[r])
        np.testing.assert_array_equal(one[r], seven[r])


def test_a_nan_run_is_lost_and_the_others_untouched():
    cfg, a, _ = _ct_pair(B=3, seed=4)
    _, b, _ = _ct_pair(B=3, seed=4)
    s = Setup(cfg).sensor()
    z = Observation.broadcast(s, np.array([1300.0, 0.75]), s.R(4.0))
    a.predict()
    b.predict()
    a.x[2, 1, 17] = np.nan  # one bad particle in run 1
    a.update([z])
    b.update([z])
    ea, eb = a.estimate(), b.estimate()
    assert np.all(np.isnan(ea.mean[1])) and np.all(np.isnan(a.x[:, 1]))
    np.testing.assert_array_equal(ea.mean[[0, 2]], eb.mean[[0, 2]])
    np.testing.assert_array_equal(a.x[:, [0, 2]], b.x[:, [0, 2]])  # the clean runs' clouds too


def test_two_sharp_range_bearing_likelihoods_never_give_nan():
    cfg, f, _ = _ct_pair()
    s = Setup(cfg).sensor()
    far = Observation.broadcast(s, np.array([9e4, -2.0]), np.diag([1e-6, 1e-10]))
    f.predict()
    f.update([far, far])
    assert np.all(np.isfinite(f.estimate().mean))


# ---------------------------------------------------------------------------------------------
# resampling


def test_systematic_walk_picks_what_searchsorted_picks():
    rng = np.random.default_rng(0)
    for t in range(500):
        N = int(rng.integers(1, 400))
        w = rng.random(N) ** rng.integers(1, 40)
        w[rng.random(N) < 0.3] = 0.0
        w[rng.integers(N)] += 1e-3
        u = [0.0, 1.0 - 2.0**-53, rng.random()][t % 3]
        cdf = np.cumsum(w)
        ref = np.searchsorted(cdf, (u + np.arange(N)) * (cdf[-1] / N), side="right")
        idx = np.empty(N + 1, dtype=np.int64)
        assert systematic_walk(w.copy(), u, idx)
        last = np.searchsorted(cdf, cdf[-1], side="left")  # the first j whose cdf is the total
        np.testing.assert_array_equal(idx[:N], np.minimum(ref, last))
        counts = np.bincount(idx[:N], minlength=N)
        assert np.all(np.abs(counts - N * w / w.sum()) < 1.0 + 1e-9)
        assert np.all(counts[w == 0] == 0)


def test_systematic_walk_refuses_non_finite_weights():
    idx = np.empty(4, dtype=np.int64)
    for bad in ([1.0, np.nan, 1.0], [0.0, 0.0, 0.0], [1.0, np.inf, 1.0]):
        assert not systematic_walk(np.array(bad), 0.5, idx)
    with pytest.raises(ValueError, match="positive, finite sum"):
        systematic_indices(np.array([[1.0, np.nan]]), [np.random.default_rng(0)])


# ---------------------------------------------------------------------------------------------
# elementary functions


@njit(cache=False, error_model="numpy")
def _elementary(x, v, y, out):
    for i in range(x.shape[0]):
        out[0, i] = kernels.exp(-abs(x[i]))
        out[1, i] = kernels.log(abs(x[i]) + 1e-300)
        out[2, i], out[3, i] = kernels.sincos(x[i])
        out[4, i], out[5, i] = kernels.sincos_2pi(v[i])
        out[6, i] = kernels.atan2(y[i], x[i])


def _ulp(got, want):
    return np.max(np.abs(got - want) / np.spacing(np.maximum(np.abs(want), 1e-300)))


def test_elementary_functions_are_within_a_few_ulp_of_numpy():
    rng = np.random.default_rng(1)
    n = 20_000
    x = rng.normal(size=n) * 10.0 ** rng.uniform(-8, 2.9, n)
    x[:4] = [0.0, -0.0, 700.0, -707.0]
    v = rng.random(n)
    y = rng.normal(size=n) * 10.0 ** rng.uniform(-8, 4, n)
    out = np.empty((7, n))
    _elementary(x, v, y, out)
    normal = np.abs(x) < 708.3  # below, exp gives 0 where libm gives subnormals
    assert _ulp(out[0][normal], np.exp(-np.abs(x[normal]))) <= 2
    assert np.all(out[0][~normal] == 0.0)
    assert _ulp(out[1], np.log(np.abs(x) + 1e-300)) <= 2
    assert _ulp(out[2], np.sin(x)) <= 2 and _ulp(out[3], np.cos(x)) <= 2
    assert np.max(np.abs(out[4] - np.sin(2 * np.pi * v))) < 1e-15
    assert np.max(np.abs(out[5] - np.cos(2 * np.pi * v))) < 1e-15
    assert _ulp(out[6], np.arctan2(y, x)) <= 2


def test_elementary_functions_pass_nan_and_infinity_through():
    assert math.isnan(kernels.exp(np.nan)) and kernels.exp(-np.inf) == 0.0
    assert kernels.exp(np.inf) == np.inf and kernels.exp(-800.0) == 0.0
    assert all(math.isnan(t) for t in kernels.sincos(np.nan))
    assert all(math.isnan(t) for t in kernels.sincos(np.inf))
    assert math.isnan(kernels.atan2(np.nan, 1.0)) and math.isnan(kernels.atan2(1.0, np.nan))
    assert kernels.atan2(0.0, 0.0) == 0.0
    assert kernels.atan2(1.0, -1.0) == pytest.approx(3 * np.pi / 4, rel=1e-15)


@pytest.mark.parametrize("N", [1, 2, 3, 257])
def test_tiny_and_odd_clouds(N):
    cfg = make_config(particles=10)
    s = Setup(cfg).sensor()
    pf = ParticleFilter(
        Setup(cfg).motion,
        np.asarray(cfg.x0)[:, None],
        np.diag(cfg.P0_diag),
        N,
        streams(0, [0], "tiny"),
    )
    for k in range(3):
        pf.predict()
        obs = pf.predicted_observation(s, s.R(1.0))
        pf.update([Observation.broadcast(s, np.array([1400.0 + 300 * k, 0.1]), s.R(4.0)), obs])
        est = pf.estimate()
        assert np.all(np.isfinite(est.mean)) and pf.x.shape == (5, 1, N)


def test_x_can_be_changed_after_predict_and_replaced_after_update():
    """A recovery redraws lost runs in place after predict; after update x is read-only (the
    estimate was computed from it) and a new cloud is assigned instead."""
    cfg, a, _ = _ct_pair(seed=8)
    s = Setup(cfg).sensor()
    z = Observation.broadcast(s, np.array([1300.0, 0.75]), s.R(4.0))
    a.predict()
    a.x[:, 1, :] = np.asarray(cfg.x0)[:, None] + 1.0
    np.testing.assert_allclose(a.estimate().mean[1], np.asarray(cfg.x0) + 1.0)
    a.update([z])
    a.estimate()
    with pytest.raises(ValueError):
        a.x[:, 1, :] = 0.0
    x = a.x.copy()
    x[:, 1, :] = np.asarray(cfg.x0)[:, None] + 2.0
    a.x = x
    np.testing.assert_allclose(a.estimate().mean[1], np.asarray(cfg.x0) + 2.0)
    a.predict()
    want = CoordinatedTurn(T=cfg.Ts, q1=0.0, q2=0.0).f(np.asarray(cfg.x0) + 2.0)
    assert np.all(np.abs(a.x[:, 1].mean(axis=1) - want)[[0, 2]] < 1.0)
