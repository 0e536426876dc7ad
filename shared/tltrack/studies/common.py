"""What every study shares: how it runs the engine, and how it reports paired differences.

Runs of the same index share the truth and the primary's measurements across configurations
(their random streams are named, not positional), so differences between configurations are
*paired*: the Monte-Carlo error of a difference A - B is twice the standard error of the per-run
difference of the overall RMSE (each run's sqrt of the mean over k of its squared position
error).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from tltrack.config import Config, load_config
from tltrack.engine.montecarlo import FilterResult, default_batch_size, run_sweep
from tltrack.engine.scenario import truth
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.studies import finished

Results = dict[str, FilterResult]
T = TypeVar("T")
R = TypeVar("R")


@dataclass(frozen=True)
class Runner:
    """How a study runs its experiments: where, in what batches, telling whom of progress."""

    progress: Callable[[int], None] | None = None
    workers: int | None = None
    batch_size: int | None = None
    executor: Executor | None = None  #: a Dask cluster's (tltrack.engine.cluster), or local
    #: where finished batches are kept, so that a stopped study resumes (tltrack.engine.checkpoint),
    #: and finished sweeps (tltrack.studies.finished)
    checkpoint: Path | None = None

    def run(self, cfg: Config, names: Sequence[str]) -> Results:
        return self.sweep([cfg], names)[0]

    def map(self, fn: Callable[[T], R], items: Sequence[T]) -> list[R]:
        """``fn`` (a module's function, so that it pickles) over ``items``, in order, where the
        batches run: the cluster's executor, else a local pool of ``workers`` processes (all
        cores by default), or here when that is one. For a study's work beside the engine's."""
        workers = max(1, min(self.workers or os.cpu_count() or 1, len(items)))
        if self.executor is None and workers == 1:
            return [fn(x) for x in items]
        with nullcontext(self.executor) if self.executor else ProcessPoolExecutor(workers) as pool:
            return list(pool.map(fn, items))

    def sweep(
        self, cfgs: Sequence[Config], names: Sequence[str], *, time_steps: bool = True
    ) -> list[Results]:
        """Configurations differing only in the primary's sensor, the sources run once; with
        ``time_steps``, one more run timed step by step (:func:`run_sweep`). A sweep that
        finished before in the checkpoint folder is read back whole."""
        batch_size = self.batch_size or default_batch_size(cfgs[0], names)
        kept = None
        if self.checkpoint is not None:
            kept = finished.Finished(self.checkpoint, cfgs, names, batch_size, time_steps)
            if (results := kept.load()) is not None:
                if self.progress:
                    self.progress(cfgs[0].runs)
                return results
        results = run_sweep(
            cfgs,
            names,
            progress=self.progress,
            workers=self.workers,
            batch_size=batch_size,
            executor=self.executor,
            time_steps=time_steps,
            checkpoint=self.checkpoint,
        )
        if kept is not None:
            kept.save(results)
        return results


def run_difference(a: FilterResult, b: FilterResult) -> NDArray[np.float64]:
    """Per run, the overall RMSE of a minus that of b: the paired comparison's samples."""
    return np.asarray(a.run_rmse) - np.asarray(b.run_rmse)


def mc_error(d: NDArray[np.float64]) -> float:
    """Twice the standard error of the mean of the paired differences ``d``."""
    return float(2.0 * d.std(ddof=1) / np.sqrt(len(d)))


def paired(a: FilterResult, b: FilterResult) -> str:
    """``"+x.xxx (e.eee)"``: the mean over runs of the per-run overall-RMSE difference a - b, and
    its Monte-Carlo error (see the module docstring)."""
    d = run_difference(a, b)
    return f"{d.mean():+.3f} ({mc_error(d):.3f})"


def row(cells: Sequence[Any]) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def bound(cfg: Config, with_sources: bool = True) -> NDArray[np.float64]:
    """The PCRLB of the primary (and every source's data) along run 0's truth, per k."""
    setup = Setup(cfg)
    ids = setup.sensor_ids if with_sources else [PRIMARY]
    return setup.pcrlb(ids, truth(setup, 0)[None])


def plain(r: Results) -> dict[str, Any]:
    """What a study's JSON keeps of each filter's results."""
    return {
        n: {
            "rmse_overall": v.rmse_overall,
            "lost_fraction": v.lost_fraction,
            "transfer_rate": v.transfer_rate,
            "run_rmse": v.run_rmse,
        }
        for n, v in r.items()
    }


def write(out: Path, name: str, lines: list[str], data: dict[str, Any]) -> Path:
    """``out/<name>.md`` (the report) and ``out/<name>.json`` (its numbers)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.json").write_text(json.dumps(data, indent=1))
    path = out / f"{name}.md"
    path.write_text("\n".join(lines) + "\n")
    return path


@dataclass(frozen=True)
class Setting:
    """The experiment a study varies: runs, seed, the filter kind, and the base configuration.

    ``particles`` None: the study's own default. ``truth_file`` replaces the truth mode.
    """

    runs: int = 200
    seed: int = 0
    kind: str = "pf"
    source_filter: str | None = None
    preset: str = "arasaratnam-haykin"
    truth: str = "noise-free"
    truth_file: Path | None = None
    particles: int | None = None

    def config(self, particles: int, **changes: Any) -> Config:
        """The base configuration with ``changes``, every source of the kind asked for."""
        data: dict[str, Any] = {
            "preset": self.preset,
            "primary_intensity": 4,
            "particles": self.particles or particles,
            "runs": self.runs,
            "seed": self.seed,
            **changes,
        }
        if self.truth_file is not None:
            data.setdefault("truth_file", self.truth_file)
        if data.get("truth_file") is None:
            data.setdefault("truth", self.truth)
        if self.source_filter is not None:
            srcs = data.get("sources", [{"id": "s1"}])
            data["sources"] = [{**s, "filter": self.source_filter} for s in srcs]
        return load_config(None, **data)

    def name(self, role: str = "") -> str:
        """The filter of this study's kind in ``role`` (``""``, ``tl-``, ``robust-tl-`` ...)."""
        return f"{role}{self.kind}"

    def describe(self, cfg: Config) -> str:
        truth = f"truth file `{cfg.truth_file}`" if cfg.truth == "file" else f"{cfg.truth} truth"
        sources = f", sources' filter {self.source_filter}" if self.source_filter else ""
        return (
            f"`{cfg.preset}`, {truth}, I_p = {cfg.primary_intensity:g}, N = {cfg.particles}, "
            f"{cfg.runs} runs, seed {cfg.seed}, filter kind {self.kind}{sources}"
        )
