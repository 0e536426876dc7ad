import numpy as np
import pytest
from tltrack.config import make_config
from tltrack.engine.montecarlo import run_experiment
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import Setup
from tltrack.engine.streams import streams
from tltrack.filters.auxiliary import AuxiliaryParticleFilter
from tltrack.filters.particle import ParticleFilter
from tltrack.filters.recovery import Recovery
from tltrack.models import Observation, RangeBearing

pytestmark = pytest.mark.unit

CFG = make_config(preset="arasaratnam-haykin")


@pytest.mark.parametrize("kind", [ParticleFilter, AuxiliaryParticleFilter])
def test_a_cloud_far_from_the_measurement_is_redrawn_around_it(kind):
    model = Setup(CFG).motion
    s = RangeBearing(10.0, 3e-3, model.layout)
    x0 = np.array(CFG.x0)[:, None].repeat(2, 1)
    pf = kind(model, x0, np.diag(CFG.P0_diag), 500, streams(0, range(2), "r"))
    pf.predict()
    truth = np.array([1300.0, 1000.0])
    far = np.array([[np.hypot(*truth), np.hypot(*truth)], [np.arctan2(1000, 1300), 2.0]])
    z = Observation.broadcast(s, far, s.R(4.0))
    rec = Recovery(np.diag(CFG.P0_diag))
    lost = rec(pf, z)
    assert lost.tolist() == [False, True] and rec.count.tolist() == [0, 1]
    pos, _ = s.to_position(far[:, 1:], s.R(4.0)[None])
    assert np.allclose(pf.x[[0, 2], 1, :].mean(axis=1), pos[:, 0], atol=15.0)
    pf.update([z])
    assert np.all(np.isfinite(pf.estimate().mean))


def test_an_rpf_test_that_finds_nothing_lost_changes_no_number():
    """The auxiliary filter's test reads the transition means its update then reuses."""
    model = Setup(CFG).motion
    s = RangeBearing(CFG.sigma_r, CFG.sigma_bearing, model.layout)
    run = simulate(Setup(CFG), 0)
    x0 = run.x0_hat[:, None].repeat(2, 1)
    tested, plain = (
        AuxiliaryParticleFilter(model, x0, np.diag(CFG.P0_diag), 500, streams(0, range(2), "r"))
        for _ in range(2)
    )
    rec = Recovery(np.diag(CFG.P0_diag))
    for z_k in run.z["primary"][:10]:
        z = Observation.broadcast(s, np.asarray(z_k), s.R(CFG.primary_intensity))
        for pf in (tested, plain):
            pf.predict()
        assert not rec(tested, z).any()
        for pf in (tested, plain):
            pf.update([z])
        np.testing.assert_array_equal(tested.estimate().mean, plain.estimate().mean)


def test_recovery_brings_lost_runs_back_in_the_seeds_hard_preset():
    """The seed's own q2 loses runs (docs/background.md); recovery is an option and must help."""
    cfg = make_config(preset="paper", truth="random", particles=1000, runs=12, K=60, seed=5)
    off = run_experiment(cfg, ["pf"], time_steps=False)["pf"]
    on = run_experiment(cfg.with_(recovery=True), ["pf"], time_steps=False)["pf"]
    assert off.lost_fraction > 0
    assert on.lost_fraction < off.lost_fraction
    assert np.isfinite(on.rmse_overall)
