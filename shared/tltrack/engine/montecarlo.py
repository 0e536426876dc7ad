"""The Monte-Carlo engine: many runs at once, vectorised over runs and particles.

Runs are cut into batches; a batch runs every requested filter side by side on the same truths and
measurements, each filter vectorised over the batch. Batches go to worker processes and only their
sufficient statistics come back (squared errors per step, NEES, per-run summaries), so memory does
not grow with the run count. Every random number comes from a per-(seed, run, purpose) stream, so
the result is the same whatever the batch size or worker count.

The overall RMSE is the paper's: the mean over k of sqrt(mean over runs of the squared position
error). Lost runs count (no filter is reinitialised here unless the config's ``recovery`` asks
for it). A run is *lost* when its position error stays above ``lost_threshold_m`` through each of
its last ``LOST_STEPS`` steps: it has diverged, not merely ended on one bad step.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tltrack.config import Config
from tltrack.engine.checkpoint import Checkpoint, full_batches
from tltrack.engine.driver import (
    Channel,
    Direct,
    Driver,
    Lossy,
    StepRecord,
    primary_specs,
    source_links,
)
from tltrack.engine.faults import transfer_lag
from tltrack.engine.names import operator_of
from tltrack.engine.registry import FilterSpec, parse
from tltrack.engine.scenario import Run, simulate
from tltrack.engine.setup import Setup
from tltrack.filters import consistency
from tltrack.filters.base import Estimate, Filter
from tltrack.filters.decision import position_fix
from tltrack.filters.kernels.moments import spread_coordinates
from tltrack.filters.warm import warm_up
from tltrack.models.base import Layout

Array = NDArray[np.float64]

#: a run is lost when its error passes the threshold in each of its last LOST_STEPS steps
LOST_STEPS = 10


@dataclass
class FilterStats:
    """Sufficient statistics of one filter over the runs seen so far."""

    K: int
    sq_err: Array = field(init=False)  # (K,) sum over runs of the squared position error
    nees: Array = field(init=False)  # (K,) sum over runs of the NEES
    nees_singular: int = 0  # run-steps whose covariance was singular
    run_mse: list[Array] = field(default_factory=list)  # per run: mean over k of squared error
    #: per run: the smallest position error over the last LOST_STEPS steps (NaN if any is NaN)
    tail_err: list[Array] = field(default_factory=list)
    step_ms: list[float] = field(default_factory=list)
    transfer_steps: int = 0  # run-steps whose update used at least one transfer
    regularised: int = 0  # run-steps whose cloud an rpf redrew from its kernel
    tracks: list[Array] = field(default_factory=list)  # per batch, (K, B, n) means, on request
    n_z: int = 0  # components of the filter's own measurement (the NIS band's degrees of freedom)
    nis_sum: float = 0.0  # over run-steps with a finite NIS of the own measurement
    nis_count: int = 0
    windows: int = 0  # run-steps with a full window of NIS (consistency.WINDOW)
    above_band: int = 0  # ... whose window mean was above its 99% band
    below_band: int = 0  # ... below it

    def __post_init__(self) -> None:
        self.sq_err = np.zeros(self.K)
        self.nees = np.zeros(self.K)

    def merge(self, other: FilterStats) -> None:
        self.sq_err += other.sq_err
        self.nees += other.nees
        self.nees_singular += other.nees_singular
        self.run_mse += other.run_mse
        self.tail_err += other.tail_err
        self.step_ms += other.step_ms
        self.transfer_steps += other.transfer_steps
        self.regularised += other.regularised
        self.tracks += other.tracks
        self.n_z = self.n_z or other.n_z
        self.nis_sum += other.nis_sum
        self.nis_count += other.nis_count
        self.windows += other.windows
        self.above_band += other.above_band
        self.below_band += other.below_band

    def to_json(self) -> dict[str, Any]:
        """Every field as plain JSON, which :meth:`from_json` reads back exactly: arrays as
        (nested) lists of Python floats, whose :mod:`json` text round-trips them (NaN as NaN)."""
        doc: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            match f.type:
                case "int":
                    doc[f.name] = int(value)
                case "float":
                    doc[f.name] = float(value)
                case "list[float]":
                    doc[f.name] = [float(v) for v in value]
                case "Array":
                    doc[f.name] = _floats(value).tolist()
                case "list[Array]":
                    doc[f.name] = [_floats(v).tolist() for v in value]
                case _:
                    raise TypeError(f"FilterStats.{f.name}: no JSON for a {f.type}")
        return doc

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> FilterStats:
        """The statistics that :meth:`to_json` wrote, bit for bit; ``ValueError``,
        ``KeyError`` or ``TypeError`` when ``doc`` is not such."""
        fields = dataclasses.fields(cls)
        extra = set(doc) - {f.name for f in fields}
        if extra:
            raise ValueError(f"FilterStats has no {sorted(extra)}")
        values: dict[str, Any] = {}
        for f in fields:
            value = doc[f.name]
            match f.type:
                case "int":
                    values[f.name] = _exactly(int, value)
                case "float":
                    values[f.name] = float(_exactly((int, float), value))
                case "list[float]":
                    values[f.name] = [float(_exactly((int, float), v)) for v in value]
                case "Array":
                    values[f.name] = _floats(value)
                case "list[Array]":
                    values[f.name] = [_floats(v) for v in _exactly(list, value)]
                case _:
                    raise TypeError(f"FilterStats.{f.name}: no JSON for a {f.type}")
        out = cls(**{f.name: values[f.name] for f in fields if f.init})
        for f in fields:
            if not f.init:
                setattr(out, f.name, values[f.name])
        if out.sq_err.shape != (out.K,) or out.nees.shape != (out.K,):
            raise ValueError(f"sums of {out.sq_err.shape} and {out.nees.shape} steps, K = {out.K}")
        return out


def _floats(value: Any) -> Array:
    """``value`` as an array of float64 (NaN where it was NaN), refusing what holds no number."""
    if isinstance(value, np.ndarray) and value.dtype != np.float64:
        raise TypeError(f"an array of {value.dtype}, not float64")
    if not isinstance(value, np.ndarray | list):
        raise TypeError(f"a {type(value).__name__}, not a list of numbers")
    return np.asarray(value, dtype=np.float64)


def _exactly(kind: type | tuple[type, ...], value: Any) -> Any:
    """``value``, when it is of ``kind`` (a JSON true is no count)."""
    if isinstance(value, bool) or not isinstance(value, kind):
        raise TypeError(f"{value!r} is not a {kind}")
    return value


def expand(names: Sequence[str], cfg: Config) -> list[FilterSpec]:
    """The requested filters plus the sources each TL filter needs, sources first."""
    links = source_links(names, Setup(cfg))
    return list(dict.fromkeys([*(parse(n) for n, _ in links), *primary_specs(names)]))


def nees(d: Array, P: Array, rcond: float = 1e-10) -> tuple[Array, NDArray[np.bool_]]:
    """d' P^-1 d per run (NaN where P is not finite), and whether P was singular.

    A collapsed cloud's P is singular up to rounding (its spread is one step's process noise,
    of rank 3 in CT). A solve does not fail there: it returns rounding noise up to 1e46, of
    either sign, that also differs between machines. There the NEES is that of the coordinates
    S with spread (:func:`~tltrack.filters.kernels.moments.spread_coordinates`), d_S' P_SS^-1 d_S.
    """
    out = np.full(len(d), np.nan)
    finite = np.isfinite(P).all(axis=(1, 2)) & np.isfinite(d).all(axis=1)
    if not finite.any():
        return out, np.zeros(len(d), dtype=bool)
    P, d = P[finite], d[finite]
    keep = spread_coordinates(P, rcond)
    singular = ~keep.all(axis=1)
    if singular.any():  # a dropped coordinate becomes a unit variance of its own, with no error
        both = keep[:, :, None] & keep[:, None, :]
        P = np.where(singular[:, None, None] & ~both, np.eye(d.shape[1]), P)
        d = np.where(keep, d, 0.0)
    out[finite] = np.einsum("bi,bi->b", d, np.linalg.solve(P, d[:, :, None])[:, :, 0])
    everywhere = np.zeros(len(out), dtype=bool)
    everywhere[finite] = singular
    return out, everywhere


class _Score:
    """Accumulates one filter's errors against the truth of a batch, and its consistency."""

    def __init__(self, K: int, layout: Layout, keep_tracks: bool, n_z: int) -> None:
        self.stats = FilterStats(K, n_z=n_z)
        self.pos = layout.pos
        self._sq: list[Array] = []
        self._means: list[Array] | None = [] if keep_tracks else None
        self._window = consistency.Window()

    def add_nis(self, values: Array) -> None:
        """One step's NIS of the filter's own z_k, per run."""
        s = self.stats
        finite = np.isfinite(values)
        s.nis_sum += float(values[finite].sum())
        s.nis_count += int(finite.sum())
        mean = self._window.push(values)
        full = np.isfinite(mean)
        lo, hi = consistency.band(s.n_z)
        s.windows += int(full.sum())
        s.above_band += int((mean[full] > hi).sum())
        s.below_band += int((mean[full] < lo).sum())

    def add(self, k: int, est: Estimate, truth_k: Array) -> None:
        d = est.mean - truth_k  # (B, n)
        e2 = d[:, self.pos[0]] ** 2 + d[:, self.pos[1]] ** 2
        self.stats.sq_err[k - 1] += e2.sum()
        eps, singular = nees(d, est.cov)
        self.stats.nees[k - 1] += eps.sum()
        self.stats.nees_singular += int(singular.sum())
        self._sq.append(e2)
        if self._means is not None:
            self._means.append(est.mean)

    def close(self) -> FilterStats:
        sq = np.stack(self._sq)  # (K, B)
        if self._means is not None:
            self.stats.tracks.append(np.stack(self._means))
        self.stats.run_mse.append(sq.mean(axis=0))
        self.stats.tail_err.append(np.sqrt(sq[-LOST_STEPS:].min(axis=0)))
        return self.stats


