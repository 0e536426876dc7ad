import numpy as np
from tltrack.filters.decision import TransferPolicy, disagreement, nis
from tltrack.models import Observation, RangeBearing

S = RangeBearing(10.0, np.sqrt(10) * 1e-3)
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
