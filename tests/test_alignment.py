"""The transfer made after the source's step j applies at the primary's step j + 1, never j.

A misaligned transfer still "helps" (the target moves little in one step), so no accuracy check
would notice; only equality with the offline engine does. The shifted replay must fail it.
"""

import numpy as np
from tltrack.config import make_config
from tltrack.engine.montecarlo import trace_run
from tltrack.engine.scenario import PRIMARY, simulate
from tltrack.messages import Measurement, Transfer
from tltrack.tracking import PrimaryEpisode, SourceEpisode

CFG = make_config(preset="arasaratnam-haykin", truth="fixed", seed=3, K=25, particles=400)


def _replay(shift: int) -> np.ndarray:
    """TL-PF estimates when the transfer from source step j is applied at step j + 1 - shift."""
    run = simulate(CFG, 0)
    sid = CFG.source.id
    src, prim = SourceEpisode(CFG, 0, "pf", sid), PrimaryEpisode(CFG, 0, "pf")
    made: dict[int, Transfer] = {}
    out = []
    for k in range(1, CFG.K + 1):
        z = {
            i: Measurement(episode="e", sender="t", k=k, t_sensor=0.0, sensor=i, z=run.z[i][k - 1])
            for i in (PRIMARY, sid)
        }
        _, eta = src.step(z[sid])
        made[k + 1 - shift] = Transfer(
            episode="e",
            sender=sid,
            k=k,
            t_sensor=0.0,
            k_apply=k + 1,
            eta=eta.mean[:, 0],
            P_eta=eta.cov[0],
        )
        transfers = {sid: made[k]} if k in made and k > 1 else {}
        tl, _ = prim.step(z[PRIMARY], transfers)
        out.append(tl.mean[0])
    return np.array(out)


def test_aligned_transfer_reproduces_the_engine_and_a_shifted_one_does_not():
    engine = trace_run(CFG, ["tl-pf"], run=0)["tl-pf"]
    np.testing.assert_allclose(_replay(shift=0), engine, rtol=0, atol=1e-9)
    shifted = _replay(shift=1)
    assert np.max(np.abs(shifted - engine)) > 1e-3
