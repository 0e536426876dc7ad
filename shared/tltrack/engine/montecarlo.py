"""The Monte-Carlo engine: many runs at once, vectorised over runs and particles.

Runs are cut into batches; a batch runs every requested filter side by side on the same truths and
measurements, each filter vectorised over the batch. Batches go to worker processes and only their
sufficient statistics come back (squared errors per step, NEES, per-run summaries), so memory does
not grow with the run count. Every random number comes from a per-(seed, run, purpose) stream, so
the result is the same whatever the batch size or worker count.

The overall RMSE is the paper's: the mean over k of sqrt(mean over runs of the squared position
error). Lost runs count (no filter is ever reinitialised here).
"""

from __future__ import annotations

import copy
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from contextlib import nullcontext
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from tltrack.config import PARTICLE_KINDS, Config
from tltrack.engine.faults import transfer_lag
from tltrack.engine.registry import FilterSpec, build, parse, recovery, source_name
from tltrack.engine.scenario import simulate
from tltrack.filters.base import Estimate, Filter
from tltrack.filters.decision import TransferPolicy, position_fix
from tltrack.filters.kernels.moments import spread_coordinates
from tltrack.filters.transfer import Primary, Source
from tltrack.filters.warm import warm_up
from tltrack.models.base import Layout, MotionModel
from tltrack.models.from_config import PRIMARY, intensity, motion_model, sensor
from tltrack.models.observation import Observation

Array = NDArray[np.float64]


@dataclass
class FilterStats:
    """Sufficient statistics of one filter over the runs seen so far."""

    K: int
    sq_err: Array = field(init=False)  # (K,) sum over runs of the squared position error
    nees: Array = field(init=False)  # (K,) sum over runs of the NEES
    nees_singular: int = 0  # run-steps whose covariance was singular
    run_mse: list[Array] = field(default_factory=list)  # per run: mean over k of squared error
    final_err: list[Array] = field(default_factory=list)  # per run: position error at k = K
    step_ms: list[float] = field(default_factory=list)
    transfer_steps: int = 0  # run-steps whose update used at least one transfer
    regularised: int = 0  # run-steps whose cloud an rpf redrew from its kernel
    tracks: list[Array] = field(default_factory=list)  # per batch, (K, B, n) means, on request

    def __post_init__(self) -> None:
        self.sq_err = np.zeros(self.K)
        self.nees = np.zeros(self.K)

    def merge(self, other: FilterStats) -> None:
        self.sq_err += other.sq_err
        self.nees += other.nees
        self.nees_singular += other.nees_singular
        self.run_mse += other.run_mse
        self.final_err += other.final_err
        self.step_ms += other.step_ms
        self.transfer_steps += other.transfer_steps
        self.regularised += other.regularised
        self.tracks += other.tracks


def expand(names: Sequence[str], cfg: Config) -> list[FilterSpec]:
    """The requested filters plus the sources each TL filter needs, sources first."""
    return list(
        dict.fromkeys([*(parse(n) for n, _ in source_filters(names, cfg)), *_primaries(names)])
    )


def _primaries(names: Sequence[str]) -> list[FilterSpec]:
    return [s for s in (parse(n) for n in dict.fromkeys(names)) if s.role != "source"]


def source_filters(names: Sequence[str], cfg: Config) -> list[tuple[str, str]]:
    """(source filter, source id) of every source filter to run: those the TL filters listen to,
    and those asked for by name (for every source)."""
    ids = [s.id for s in cfg.sources]
    pairs = []
    for spec in (parse(n) for n in dict.fromkeys(names)):
        if spec.role in ("tl", "robust"):
            pairs += [(source_name(spec, cfg, sid), sid) for sid in ids]
    pairs += [
        (spec.name, sid) for spec in map(parse, names) if spec.role == "source" for sid in ids
    ]
    return list(dict.fromkeys(pairs))


def reported_name(spec: FilterSpec, source_id: str, n_sources: int) -> str:
    """``source-pf`` for the paper's single source; ``source-pf/<id>`` when there are several."""
    return spec.name if n_sources == 1 else f"{spec.name}/{source_id}"


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
    """Accumulates one filter's errors against the truth of a batch."""

    def __init__(self, K: int, layout: Layout, keep_tracks: bool) -> None:
        self.stats = FilterStats(K)
        self.pos = layout.pos
        self._sq: list[Array] = []
        self._means: list[Array] | None = [] if keep_tracks else None

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
        self.stats.final_err.append(np.sqrt(sq[-1]))
        return self.stats


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
    if any(parse(n).role == "robust" for n in names):
        for sid in [PRIMARY, *(s.id for s in cfg.sources)]:
            position_fix(sensor(cfg, sid))


