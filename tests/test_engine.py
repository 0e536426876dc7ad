import json

import numpy as np
import pytest
from tltrack.config import load_config, make_config
from tltrack.engine import results
from tltrack.engine.montecarlo import nees, run_experiment, run_sweep, trace_run
from tltrack.engine.scenario import simulate, truth
from tltrack.engine.setup import Setup
from tltrack.filters.kernels.moments import spread_coordinates

pytestmark = pytest.mark.unit

FILTERS = ["pf", "tl-pf", "ukf", "tl-ckf5", "fusion-pf"]


def _cfg(**kw):
    return make_config(
        {"preset": "arasaratnam-haykin", "K": 15, "particles": 200, "runs": 7, "seed": 4, **kw}
    )


def test_same_seed_same_result_whatever_the_batch_size_or_worker_count():
    """Batched BLAS may round the last bit differently for another batch shape; nothing more."""
    cfg = _cfg()
    base = run_experiment(cfg, FILTERS, batch_size=7, workers=1, time_steps=False)
    for bs, workers in ((1, 1), (3, 2)):
        other = run_experiment(cfg, FILTERS, batch_size=bs, workers=workers, time_steps=False)
        for name in base:
            np.testing.assert_allclose(base[name].run_rmse, other[name].run_rmse, rtol=1e-9)
            np.testing.assert_allclose(
                base[name].rmse_per_step, other[name].rmse_per_step, rtol=1e-9
            )


def test_overall_rmse_is_the_papers_mean_of_per_step_rmse():
    cfg = _cfg()
    res = run_experiment(cfg, ["pf"], workers=1, time_steps=False)["pf"]
    per_run = {r: trace_run(cfg, ["pf"], r)["pf"] for r in range(cfg.runs)}
    sq = np.array(
        [
            [
                np.sum((per_run[r][k, [0, 2]] - truth(Setup(cfg), r)[k + 1, [0, 2]]) ** 2)
                for k in range(cfg.K)
            ]
            for r in range(cfg.runs)
        ]
    )
    np.testing.assert_allclose(res.rmse_per_step, np.sqrt(sq.mean(axis=0)), rtol=1e-12)
    assert res.rmse_overall == pytest.approx(np.mean(np.sqrt(sq.mean(axis=0))))


@pytest.mark.parametrize("mode", ["fixed", "random", "noise-free"])
def test_truth_modes(mode):
    cfg = _cfg(truth=mode)
    a, b = truth(Setup(cfg), 0), truth(Setup(cfg), 1)
    assert np.array_equal(a, b) == (mode != "random")
    if mode == "noise-free":
        assert a[:, 4].std() == 0.0  # the turn rate never changes
    assert not np.array_equal(
        simulate(Setup(cfg), 0).z["primary"], simulate(Setup(cfg), 1).z["primary"]
    )


def test_transfer_helps_and_fusion_helps_more():
    cfg = make_config(
        preset="arasaratnam-haykin", truth="noise-free", particles=1000, runs=16, K=40, seed=2
    )
    res = run_experiment(cfg, ["pf", "tl-pf", "fusion-pf"], time_steps=False)
    assert res["tl-pf"].rmse_overall < res["pf"].rmse_overall
    assert res["fusion-pf"].rmse_overall < res["pf"].rmse_overall


def test_results_document_has_the_contract_fields(tmp_path):
    cfg = _cfg(runs=3)
    doc = results.assemble(cfg, run_experiment(cfg, ["pf", "tl-pf"], workers=1))
    path = results.write(doc, tmp_path)
    back = json.loads(path.read_text())
    assert back["schema_version"] == results.SCHEMA_VERSION
    assert {"package_version", "git_commit", "numpy_version", "machine"} <= back[
        "provenance"
    ].keys()
    assert set(back["filters"]) == {"pf", "tl-pf", "source-pf"}
    for r in back["filters"].values():
        assert len(r["rmse_per_step"]) == cfg.K
        assert {"rmse_overall", "ms_per_step", "lost_fraction", "nees"} <= r.keys()
        assert r["ms_per_step"] > 0
    assert len(back["pcrlb"]["primary"]) == len(back["pcrlb"]["with_source"]) == cfg.K
    assert all(
        w <= p for w, p in zip(back["pcrlb"]["with_source"], back["pcrlb"]["primary"], strict=True)
    )


def test_lost_fraction_counts_runs_far_off_at_the_end():
    cfg = _cfg(lost_threshold_m=1e-3)
    assert run_experiment(cfg, ["pf"], workers=1, time_steps=False)["pf"].lost_fraction == 1.0
    cfg = _cfg(lost_threshold_m=1e6)
    assert run_experiment(cfg, ["pf"], workers=1, time_steps=False)["pf"].lost_fraction == 0.0