class Scores:
    """A collector (:mod:`~tltrack.engine.driver`): every filter's errors against the truth
    (K + 1, B, n_x) of a batch, and with ``timing`` its wall time per step.

    Operators with their own periods are each scored at their own samples: ``truth`` then maps
    each operator's id to the truth at its steps 0..K_i.
    """

    def __init__(
        self,
        truth: Array | Mapping[str, Array],
        layout: Layout,
        timing: bool,
        keep_tracks: bool,
        n_z: Callable[[str], int] = lambda _name: 0,
    ) -> None:
        """``n_z(name)``: the components of filter ``name``'s own measurement (0: no NIS)."""
        self.truth, self.layout = truth, layout
        self.timing, self.keep_tracks = timing, keep_tracks
        self.n_z = n_z
        self._scores: dict[str, _Score] = {}
        self._filters: dict[str, Filter] = {}

    def __call__(self, record: StepRecord) -> None:
        r = record
        truth = self.truth[r.operator] if isinstance(self.truth, Mapping) else self.truth
        score = self._scores.get(r.name)
        if score is None:
            K, n_z = len(truth) - 1, self.n_z(r.name)
            score = self._scores[r.name] = _Score(K, self.layout, self.keep_tracks, n_z)
        if self.timing:
            score.stats.step_ms.append(r.seconds * 1e3)
        score.add(r.k, r.estimate, truth[r.k])
        if r.nis is not None and score.stats.n_z:
            score.add_nis(r.nis)
        if r.used is not None:
            score.stats.transfer_steps += int(r.used.sum())
        self._filters[r.name] = r.filter

    def close(self) -> dict[str, FilterStats]:
        for name, filt in self._filters.items():
            self._scores[name].stats.regularised = _regularised(filt)
        return {name: s.close() for name, s in self._scores.items()}