def check_sweep(cfgs: Sequence[Config]) -> None:
    """Refuse configurations that differ in more than the primary's noise intensity.

    Only then do the sources (and the truths) coincide, so they can be run once for all.
    """
    if not cfgs:
        raise ValueError("a sweep needs at least one configuration")
    ref = cfgs[0].model_dump(exclude={"primary_intensity"})
    for c in cfgs[1:]:
        diff = {k for k, v in c.model_dump(exclude={"primary_intensity"}).items() if ref[k] != v}
        if diff:
            raise ValueError(f"a sweep may vary primary_intensity only; also varied: {diff}")


def run_sweep_batch(
    cfgs: Sequence[Config],
    names: Sequence[str],
    runs: Sequence[int],
    *,
    timing: bool = False,
    keep_tracks: bool = False,
) -> list[dict[str, FilterStats]]:
    """:func:`run_batch` for configurations that differ only in the primary's noise intensity.

    The truths, the sources' measurements and so the sources' filters and transfers do not depend
    on the primary's sensor, so each source steps once per k and its transfer feeds the primary of
    every configuration: the results are those of separate batches, at a fraction of the cost.
    """
    check_sweep(cfgs)
    cfg = cfgs[0]
    model = motion_model(cfg)
    K = cfg.K
    sims = [[simulate(c, r) for r in runs] for c in cfgs]
    x0_hat = np.stack([s.x0_hat for s in sims[0]], axis=1)  # (n, B)
    truth = np.stack([s.truth for s in sims[0]], axis=1)  # (K + 1, B, n)
    source_ids = [s.id for s in cfg.sources]
    z_src = {i: np.stack([s.z[i] for s in sims[0]], axis=2) for i in source_ids}  # (K, n_z, B)
    meas = {i: (sensor(cfg, i), sensor(cfg, i).R(intensity(cfg, i))) for i in source_ids}

    def observation(sensor_id: str, k: int) -> Observation:
        s, R = meas[sensor_id]
        return Observation.broadcast(s, z_src[sensor_id][k - 1], R)

    specs = _primaries(names)
    sources: dict[tuple[str, str], Source] = {}
    labels: dict[tuple[str, str], str] = {}  # each source filter's reported name
    source_scores: dict[str, _Score] = {}
    for name, sid in source_filters(names, cfg):
        spec = parse(name)
        filt = build(spec, cfg, model, x0_hat, runs, source_id=sid)
        sources[name, sid] = Source(filt, *meas[sid], recovery(spec, cfg))
        labels[name, sid] = reported_name(spec, sid, len(source_ids))
        source_scores[labels[name, sid]] = _Score(K, model.layout, keep_tracks)
    variants = [
        _PrimaryVariant(c, [s.z[PRIMARY] for s in sim], specs, model, x0_hat, runs, keep_tracks)
        for c, sim in zip(cfgs, sims, strict=True)
    ]

    lag = {sid: transfer_lag(cfg, sid) for sid in source_ids}
    made: dict[tuple[str, str], dict[int, Observation]] = {key: {} for key in sources}
    for k in range(1, K + 1):
        for (name, sid), src in sources.items():
            t0 = time.perf_counter()
            est, transfer = src.step(observation(sid, k))
            score = source_scores[labels[name, sid]]
            _tick(score, timing, t0)
            score.add(k, est, truth[k])
            # made at k, applies at k_apply = k + 1; named by its source, as a live one is
            made[name, sid][k + 1] = replace(transfer, origin=sid)
            made[name, sid].pop(k - lag[sid] - 1, None)

        def transfers(spec: FilterSpec, k: int = k) -> list[Observation]:
            if spec.role in ("tl", "robust"):  # none at k = 1
                return [
                    t
                    for sid in source_ids
                    if (t := made[source_name(spec, cfg, sid), sid].get(k - lag[sid])) is not None
                ]
            if spec.role == "fusion":
                return [observation(sid, k) for sid in source_ids]
            return []

        for v in variants:
            v.step(k, transfers, truth[k], timing)
    for key, src in sources.items():
        source_scores[labels[key]].stats.regularised = _regularised(src.filter)
    source_stats = {name: s.close() for name, s in source_scores.items()}
    # Each configuration reports the shared sources as its own (copies: merges must not alias).
    return [
        {**{n: copy.deepcopy(s) for n, s in source_stats.items()}, **v.close()} for v in variants
    ]


