"""Robust transfer: a primary that judges each transfer before it uses it.

The paper's primary trusts its source. Here the source's sensor is miscalibrated (the ``bias``
fault: a constant offset of a few standard deviations). ``tl-rpf`` follows it and ends up worse
than the isolated filter; ``robust-tl-rpf`` checks each transfer against its own measurement (a
consistency gate, :mod:`tltrack.filters.decision`), stops using a source found out, and rolls back
to the isolated filter the runs that source had already taught. With an honest source it keeps
most of TL's gain.

    python examples/tutorials/robust_transfer.py
"""

from __future__ import annotations

from typing import Any

from tltrack.config import make_config
from tltrack.engine.montecarlo import run_experiment

FILTERS = ["rpf", "tl-rpf", "robust-tl-rpf"]


def main(runs: int = 20, particles: int = 1000) -> dict[str, dict[str, Any]]:
    """Each filter's result against an honest and a biased source: {fault: {filter: result}}."""
    out = {}
    for fault in ("none", "bias"):
        cfg = make_config(
            preset="arasaratnam-haykin",
            truth="fixed",
            particles=particles,
            runs=runs,
            seed=1,
            sources=[{"id": "s1", "fault": fault}],
        )
        out[fault] = run_experiment(cfg, FILTERS, workers=1)
    print(f"{'source':8s}" + "".join(f"{n:>16s}" for n in FILTERS) + "   robust's transfer rate")
    for fault, res in out.items():
        rmse = "".join(f"{res[n].rmse_overall:14.2f} m" for n in FILTERS)
        print(f"{fault:8s}{rmse}   {res['robust-tl-rpf'].transfer_rate:6.1%}")
    return out


if __name__ == "__main__":
    main()