def run_batch(
    cfg: Config,
    names: Sequence[str],
    runs: Sequence[int],
    *,
    timing: bool = False,
    keep_tracks: bool = False,
) -> dict[str, FilterStats]:
    """Run every filter of ``names`` (and the sources they need) on the runs of one batch.

    With ``timing``, also record each filter's wall time per step: meaningful for a batch of one
    run, which is how a live tracker steps. With ``keep_tracks``, keep every estimate too.
    """
    return run_sweep_batch([cfg], names, runs, timing=timing, keep_tracks=keep_tracks)[0]


def check_filters(cfg: Config, names: Sequence[str]) -> None:
    """Refuse, before any run, filters that cannot work with the configured sensors: a
    ``ValueError`` that says why (robust transfer needs sensors that fix a position)."""
    if not cfg.timeline.synchronous and any(parse(n).role == "fusion" for n in names):
        raise ValueError(
            "centralized fusion takes every sensor's z_k at the primary's step: it needs every "
            "operator on one period, phase and clock"
        )
    if any(parse(n).role == "robust" for n in names):
        setup = Setup(cfg)
        for sid in setup.sensor_ids:
            position_fix(setup.sensor(sid))


#: what a sweep's configurations may vary: the primary's sensor alone
SWEEP_FIELDS = {"primary_intensity", "primary_detection"}


