from dataclasses import replace

import numpy as np
import pytest
from tltrack.config import make_config
from tltrack.engine.montecarlo import run_batch
from tltrack.filters.decision import TransferPolicy, disagreement, nis
from tltrack.models import CoordinatedTurn, Observation, RangeBearing

pytestmark = pytest.mark.unit

S = RangeBearing(10.0, np.sqrt(10) * 1e-3, CoordinatedTurn.layout)
R_p, R_s = S.R(4.0), S.R(1.0)
B = 4000


def _pair(rng, bias=0.0):
    """Primary z_k and an honest (or bearing-biased) transfer about the same true h(x_k)."""
    h = np.array([[1500.0], [0.7]])
    z = h + np.linalg.cholesky(R_p) @ rng.standard_normal((2, B))
    P_eta = R_s + np.diag([30.0, 2e-6])
    eta = h + np.linalg.cholesky(P_eta) @ rng.standard_normal((2, B)) + np.array([[0], [bias]])
    return (
        Observation.broadcast(S, z, R_p),
        Observation(S, eta, np.broadcast_to(P_eta, (B, 2, 2))),
    )


def test_an_honest_transfers_disagreement_is_chi_square_2():
    z, t = _pair(np.random.default_rng(0))
    assert (
        abs(nis(*disagreement(t, z)).mean() - 2.0) < 0.15
    )  # E[chi2(2)] = 2; linearisation error is tiny here


def test_honest_transfers_pass_and_a_biased_source_is_shut_out():
    rng = np.random.default_rng(1)
    honest, biased = TransferPolicy(), TransferPolicy()
    for _ in range(30):
        z, t = _pair(rng)
        kept_h = honest.select(z, [t])[0].mask
        z, t = _pair(rng, bias=10 * np.sqrt(10) * 1e-3)
        kept_b = biased.select(z, [t])[0].mask
    assert kept_h.mean() > 0.99
    assert kept_b.mean() < 0.01


def test_budget_caps_the_share_of_steps_with_a_transfer():
    rng = np.random.default_rng(2)
    policy = TransferPolicy(budget=0.25)
    for _ in range(40):
        z, t = _pair(rng)
        policy.select(z, [t])
    assert np.all(policy.used <= 0.25 * 40)
    assert policy.used.mean() > 0.2 * 40  # the budget is spent, not wasted


def test_a_source_that_agrees_keeps_its_precision_and_an_offset_one_is_discounted():
    rng = np.random.default_rng(3)
    honest, offset = TransferPolicy(), TransferPolicy()
    for _ in range(30):
        z, t = _pair(rng)
        used_h = honest.select(z, [t])[0]
        z, t = _pair(rng, bias=3 * np.sqrt(10) * 1e-3)  # 3 sigma: passes most single gates
        used_o = offset.select(z, [t])[0]
    stated = t.cov[0, 1, 1]
    assert np.median(used_h.cov[:, 1, 1]) < 1.5 * stated
    assert np.median(used_o.cov[:, 1, 1]) > 2.0 * np.median(used_h.cov[:, 1, 1])


def test_each_sources_record_follows_its_origin_whichever_others_arrive():
    rng = np.random.default_rng(4)
    policy = TransferPolicy()
    for k in range(6):
        z, t = _pair(rng)
        s1, s2 = replace(t, origin="s1"), replace(t, origin="s2")
        policy.select(z, [s1, s2] if k % 2 else [s2])
    assert {o: len(h) for o, h in policy._history.items()} == {"s1": 3, "s2": 6}


def test_a_source_found_out_late_leaves_the_robust_primary_equal_to_the_isolated_one():
    """Rollback: runs that used a biased source before the evidence was in end up exactly on the
    isolated filter (same random numbers), instead of dragged off for good."""
    cfg = make_config(
        preset="arasaratnam-haykin",
        truth="noise-free",
        K=30,
        particles=400,
        sources=[{"id": "s1", "fault": "bias"}],
    )
    stats = run_batch(cfg, ["pf", "robust-tl-pf"], list(range(60)), keep_tracks=True)
    iso, robust = stats["pf"].tracks[0], stats["robust-tl-pf"].tracks[0]  # (K, B, n)
    used = np.any(robust != iso, axis=(0, 2))
    assert used.any(), "no run ever used the biased source: the rollback was not exercised"
    np.testing.assert_array_equal(robust[-1], iso[-1])