class _PrimaryVariant:
    """The primaries of one configuration of a sweep, with their own measurement z_k."""

    def __init__(
        self,
        cfg: Config,
        z: list[Array],
        specs: Sequence[FilterSpec],
        model: MotionModel,
        x0_hat: Array,
        runs: Sequence[int],
        keep_tracks: bool,
    ) -> None:
        self.sensor = sensor(cfg)
        self.R = self.sensor.R(intensity(cfg))
        self.z = np.stack(z, axis=2)  # (K, n_z, B)
        self.primaries: dict[str, tuple[FilterSpec, Primary]] = {}
        self.scores: dict[str, _Score] = {}
        for spec in specs:
            policy = (
                TransferPolicy(cfg.gate_probability, cfg.transfer_budget)
                if spec.role == "robust"
                else None
            )
            filt = build(spec, cfg, model, x0_hat, runs)
            twin = None
            if spec.role == "robust":  # its isolated twin, on the same random numbers
                iso = build(parse(spec.kind), cfg, model, x0_hat, runs)
                twin = Primary(iso, None, recovery(spec, cfg))
            self.primaries[spec.name] = (spec, Primary(filt, policy, recovery(spec, cfg), twin))
            self.scores[spec.name] = _Score(cfg.K, model.layout, keep_tracks)

    def step(
        self,
        k: int,
        transfers: Callable[[FilterSpec], list[Observation]],
        truth_k: Array,
        timing: bool,
    ) -> None:
        own = Observation.broadcast(self.sensor, self.z[k - 1], self.R)
        for name, (spec, prim) in self.primaries.items():
            extra = transfers(spec)
            t0 = time.perf_counter()
            est = prim.step(own, extra)
            _tick(self.scores[name], timing, t0)
            self.scores[name].add(k, est, truth_k)
            if prim.used is not None:
                self.scores[name].stats.transfer_steps += int(prim.used.sum())

    def close(self) -> dict[str, FilterStats]:
        for name, (_spec, prim) in self.primaries.items():
            self.scores[name].stats.regularised = _regularised(prim.filter)
        return {name: s.close() for name, s in self.scores.items()}


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


def _tick(score: _Score, timing: bool, t0: float) -> None:
    if timing:
        score.stats.step_ms.append((time.perf_counter() - t0) * 1e3)


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

    @classmethod
    def from_stats(cls, s: FilterStats, runs: int, lost_threshold: float) -> FilterResult:
        rmse_k = np.sqrt(s.sq_err / runs)
        final = np.concatenate(s.final_err)
        return cls(
            rmse_per_step=rmse_k.tolist(),
            rmse_overall=float(rmse_k.mean()),
            lost_fraction=float(np.mean(~(final <= lost_threshold))),  # NaN counts as lost
            nees=float(s.nees.sum() / (runs * s.K)),
            nees_singular_rate=s.nees_singular / (runs * s.K),
            ms_per_step=float(np.median(s.step_ms)) if s.step_ms else None,
            transfer_rate=s.transfer_steps / (runs * s.K),
            regularised_rate=s.regularised / (runs * s.K),
            run_rmse=np.sqrt(np.concatenate(s.run_mse)).tolist(),
        )


def default_batch_size(cfg: Config, names: Sequence[str]) -> int:
    """Runs per batch: enough to amortise Python overhead, few enough to stay far under 2 GiB.

    A sweep keeps the batch of one configuration: its memory grows with the number of
    configurations (8 I_p of reproduce: ~0.1 GB a worker), while a batch cut to fit would leave
    the sigma-point filters stepping 3 runs at a time (measured 2.4x slower).
    """
    pf_count = sum(1 for s in expand(names, cfg) if s.kind in PARTICLE_KINDS) or 1
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
) -> list[dict[str, FilterResult]]:
    """:func:`run_experiment` for each of ``cfgs`` (they may differ only in the primary's noise
    intensity), running the sources once for all of them; see :func:`run_sweep_batch`.

    Batches run on a local process pool of ``workers`` processes, or on ``executor`` (a Dask
    cluster's, see :mod:`tltrack.engine.cluster`), never both. ``progress`` hears of each batch as
    it completes; results are merged in batch order, so they do not depend on which finished first.
    """
    check_sweep(cfgs)
    if executor is not None and workers is not None:
        raise ValueError("give workers (the local pool's size) or an executor, not both")
    cfg = cfgs[0]
    check_filters(cfg, names)
    bs = batch_size or default_batch_size(cfg, names)
    batches = [list(range(i, min(i + bs, cfg.runs))) for i in range(0, cfg.runs, bs)]
    workers = max(1, min(workers or os.cpu_count() or 1, len(batches)))
    totals: list[dict[str, FilterStats]] = [{} for _ in cfgs]

    def absorb(stats: list[dict[str, FilterStats]]) -> None:
        for total, part in zip(totals, stats, strict=True):
            for name, s in part.items():
                if name in total:
                    total[name].merge(s)
                else:
                    total[name] = s

    warm_up()  # workers then load compiled kernels from the cache instead of compiling them
    if executor is None and workers == 1:
        for b in batches:
            absorb(run_sweep_batch(cfgs, names, b))
            if progress:
                progress(len(b))
    else:
        with nullcontext(executor) if executor else ProcessPoolExecutor(workers) as pool:
            futures = {
                pool.submit(run_sweep_batch, cfgs, names, b): i for i, b in enumerate(batches)
            }
            done: dict[int, list[dict[str, FilterStats]]] = {}
            merged = 0
            try:
                for fut in as_completed(futures):
                    i = futures[fut]
                    done[i] = fut.result()
                    if progress:
                        progress(len(batches[i]))
                    while merged in done:  # in batch order: float sums in a fixed order
                        absorb(done.pop(merged))
                        merged += 1
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