def check_sweep(cfgs: Sequence[Config]) -> None:
    """Refuse configurations that differ in more than the primary's noise intensity and its
    detection process.

    Only then do the sources (and the truths) coincide, so they can be run once for all.
    """
    if not cfgs:
        raise ValueError("a sweep needs at least one configuration")
    ref = cfgs[0].model_dump(exclude=SWEEP_FIELDS)
    for c in cfgs[1:]:
        diff = {k for k, v in c.model_dump(exclude=SWEEP_FIELDS).items() if ref[k] != v}
        if diff:
            allowed = " and ".join(sorted(SWEEP_FIELDS))
            raise ValueError(f"a sweep may vary {allowed} only; also varied: {diff}")


def run_sweep_batch(
    cfgs: Sequence[Config],
    names: Sequence[str],
    runs: Sequence[int],
    *,
    timing: bool = False,
    keep_tracks: bool = False,
) -> list[dict[str, FilterStats]]:
    """:func:`run_batch` for configurations that differ only in the primary's sensor (its noise
    intensity, its detection process).

    The truths, the sources' measurements and so the sources' filters and transfers do not depend
    on the primary's sensor, so each source steps once per k and its transfer feeds the primary of
    every configuration: the results are those of separate batches, at a fraction of the cost.
    """
    check_sweep(cfgs)
    setups = [Setup(c) for c in cfgs]
    base = setups[0]
    sims = [[simulate(s, r) for r in runs] for s in setups]
    x0_hat = np.stack([s.x0_hat for s in sims[0]], axis=1)  # (n, B)
    truth = np.stack([s.truth for s in sims[0]], axis=1)  # (ticks + 1, B, n)
    timeline = base.timeline
    # each operator scored at its own samples: the truth at its steps 0..K_i
    own = {i: truth[[0, *timeline.indices(i)]] for i in base.sensor_ids}
    # sensor id -> (K_i, n_z, B), per configuration (the sources' are the same in all)
    z = [{i: np.stack([s.z[i] for s in sim], axis=2) for i in base.sensor_ids} for sim in sims]
    scores = [Scores(own, s.layout, timing, keep_tracks, own_n_z(s)) for s in setups]
    driver = Driver(
        setups,
        names,
        x0_hat,
        runs,
        channel=channel(base.cfg, runs),
        collectors=[[s] for s in scores],
    )
    for n in range(1, timeline.ticks + 1):
        now = timeline.at(n)
        if now:
            driver.tick(
                n,
                [
                    {
                        i: s.sensors[i].statement(zi[i][k - 1], _scans(sim, i, k))
                        for i, k in now.items()
                    }
                    for s, zi, sim in zip(setups, z, sims, strict=True)
                ],
            )
    return [s.close() for s in scores]


def channel(cfg: Config, runs: Sequence[int]) -> Channel:
    """The sources' links to the primary: lossy and late where the config gives a ``link``
    (:class:`Lossy`), direct for the others, a stale source's transfers late (:class:`Direct`)."""
    ahead = cfg.timeline.sends_ahead
    direct = Direct({s.id: transfer_lag(cfg, s.id) for s in cfg.sources}, ahead)
    links = {s.id: s.link for s in cfg.sources if s.link is not None}
    return Lossy(runs, cfg.seed, links, cfg.Ts, direct, ahead) if links else direct


def _scans(sims: Sequence[Run], sensor_id: str, k: int) -> list[Array] | None:
    """Each run's detections of one sensor at step k; None for the paper's sensor."""
    if sensor_id not in sims[0].scans:
        return None
    return [r.scans[sensor_id].detections[k - 1] for r in sims]


def own_n_z(setup: Setup) -> Callable[[str], int]:
    """The components of the own measurement of a filter, by its reported name."""

    def n_z(name: str) -> int:
        return setup.sensor(operator_of(name, setup.source_ids)).n_z

    return n_z


def _regularised(filt: Filter) -> int:
    """Run-steps whose cloud the filter redrew from its regularisation kernel (rpf only)."""
    return int(np.sum(getattr(filt, "regularised", 0)))


def trace_run(cfg: Config, names: Sequence[str], run: int) -> dict[str, Array]:
    """Every filter's estimates x_hat_1..x_hat_K of one run, (K, n_x).

    What a live replay of the run must match.
    """
    return {
        n: s.tracks[0][:, 0, :] for n, s in run_batch(cfg, names, [run], keep_tracks=True).items()
    }


