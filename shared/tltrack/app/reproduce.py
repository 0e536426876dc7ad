"""``tltrack reproduce``: the paper's figures and tables."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tltrack.app.common import (
    BatchSize,
    CheckpointDir,
    Scheduler,
    Workers,
    app,
    checked_checkpoint,
    checked_folder,
    console,
    engine_pool,
    progress_bar,
    say_error,
)
from tltrack.config import ConfigError


@app.command(
    epilog="Examples:\n\n    tltrack reproduce --runs 500 --out out/reproduce\n\n"
    "    tltrack reproduce --runs 200 --preset arasaratnam-haykin --truth noise-free"
)
def reproduce(
    runs: Annotated[
        int,
        typer.Option(min=2, help="Monte-Carlo runs per point (paper: 10000); 2 for an error bar"),
    ] = 500,
    out: Annotated[Path, typer.Option(help="output directory")] = Path("out/reproduce"),
    preset: Annotated[str, typer.Option(help="paper or arasaratnam-haykin")] = "paper",
    truth: Annotated[str, typer.Option(help="fixed, random or noise-free")] = "fixed",
    seed: Annotated[int, typer.Option(help="master seed")] = 0,
    workers: Workers = None,
    table2_pf_only: Annotated[
        bool, typer.Option(help="only Table 2's particle-filter rows (the 10,000-run benchmark)")
    ] = False,
    losses_only: Annotated[
        bool, typer.Option(help="only the lost-track table, for both presets and truth modes")
    ] = False,
    batch_size: BatchSize = None,
    scheduler: Scheduler = None,
    checkpoint: CheckpointDir = None,
) -> None:
    """Regenerate every figure and table of the paper's Simulation Results, with report.md."""
    from tltrack.studies import reproduce as rep

    if table2_pf_only and losses_only:
        say_error("--table2-pf-only and --losses-only: choose one")
        raise typer.Exit(2)
    try:
        base = rep.base_config(preset, truth, runs, seed)
    except ConfigError as err:
        say_error(f"invalid configuration: {err}")
        raise typer.Exit(2) from None
    if table2_pf_only:
        todo, write = rep.table2_pf_jobs(base), rep.table2_pf_report
    elif losses_only:
        todo, write = rep.loss_jobs(base), rep.losses_report
    else:
        todo, write = rep.jobs(base) + rep.loss_jobs(base), rep.report
    checkpoint = checked_checkpoint(checkpoint)
    checked_folder(out, writes=("report.md", "summary.json", "losses.md", "table2_pf.md"))
    with engine_pool(scheduler, workers) as executor, progress_bar(runs, "reproduce") as bar:
        # a job's clock starts when its sweep does (run_all's first, empty advance), not while
        # it waits for the sweeps before it
        tasks = {j.label: bar.add_task(j.label, total=runs, start=False) for j in todo}
        docs = rep.run_all(
            todo,
            out,
            workers=workers,
            batch_size=batch_size,
            executor=executor,
            progress=lambda label, n: bar.advance(tasks[label], n),
            checkpoint=checkpoint,
        )
    made = write(docs, out)
    console.print(f"wrote {made}")
