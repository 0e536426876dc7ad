"""The transfer made after the source's step j applies at the primary's step j + 1, never j.

A misaligned transfer still "helps" (the target moves little in one step), so no accuracy check
would notice; only equality with the offline engine does. The shifted replay must fail it.
"""

import numpy as np
import pytest
from tltrack.config import make_config
from tltrack.engine.faults import STALE_LAG
from tltrack.engine.montecarlo import trace_run
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.live.tracking import PrimaryEpisode, SourceEpisode
from tltrack.wire.messages import Measurement, Transfer

pytestmark = pytest.mark.unit

CFG = make_config(preset="arasaratnam-haykin", truth="fixed", seed=3, K=25, particles=400)


def _replay(shift: int) -> np.ndarray:
    """TL-PF estimates when the transfer from source step j is applied at step j + 1 - shift."""
    run = simulate(Setup(CFG), 0)
    sid = CFG.source.id
    src, prim = SourceEpisode(CFG, 0, "pf", sid), PrimaryEpisode(CFG, 0, "pf")
    made: dict[int, Transfer] = {}
    out = []
    for k in range(1, CFG.K + 1):
        z = {
            i: Measurement(
                episode="e", sender="t", k=k, t_sensor=0.0, sensor=i, z=[run.z[i][k - 1]]
            )
            for i in (PRIMARY, sid)
        }
        _, eta = src.step(z[sid])
        made[k + 1 - shift] = Transfer(
            episode="e",
            sender=sid,
            k=k,
            t_sensor=0.0,
            k_apply=k + 1,
            sensor=src.own.spec,
            eta=eta.mean[:, 0],
            P_eta=eta.cov[0],
        )
        transfers = {sid: made[k]} if k in made and k > 1 else {}
        tl = prim.step(z[PRIMARY], transfers)
        out.append(tl.mean[0])
    return np.array(out)


def test_aligned_transfer_reproduces_the_engine_and_a_shifted_one_does_not():
    engine = trace_run(CFG, ["tl-pf"], run=0)["tl-pf"]
    np.testing.assert_allclose(_replay(shift=0), engine, rtol=0, atol=1e-9)
    shifted = _replay(shift=1)
    assert np.max(np.abs(shifted - engine)) > 1e-3


def test_the_engines_robust_primary_keeps_each_sources_record_as_a_live_one_does():
    """Two sources, the first stale: its transfers start 3 steps after the other's. The engine's
    robust primary must judge each by its own record, as the live one (keyed by sender) does."""
    cfg = make_config(
        preset="arasaratnam-haykin",
        truth="fixed",
        seed=3,
        K=25,
        particles=400,
        sources=[{"id": "s1", "fault": "stale"}, {"id": "s2"}],
    )
    lag = {"s1": STALE_LAG, "s2": 0}
    run = simulate(Setup(cfg), 0)
    srcs = {s: SourceEpisode(cfg, 0, "pf", s) for s in lag}
    prim = PrimaryEpisode(cfg, 0, "pf", robust=True)
    made: dict[str, dict[int, Transfer]] = {s: {} for s in lag}
    out = []
    for k in range(1, cfg.K + 1):
        for s, src in srcs.items():
            z = Measurement(
                episode="e", sender="t", k=k, t_sensor=0.0, sensor=s, z=[run.z[s][k - 1]]
            )
            _, eta = src.step(z)
            made[s][k + 1] = Transfer(
                episode="e",
                sender=s,
                k=k,
                t_sensor=0.0,
                k_apply=k + 1,
                sensor=src.own.spec,
                eta=eta.mean[:, 0],
                P_eta=eta.cov[0],
            )
        transfers = {s: made[s][k - lag[s]] for s in lag if k - lag[s] in made[s]}
        z = Measurement(
            episode="e", sender="t", k=k, t_sensor=0.0, sensor=PRIMARY, z=[run.z[PRIMARY][k - 1]]
        )
        tl = prim.step(z, transfers)
        out.append(tl.mean[0])
    engine = trace_run(cfg, ["robust-tl-pf"], run=0)["robust-tl-pf"]
    np.testing.assert_allclose(np.array(out), engine, rtol=0, atol=1e-9)