@dataclass(frozen=True)
class FilterResult:
    """What the paper reports for one filter, plus consistency and loss of track."""

    rmse_per_step: list[float]
    rmse_overall: float
    lost_fraction: float
    nees: float
    nees_singular_rate: float  # share of run-steps with a singular covariance
    ms_per_step: float | None
    transfer_rate: float  # share of run-steps whose update used a transfer
    regularised_rate: float  # share of run-steps an rpf regularised (rpf_bandwidth > 0)
    run_rmse: list[float]  # per run, sqrt(mean over k of its squared error): paired MC errors
    nis: float  # mean NIS of the filter's own measurement (n_z when its model fits)
    nis_above_band: float  # share of full windows whose mean NIS was above its 99% band
    nis_below_band: float  # ... below it
    consistency: str | None  # what the NIS says when it stands out (consistency.verdict)

    @classmethod
    def from_stats(cls, s: FilterStats, runs: int, lost_threshold: float) -> FilterResult:
        rmse_k = np.sqrt(s.sq_err / runs)
        tail = np.concatenate(s.tail_err)
        above = s.above_band / s.windows if s.windows else 0.0
        below = s.below_band / s.windows if s.windows else 0.0
        return cls(
            rmse_per_step=rmse_k.tolist(),
            rmse_overall=float(rmse_k.mean()),
            lost_fraction=float(np.mean(~(tail <= lost_threshold))),  # NaN counts as lost
            nees=float(s.nees.sum() / (runs * s.K)),
            nees_singular_rate=s.nees_singular / (runs * s.K),
            ms_per_step=float(np.median(s.step_ms)) if s.step_ms else None,
            transfer_rate=s.transfer_steps / (runs * s.K),
            regularised_rate=s.regularised / (runs * s.K),
            run_rmse=np.sqrt(np.concatenate(s.run_mse)).tolist(),
            nis=s.nis_sum / s.nis_count if s.nis_count else float("nan"),
            nis_above_band=above,
            nis_below_band=below,
            consistency=consistency.verdict(above, below),
        )


