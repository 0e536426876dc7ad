"""``tltrack experiment``: run the Monte-Carlo engine and write results.json and its figures."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from pathlib import Path
from typing import Any

from tltrack.config import Config
from tltrack.engine import plots, results
from tltrack.engine.montecarlo import run_experiment, trace_run
from tltrack.engine.scenario import truth
from tltrack.engine.setup import Setup


def run_and_save(
    cfg: Config,
    filters: Sequence[str],
    out: Path,
    *,
    workers: int | None = None,
    batch_size: int | None = None,
    progress: Callable[[int], None] | None = None,
    executor: Executor | None = None,
    checkpoint: Path | None = None,
) -> dict[str, Any]:
    """Run, then write ``out/results.json``, ``out/rmse.png`` and ``out/trajectory.png``."""
    res = run_experiment(
        cfg,
        filters,
        workers=workers,
        batch_size=batch_size,
        progress=progress,
        executor=executor,
        checkpoint=checkpoint,
    )
    doc = results.assemble(cfg, res)
    results.write(doc, out)
    draw(doc, out)
    return doc


def draw(doc: dict[str, Any], out: Path, cfg: Config | None = None) -> list[Path]:
    """The figures of one results document (also what ``tltrack plot`` redraws); ``cfg``: its
    config, already validated."""
    cfg = cfg or Config.model_validate(doc["config"])
    names = [n for n in doc["filters"] if "/" not in n]
    tracks = trace_run(cfg, [n for n in names if not n.startswith("source-")], run=0)
    setup = Setup(cfg)
    layout = setup.layout
    xy = {name: layout.position(x.T).T for name, x in tracks.items()}
    return [
        plots.rmse_vs_time(doc, out / "rmse.png"),
        plots.trajectory(layout.position(truth(setup, 0).T).T, xy, out / "trajectory.png"),
    ]
