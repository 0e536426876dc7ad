"""``tltrack experiment`` and ``tltrack plot``: the Monte-Carlo engine's results and figures."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer

from tltrack.app.common import (
    BatchSize,
    CheckpointDir,
    Scheduler,
    Workers,
    app,
    build_config,
    checked_checkpoint,
    checked_folder,
    console,
    engine_pool,
    filter_names,
    progress_bar,
    say_error,
    say_warning,
)


def _numbers(v: Any) -> bool:
    """A list of numbers, not all of them NaN (a figure of nothing is no figure)."""
    return (
        isinstance(v, list)
        and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        and any(math.isfinite(x) for x in v)
    )


def _drawable(doc: dict[str, Any]) -> None:
    """What the figures read beyond what :func:`tltrack.engine.results.read` checks: each
    filter's name (its run is traced again) and RMSE, and the PCRLB; ``ValueError`` naming the
    field."""
    from tltrack.engine.registry import parse

    for name, r in doc["filters"].items():
        parse(name.split("/", 1)[0])
        if not _numbers(r["rmse_per_step"]):
            raise ValueError(f"filters.{name}.rmse_per_step: not a list of numbers")
        if isinstance(r["rmse_overall"], bool):
            raise ValueError(f"filters.{name}.rmse_overall: not a number")
    pcrlb = doc.get("pcrlb", {})
    if not isinstance(pcrlb, dict) or not all(_numbers(b) for b in pcrlb.values()):
        raise ValueError("pcrlb: not a map of names to lists of numbers")


@app.command(
    epilog="Examples:\n\n"
    "    tltrack experiment --scenario ct --preset arasaratnam-haykin --truth noise-free "
    "--filters pf,tl-pf --particles 6000 --runs 200 --primary-intensity 4 --seed 1 --out /tmp/e\n\n"
    "    tltrack experiment --config my.toml --filters ukf,tl-ukf --out out/ukf\n\n"
    "    tltrack experiment --preset arasaratnam-haykin --pd 0.9 --clutter-rate 20 "
    "--filters rpf,tl-rpf,ukf,tl-ukf --runs 20 --out /tmp/clutter"
)
def experiment(
    scenario: Annotated[
        str | None,
        typer.Option(help="the motion model: cv (Scenario 1), ct (Scenario 2), ca, or a plugin's"),
    ] = None,
    preset: Annotated[str | None, typer.Option(help="paper or arasaratnam-haykin")] = None,
    target_class: Annotated[
        str | None,
        typer.Option(help="ship or aircraft: the filters take the class's fitted motion modes"),
    ] = None,
    config: Annotated[Path | None, typer.Option(help="TOML or JSON config file")] = None,
    filters: Annotated[str, typer.Option(help="comma-separated filter names")] = "pf,tl-pf",
    particles: Annotated[int | None, typer.Option(help="particles per PF")] = None,
    runs: Annotated[int | None, typer.Option(help="Monte-Carlo runs")] = None,
    source_intensity: Annotated[float | None, typer.Option(help="I_w of the source")] = None,
    sources: Annotated[
        str | None, typer.Option(help="several sources at the origin, by intensity, e.g. 1,2,8")
    ] = None,
    source_fault: Annotated[
        str | None, typer.Option(help="fault of the (first) source: none, bias, diverged or stale")
    ] = None,
    source_filter: Annotated[
        str | None,
        typer.Option(help="every source's filter kind (default: its TL primary's kind)"),
    ] = None,
    transfer_budget: Annotated[
        float | None, typer.Option(help="robust-tl-*: at most this share of steps with a transfer")
    ] = None,
    primary_intensity: Annotated[float | None, typer.Option(help="I_w of the primary")] = None,
    pd: Annotated[
        float | None, typer.Option(help="the primary's probability of detection, in (0, 1]")
    ] = None,
    clutter_rate: Annotated[
        float | None, typer.Option(help="the primary's mean false alarms per scan (Poisson)")
    ] = None,
    source_pd: Annotated[
        float | None, typer.Option(help="every source's probability of detection")
    ] = None,
    source_clutter_rate: Annotated[
        float | None, typer.Option(help="every source's mean false alarms per scan")
    ] = None,
    truth: Annotated[str | None, typer.Option(help="fixed, random or noise-free")] = None,
    seed: Annotated[int | None, typer.Option(help="master seed of every random stream")] = None,
    truth_seed: Annotated[int | None, typer.Option(help="seed of the fixed truth")] = None,
    truth_file: Annotated[
        Path | None,
        typer.Option(help="a recorded track as the truth (CSV t,x,y or t,lat,lon); no --truth"),
    ] = None,
    out: Annotated[Path, typer.Option(help="output directory")] = Path("out/experiment"),
    recovery: Annotated[
        bool | None,
        typer.Option(
            "--recovery/--no-recovery", help="reinitialise lost particle filters (default: off)"
        ),
    ] = None,
    rpf_bandwidth: Annotated[
        float | None,
        typer.Option(help="rpf: regularisation kernel bandwidth h in [0, 1) (default 0: off)"),
    ] = None,
    workers: Workers = None,
    batch_size: BatchSize = None,
    scheduler: Scheduler = None,
    checkpoint: CheckpointDir = None,
) -> None:
    """Run the Monte-Carlo engine; write DIR/results.json, rmse.png and trajectory.png."""
    from tltrack.engine.experiment import run_and_save

    cfg = build_config(
        config,
        scenario=scenario,
        preset=preset,
        target_class=target_class,
        particles=particles,
        runs=runs,
        source_intensity=source_intensity,
        primary_intensity=primary_intensity,
        pd=pd,
        clutter_rate=clutter_rate,
        source_pd=source_pd,
        source_clutter_rate=source_clutter_rate,
        truth=truth,
        seed=seed,
        truth_seed=truth_seed,
        truth_file=truth_file,
        sources=sources,
        source_fault=source_fault,
        source_filter=source_filter,
        transfer_budget=transfer_budget,
        recovery=recovery,
        rpf_bandwidth=rpf_bandwidth,
    )
    names = filter_names(filters, cfg)
    checkpoint = checked_checkpoint(checkpoint)
    checked_folder(out, writes=("results.json", "rmse.png", "trajectory.png"))
    with engine_pool(scheduler, workers) as executor, progress_bar(cfg.runs, "runs") as bar:
        task = bar.add_task("runs", total=cfg.runs)
        doc = run_and_save(
            cfg,
            names,
            out,
            workers=workers,
            batch_size=batch_size,
            progress=lambda n: bar.advance(task, n),
            executor=executor,
            checkpoint=checkpoint,
        )
    _print_table(doc)
    console.print(f"wrote {out / 'results.json'}, {out / 'rmse.png'}, {out / 'trajectory.png'}")


def _print_table(doc: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(
        title="position RMSE (paper's overall definition)",
        caption="NEES*: the covariance was singular (a collapsed cloud) on some run-steps; "
        "NIS: of the filter's own measurement (n_z when its model fits), and the share of "
        "20-step windows above its 99% band",
    )
    for col in ("filter", "RMSE [m]", "lost", "NEES", "NIS", "above", "ms/step"):
        t.add_column(col, justify="right" if col != "filter" else "left")
    for name, r in doc["filters"].items():
        ms = r["ms_per_step"]
        t.add_row(
            name,
            f"{r['rmse_overall']:.2f}",
            f"{r['lost_fraction']:.1%}",
            f"{r['nees']:.4g}{'*' if r['nees_singular_rate'] > 0 else ''}",
            f"{r['nis']:.3g}",
            f"{r['nis_above_band']:.0%}",
            "-" if ms is None else f"{ms:.3f}",
        )
    Console().print(t)
    if "pcrlb_note" in doc:
        console.print(f"note: {doc['pcrlb_note']}")
    for name, r in doc["filters"].items():
        if r["consistency"]:
            say_warning(f"{name}: {r['consistency']}")


@app.command()
def plot(
    results_json: Annotated[Path, typer.Argument(help="a results.json written by experiment")],
    out: Annotated[Path | None, typer.Option(help="directory (default: beside the file)")] = None,
) -> None:
    """Redraw the figures of a saved result.

    Example: `tltrack plot out/experiment/results.json`
    """
    from pydantic import ValidationError

    from tltrack.config import Config, describe_validation_error
    from tltrack.engine.experiment import draw
    from tltrack.engine.results import read

    try:
        doc = read(results_json)
        cfg = Config.model_validate(doc["config"])
        _drawable(doc)
    except ValidationError as err:
        say_error(f"cannot read {results_json}: config: {describe_validation_error(err)}")
        raise typer.Exit(2) from None
    except (OSError, ValueError) as err:
        say_error(f"cannot read {results_json}: {err}")
        raise typer.Exit(2) from None
    folder = checked_folder(out or results_json.parent, writes=("rmse.png", "trajectory.png"))
    try:  # it traces run 0 again: a truth file since moved, a filter its sensors cannot run
        wrote = draw(doc, folder, cfg)
    except ValueError as err:
        say_error(f"cannot redraw {results_json}: {err}")
        raise typer.Exit(2) from None
    for p in wrote:
        console.print(f"wrote {p}")
