"""``tltrack track``: the trackers over a file of recorded scans, offline."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer

from tltrack.app.common import (
    app,
    build_config,
    checked_folder,
    console,
    filter_names,
    progress_bar,
    say_error,
    say_warning,
)

if TYPE_CHECKING:
    from tltrack.engine.scan_file import ScanFile
    from tltrack.engine.setup import Setup


@app.command(
    epilog="Examples:\n\n"
    "    tltrack track --scans plots.csv --config radar.toml --out out/track\n\n"
    "    tltrack track --scans plots.csv --preset arasaratnam-haykin --pd 0.9 --clutter-rate 20 "
    "--truth-file track.csv --filters rpf,tl-rpf,ukf --out out/track"
)
def track(
    scans: Annotated[
        Path, typer.Option(help="the recorded scans (CSV `k,sensor,<components>[,is_clutter]`)")
    ],
    out: Annotated[Path, typer.Option(help="output directory")],
    config: Annotated[Path | None, typer.Option(help="TOML or JSON config file")] = None,
    scenario: Annotated[str | None, typer.Option(help="the motion model")] = None,
    preset: Annotated[str | None, typer.Option(help="paper or arasaratnam-haykin")] = None,
    filters: Annotated[str, typer.Option(help="comma-separated filter names")] = "rpf,tl-rpf",
    particles: Annotated[int | None, typer.Option(help="particles per PF")] = None,
    seed: Annotated[int | None, typer.Option(help="seed of the filters' random numbers")] = None,
    steps: Annotated[int | None, typer.Option(help="K: the steps to track (the config's)")] = None,
    pd: Annotated[float | None, typer.Option(help="the primary's probability of detection")] = None,
    clutter_rate: Annotated[
        float | None, typer.Option(help="the primary's false alarms per scan")
    ] = None,
    source_pd: Annotated[float | None, typer.Option(help="every source's pd")] = None,
    source_clutter_rate: Annotated[
        float | None, typer.Option(help="every source's false alarms per scan")
    ] = None,
    truth_file: Annotated[
        Path | None,
        typer.Option(help="the target's recorded track (CSV t,x,y or t,lat,lon): scores too"),
    ] = None,
) -> None:
    """Run the sources and the primary over recorded scans, as fast as the machine allows.

    Each row of the file is one detection; a step with no row for a sensor is an empty scan.
    Writes every filter's estimates (`estimates.csv`), the transfers the sources would have sent
    (`transfers.csv`) and, with `--truth-file`, the scores of `tltrack experiment`
    (`results.json`).
    """
    from tltrack.config.truth_file import file_truth
    from tltrack.engine import results
    from tltrack.engine.scan_file import (
        ScanFileError,
        ScansDoNotFitError,
        check_fit,
        read_scans,
    )
    from tltrack.engine.setup import Setup
    from tltrack.engine.track import track as run_track
    from tltrack.engine.track import write_estimates, write_transfers

    cfg = build_config(
        config,
        scenario=scenario,
        preset=preset,
        particles=particles,
        seed=seed,
        K=steps,
        pd=pd,
        clutter_rate=clutter_rate,
        source_pd=source_pd,
        source_clutter_rate=source_clutter_rate,
        truth_file=truth_file,
    )
    names = filter_names(filters, cfg)
    setup = Setup(cfg)
    try:
        recorded = read_scans(scans, {sid: setup.sensor(sid) for sid in setup.sensor_ids}, cfg.K)
        check_fit(setup, recorded)  # before the progress bar: a file refused draws none
    except (ScanFileError, ScansDoNotFitError) as err:
        say_error(str(err))
        raise typer.Exit(2) from None
    # before the run: a folder that cannot be written loses nothing
    checked_folder(out, writes=("estimates.csv", "transfers.csv", "scans.png", "results.json"))
    for reason in recorded.refused:
        say_warning(f"{reason}: the filters predict through it", "refused")
    truth = file_truth(cfg) if cfg.truth == "file" else None
    with progress_bar(cfg.K, "steps") as bar:
        task = bar.add_task("steps", total=cfg.K)
        done = run_track(cfg, names, recorded, truth, lambda: bar.advance(task))
    write_estimates(out / "estimates.csv", cfg.scenario, done.tracks.estimates)
    write_transfers(out / "transfers.csv", setup, done.tracks.transfers)
    wrote = [
        out / "estimates.csv",
        out / "transfers.csv",
        _draw(out / "scans.png", setup, recorded, done.tracks.estimates, truth),
    ]
    if done.scores is not None:
        wrote.append(results.write(results.assemble(cfg, done.scores), out))
        for name, r in done.scores.items():
            console.print(f"{name}: position RMSE {r.rmse_overall:.2f} m")
    refused = len(recorded.refused)
    console.print(f"{cfg.K} steps, {refused} scan(s) refused; wrote {', '.join(map(str, wrote))}")


def _draw(
    path: Path,
    setup: Setup,
    recorded: ScanFile,
    estimates: list[tuple[int, str, np.ndarray, np.ndarray]],
    truth: np.ndarray | None,
) -> Path:
    """The primary's detections (when its sensor fixes a position) under the primary filters'
    estimates, and the truth when there is one."""
    from tltrack.engine.plots import scans_and_tracks
    from tltrack.engine.scene import plan
    from tltrack.engine.setup import PRIMARY

    layout = setup.layout
    tracks: dict[str, list[np.ndarray]] = {}
    for _k, name, x, _P in estimates:
        if not name.startswith("source-"):
            tracks.setdefault(name, []).append(layout.position(x))
    dets: np.ndarray | None = None
    labels: np.ndarray | None = None
    steps = [k for k, d in enumerate(recorded.detections[PRIMARY]) if d is not None and len(d)]
    if steps:
        dets = plan(
            setup.sensor(PRIMARY), np.concatenate([recorded.detections[PRIMARY][k] for k in steps])
        )
        known = [recorded.is_clutter[PRIMARY][k] for k in steps]
        if dets is not None and all(c is not None for c in known):
            labels = np.concatenate(known)  # type: ignore[arg-type]
    xy = None if truth is None else layout.position(truth.T).T
    return scans_and_tracks(dets, labels, {n: np.array(v) for n, v in tracks.items()}, path, xy)
