"""Offline tracking of recorded scans: the sources and the primary over a scan file, through the
step driver, as fast as the machine allows (``tltrack track``).

One run (a batch of one), started at the config's x0 (the prior mean, not a draw around it: there
is no Monte-Carlo run to vary). At each step every sensor's recorded scan becomes what its filters
take (:meth:`~tltrack.engine.setup.OwnSensor.statement`): the scan itself when the sensor misses
or reports false alarms, the one detection otherwise. A scan refused as too large is no statement:
the filters predict through it. What comes out: every filter's estimate per step, the transfers
the sources would have sent, and, against a recorded truth, the scores ``tltrack experiment``
writes.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tltrack.config import Config
from tltrack.engine.driver import Collector, Driver, StepRecord
from tltrack.engine.montecarlo import FilterResult, Scores, own_n_z
from tltrack.engine.scan_file import ScanFile, check_fit
from tltrack.engine.setup import Setup
from tltrack.models.kinds import MOTIONS
from tltrack.models.scan import Statement

Array = NDArray[np.float64]


#: one filter's estimate at one step: (k, filter, mean, covariance)
Estimated = tuple[int, str, Array, Array]
#: one transfer: (k_apply, the source filter's name, source id, eta_hat, P_eta_eta)
Sent = tuple[int, str, str, Array, Array]


@dataclass
class Tracks:
    """A collector: each filter's (k, mean, cov), and each source's transfers
    (k_apply, source id, eta_hat, P_eta_eta)."""

    estimates: list[Estimated] = field(default_factory=list)
    transfers: list[Sent] = field(default_factory=list)

    def __call__(self, record: StepRecord) -> None:
        r = record
        self.estimates.append((r.k, r.name, r.estimate.mean[0], r.estimate.cov[0]))
        if r.transfer is not None:
            t = r.transfer
            self.transfers.append((r.k + 1, r.name, t.origin or "", t.mean[:, 0], t.cov[0]))


@dataclass(frozen=True)
class TrackResult:
    tracks: Tracks
    scores: dict[str, FilterResult] | None  #: against the truth, when there is one
    refused: list[str]  #: the scans refused (too large), with the line of each


def statements(setup: Setup, scans: ScanFile, k: int) -> dict[str, Statement | None]:
    """What each sensor's filters take at step k (None: the scan was refused)."""
    out: dict[str, Statement | None] = {}
    for sid in setup.sensor_ids:
        dets = scans.scan(sid, k)
        out[sid] = None if dets is None else setup.sensors[sid].report(dets)
    return out


def track(
    cfg: Config,
    names: Sequence[str],
    scans: ScanFile,
    truth: Array | None = None,
    progress: Callable[[], None] = lambda: None,
    *,
    x0_hat: Array | None = None,
    run: int = 0,
) -> TrackResult:
    """Every filter of ``names`` (and the sources they listen to) over ``scans``; scored against
    ``truth`` (K + 1, n_x) when given; ``progress()`` after each step.

    The filters start at ``x0_hat`` (default: the config's x0) and draw the random numbers of
    Monte-Carlo run ``run``: with a run's x0_hat and scans, the engine's numbers for that run."""
    setup = Setup(cfg)
    check_fit(setup, scans)
    tracks = Tracks()
    collectors: list[Collector] = [tracks]
    scores = None
    if truth is not None:
        scores = Scores(truth[:, None, :], setup.layout, True, False, own_n_z(setup))
        collectors.append(scores)
    start = np.asarray(cfg.x0 if x0_hat is None else x0_hat, dtype=float)[:, None]
    driver = Driver([setup], names, start, [run], collectors=[collectors])
    for k in range(1, scans.K + 1):
        driver.step(k, [statements(setup, scans, k)])
        progress()
    results = None
    if scores is not None:
        stats = scores.close()
        results = {n: FilterResult.from_stats(s, 1, cfg.lost_threshold_m) for n, s in stats.items()}
    return TrackResult(tracks, results, scans.refused)


#: the state's components that lead every estimates.csv, whatever the motion model's order
LEADING = ("x_m", "y_m", "vx_mps", "vy_mps")


def write_estimates(path: Path, scenario: str, rows: Sequence[Estimated]) -> None:
    """estimates.csv: k, filter, x_m, y_m, vx_mps, vy_mps, the state's other components (of the
    motion model ``scenario``), and the position covariance P_xx, P_xy, P_yy."""
    components = list(MOTIONS.get(scenario).components)
    order = [c for c in LEADING if c in components] + [c for c in components if c not in LEADING]
    at = [components.index(c) for c in order]
    ix, iy = components.index("x_m"), components.index("y_m")
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["k", "filter", *order, "P_xx", "P_xy", "P_yy"])
        for k, name, x, P in rows:
            cov = (P[ix, ix], P[ix, iy], P[iy, iy])
            w.writerow([k, name, *(_num(x[i]) for i in at), *(_num(v) for v in cov)])


def write_transfers(path: Path, setup: Setup, rows: Sequence[Sent]) -> None:
    """transfers.csv: k_apply, source, filter, eta_<component>... and P_<ci>_<cj> (i <= j)
    of each transfer, in its source sensor's components (the columns of the sources' kinds;
    empty where a source's kind has no such component)."""
    comps: list[str] = []
    for sid in setup.source_ids:
        comps += [c for c in setup.sensor(sid).components if c not in comps]
    pairs = [(a, b) for i, a in enumerate(comps) for b in comps[i:]]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "k_apply",
                "source",
                "filter",
                *(f"eta_{c}" for c in comps),
                *(f"P_{a}_{b}" for a, b in pairs),
            ]
        )
        for k_apply, name, sid, eta, P in rows:
            own = list(setup.sensor(sid).components)
            at = {c: i for i, c in enumerate(own)}
            means = [_num(eta[at[c]]) if c in at else "" for c in comps]
            covs = [_num(P[at[a], at[b]]) if a in at and b in at else "" for a, b in pairs]
            w.writerow([k_apply, sid, name, *means, *covs])


def _num(v: float) -> str:
    return repr(float(v))
