"""``tltrack bench`` and ``tltrack bench-live``: step times, and the live pair's latency."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Literal, get_args

import typer

from tltrack.app.common import (
    app,
    build_config,
    checked_file,
    console,
    say_error,
)
from tltrack.live.topology import Kind as TopologyKind


@app.command("bench-live")
def bench_live(
    particles: Annotated[int, typer.Option(min=10, help="particles per PF")] = 6000,
    pace: Annotated[float, typer.Option(min=0.1, help="steps/s for the latency run")] = 50.0,
    steps: Annotated[int, typer.Option(min=1, help="steps of the latency episode")] = 500,
    rates: Annotated[
        str, typer.Option(help="step rates to try, ascending; the ladder stops at the first missed")
    ] = "100,200,300,500,800,1000",
    ladder_steps: Annotated[
        int, typer.Option(min=1, help="steps per rung of the rate ladder")
    ] = 5000,
    filters: Annotated[str, typer.Option(help="particle filter kinds, comma-separated")] = "rpf,pf",
    json_out: Annotated[Path | None, typer.Option("--json", help="write the figures here")] = None,
    topology: Annotated[
        Literal["federated", "single", "both"],
        typer.Option(help="a router per operator (federated), one for all (single), or both"),
    ] = "both",
) -> None:
    """Benchmark the live pair: latency at a moderate pace, the routed round trip and the TL step
    it is compared with, and the highest sustained rate, for each topology x filter kind (one
    entry each under `runs`; the defaults, federated and rpf, also at the top level).

    Example: `tltrack bench-live --particles 6000 --pace 50 --json out/live.json`
    """
    from tltrack.live.supervisor import Interrupted, stop_on_signals
    from tltrack.perf import livebench

    kinds = get_args(TopologyKind) if topology == "both" else (topology,)
    from tltrack.filters.kinds import FILTERS

    if json_out:
        checked_file(json_out, "--json")

    kinds_of_filter = tuple(f.strip() for f in filters.split(","))
    if unknown := [f for f in kinds_of_filter if f not in FILTERS or not FILTERS.get(f).particle]:
        say_error(f"--filters: not a particle filter kind: {unknown}")
        raise typer.Exit(2)
    try:
        ladder = [float(r) for r in rates.split(",")]
    except ValueError:
        say_error(f"--rates: not a list of numbers: {rates!r}")
        raise typer.Exit(2) from None
    if not all(math.isfinite(r) and r > 0 for r in ladder):
        say_error(f"--rates: steps per second, each finite and > 0, not {rates!r}")
        raise typer.Exit(2)
    build_config(None, particles=particles)  # the bounds the services will hold it to
    try:
        with stop_on_signals():
            result = livebench.run(
                particles, pace, steps, ladder, kinds, kinds_of_filter, ladder_steps
            )
    except Interrupted as stop:
        console.print(f"stopped by {stop}; the router and every service are stopped")
        raise typer.Exit(128 + stop.signum) from None
    text = json.dumps(result, indent=1)
    console.print(text)
    if json_out:
        json_out.write_text(text)


@app.command()
def bench(
    particles: Annotated[int, typer.Option(min=10, help="particles per PF")] = 6000,
    repeats: Annotated[int, typer.Option(min=1, help="passes over the K steps")] = 3,
    clutter: Annotated[
        bool,
        typer.Option(
            help="instead: rpf and pf on scans of 1000 detections against their clean step"
        ),
    ] = False,
    steps: Annotated[int, typer.Option(min=1, help="--clutter: steps per pass")] = 100,
    json_out: Annotated[Path | None, typer.Option("--json", help="write the figures here")] = None,
) -> None:
    """Time one filter step (tl-pf, pf, source-pf) against plain NumPy and Stone Soup, side by side.

    Example: `tltrack bench --json out/bench.json` (Stone Soup needs the `stonesoup` extra);
    `tltrack bench --clutter` (tltrack.perf.clutter)
    """
    if json_out:
        checked_file(json_out, "--json")
    build_config(None, particles=particles, **({"K": steps} if clutter else {}))
    if clutter:
        from tltrack.perf.clutter import format_clutter_table, run_clutter_bench

        result = run_clutter_bench(particles=particles, repeats=repeats, steps=steps)
        console.print(format_clutter_table(result))
    else:
        from tltrack.perf.bench import format_table, run_bench

        result = run_bench(particles=particles, repeats=repeats)
        console.print(format_table(result))
    if json_out:
        json_out.write_text(json.dumps(result, indent=1))
        console.print(f"wrote {json_out}")