def test_a_sweep_over_the_primary_intensity_equals_separate_experiments():
    """The sources run once for the whole sweep; every configuration's numbers are unchanged."""
    cfgs = [_cfg(primary_intensity=i) for i in (1, 4, 8)]
    names = ["pf", "tl-pf", "tl-ukf", "fusion-pf"]
    swept = run_sweep(cfgs, names, batch_size=4, workers=1, time_steps=False)
    for cfg, res in zip(cfgs, swept, strict=True):
        alone = run_experiment(cfg, names, batch_size=4, workers=1, time_steps=False)
        assert res.keys() == alone.keys()
        for name in alone:
            assert res[name].run_rmse == alone[name].run_rmse, name
            assert res[name].transfer_rate == alone[name].transfer_rate, name
    assert swept[0]["pf"].run_rmse != swept[2]["pf"].run_rmse  # the intensity did change


def test_a_sweep_refuses_configurations_that_differ_beyond_the_primary():
    with pytest.raises(ValueError, match="particles"):
        run_sweep([_cfg(), _cfg(particles=300)], ["tl-pf"], workers=1)


def test_nees_of_a_collapsed_cloud_is_that_of_its_spread_not_rounding_noise():
    """A regular P: exactly the solve's d' P^-1 d. A P of rank 3 (a collapsed cloud's) plus
    rounding noise: the NEES of the three coordinates with spread, the same whatever that noise
    (a solve returned values up to 1e46 of either sign). Not finite: NaN."""
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 5, 5))
    regular = A @ A.transpose(0, 2, 1) + np.eye(5)
    d = rng.normal(size=(3, 5))
    solved = np.einsum("bi,bi->b", d, np.linalg.solve(regular, d[:, :, None])[:, :, 0])
    eps, singular = nees(d, regular)
    assert np.array_equal(eps, solved) and not singular.any()

    G = rng.normal(size=(5, 3))
    rank3 = G @ G.T
    noisy = rank3 + 1e-15 * rng.normal(size=(4, 5, 5))
    noisy = (noisy + noisy.transpose(0, 2, 1)) / 2
    e = np.tile(rng.normal(size=5), (4, 1))
    kept = spread_coordinates(noisy, 1e-10)
    assert (kept == kept[0]).all() and kept[0].sum() == 3
    S = np.flatnonzero(kept[0])
    expected = e[0, S] @ np.linalg.solve(rank3[np.ix_(S, S)], e[0, S])
    eps, singular = nees(e, noisy)
    np.testing.assert_allclose(eps, expected, rtol=1e-6)
    assert singular.all() and expected > 0

    broken = regular.copy()
    broken[1, 0, 0] = np.nan
    got, _ = nees(d, broken)
    assert np.isnan(got[1]) and np.array_equal(got[[0, 2]], solved[[0, 2]])


def test_the_nis_of_a_fitting_model_is_chi2_and_a_too_quiet_one_is_told(tmp_path) -> None:
    """A linear-Gaussian cell (CV, position fixes): the UKF's mean NIS is n_z = 2 and its window
    mean stays in its band. A target circling at 50 m/s, tracked as nearly straight (q1 = 1e-4),
    surprises the filter at almost every step, and the result says so, with no truth needed."""
    fixes = {"primary_sensor": {"kind": "position", "sigma_pos": 5.0}, "seed": 4}
    cfg = make_config(scenario="cv", runs=40, K=60, truth="random", **fixes)
    fits = run_experiment(cfg, ["ukf"], workers=1, time_steps=False)["ukf"]
    assert abs(fits.nis - 2.0) < 0.15, fits.nis
    assert fits.nis_above_band < 0.05 and fits.consistency is None
    t = np.arange(0.0, 121.0)
    xy = 3000.0 + 500.0 * np.stack([np.cos(0.1 * t), np.sin(0.1 * t)], 1)
    track = tmp_path / "circle.csv"
    track.write_text("t,x,y\n" + "".join(f"{a},{x},{y}\n" for a, (x, y) in zip(t, xy, strict=True)))
    quiet = load_config(None, scenario="cv", q1=1e-4, runs=10, truth_file=track, **fixes)
    off = run_experiment(quiet, ["ukf"], workers=1, time_steps=False)["ukf"]
    assert off.nis_above_band > 0.5 and off.consistency is not None, off.nis_above_band
    assert "noise is too low" in off.consistency