def default_batch_size(cfg: Config, names: Sequence[str]) -> int:
    """Runs per batch: enough to amortise Python overhead, few enough to stay far under 2 GiB.

    A sweep keeps the batch of one configuration: its memory grows with the number of
    configurations (8 I_p of reproduce: ~0.1 GB a worker), while a batch cut to fit would leave
    the sigma-point filters stepping 3 runs at a time (measured 2.4x slower).
    """
    pf_count = sum(1 for s in expand(names, cfg) if s.particle) or 1
    return int(np.clip(400_000 // (cfg.particles * pf_count), 1, 64))


def run_experiment(
    cfg: Config,
    names: Sequence[str],
    *,
    batch_size: int | None = None,
    workers: int | None = None,
    progress: Callable[[int], None] | None = None,
    time_steps: bool = True,
    executor: Executor | None = None,
    checkpoint: Path | None = None,
) -> dict[str, FilterResult]:
    """Run ``cfg.runs`` runs of every filter; ``progress(n)`` hears of each batch of n runs."""
    return run_sweep(
        [cfg],
        names,
        batch_size=batch_size,
        workers=workers,
        progress=progress,
        time_steps=time_steps,
        executor=executor,
        checkpoint=checkpoint,
    )[0]


def run_sweep(
    cfgs: Sequence[Config],
    names: Sequence[str],
    *,
    batch_size: int | None = None,
    workers: int | None = None,
    progress: Callable[[int], None] | None = None,
    time_steps: bool = True,
    executor: Executor | None = None,
    checkpoint: Path | None = None,
) -> list[dict[str, FilterResult]]:
    """:func:`run_experiment` for each of ``cfgs`` (they may differ only in the primary's noise
    intensity), running the sources once for all of them; see :func:`run_sweep_batch`.

    Batches run on a local process pool of ``workers`` processes, or on ``executor`` (a Dask
    cluster's, see :mod:`tltrack.engine.cluster`), never both. ``progress`` hears of each batch as
    it completes; results are merged in batch order, so they do not depend on which finished first.
    With a ``checkpoint`` folder, each finished batch is kept there and a batch found there is
    read instead of run (:mod:`tltrack.engine.checkpoint`): a sweep that was stopped resumes.
    The merged statistics of the first batches, as far as all have finished, are kept there too,
    as one small JSON file that is read first: its batches count as merged at once (``progress``
    hears their runs in one call), and only the later ones are read from their files or run.
    """
    check_sweep(cfgs)
    if executor is not None and workers is not None:
        raise ValueError("give workers (the local pool's size) or an executor, not both")
    cfg = cfgs[0]
    check_filters(cfg, names)
    bs = batch_size or default_batch_size(cfg, names)
    batches = [list(range(i, min(i + bs, cfg.runs))) for i in range(0, cfg.runs, bs)]
    totals: list[dict[str, FilterStats]] = [{} for _ in cfgs]

    def absorb(stats: list[dict[str, FilterStats]]) -> None:
        for total, part in zip(totals, stats, strict=True):
            for name, s in part.items():
                if name in total:
                    total[name].merge(s)
                else:
                    total[name] = s

    kept = Checkpoint(checkpoint, cfgs, names) if checkpoint is not None else None
    done: dict[int, list[dict[str, FilterStats]]] = {}
    merged = 0

    def decode(plain: Any, runs: int) -> list[dict[str, FilterStats]]:
        """A prefix's merged statistics from their JSON, checked to hold ``runs`` runs."""
        stats = [{n: FilterStats.from_json(s) for n, s in part.items()} for part in plain]
        if len(stats) != len(cfgs) or not all(stats):
            raise ValueError(f"{len(stats)} configurations' statistics, not {len(cfgs)}")
        for part in stats:
            for name, s in part.items():
                seen = {sum(len(a) for a in s.run_mse), sum(len(a) for a in s.tail_err)}
                if seen != {runs}:
                    raise ValueError(f"{name}: {sorted(seen)} runs, not {runs}")
        return stats

    if kept and (prefix := kept.load_prefix(batches, decode)):
        merged, totals = prefix  # batches 0..merged-1, merged in order once for all
        if progress:
            progress(sum(len(b) for b in batches[:merged]))

    full = full_batches(batches)

    def save_prefix() -> None:
        if kept:  # the totals serialised now: no copy outlives a merge
            plain = [{name: s.to_json() for name, s in total.items()} for total in totals]
            kept.save_prefix(batches, merged, plain)

    def finished(i: int, stats: list[dict[str, FilterStats]], *, new: bool = True) -> None:
        nonlocal merged
        if kept and new:
            kept.save(batches[i], stats)
        if progress:
            progress(len(batches[i]))
        done[i] = stats
        before = merged
        while merged in done:  # in batch order: float sums in a fixed order
            absorb(done.pop(merged))
            merged += 1
            if merged == full:  # before a short last batch joins: a longer sweep goes on from it
                save_prefix()
        if before < merged < full:
            save_prefix()

    todo = []  # the batches not read back from the checkpoint
    for i, b in enumerate(batches):
        if i < merged:
            continue  # in the prefix
        stats = kept.load(b) if kept else None
        if stats is None:
            todo.append(i)
        else:
            finished(i, stats, new=False)
    workers = max(1, min(workers or os.cpu_count() or 1, len(todo)))
    if todo or time_steps:  # workers, and the timed run, then find the kernels compiled
        warm_up()
    if executor is None and workers == 1:
        for i in todo:
            finished(i, run_sweep_batch(cfgs, names, batches[i]))
    elif todo:
        with nullcontext(executor) if executor else ProcessPoolExecutor(workers) as pool:
            futures = {pool.submit(run_sweep_batch, cfgs, names, batches[i]): i for i in todo}
            try:
                for fut in as_completed(futures):
                    finished(futures[fut], fut.result())
            except BaseException:  # keep what finished meanwhile, then stop
                if kept:
                    for fut, i in futures.items():
                        ok = fut.done() and not fut.cancelled() and fut.exception() is None
                        if ok and i >= merged and i not in done:
                            kept.save(batches[i], fut.result())
                raise
            finally:
                for fut in futures:
                    fut.cancel()
    if time_steps:
        timed = run_sweep_batch(cfgs, names, [0], timing=True)
        for total, part in zip(totals, timed, strict=True):
            for name, s in part.items():
                total[name].step_ms = s.step_ms
    return [
        {
            name: FilterResult.from_stats(s, cfg.runs, cfg.lost_threshold_m)
            for name, s in total.items()
        }
        for total in totals
    ]
