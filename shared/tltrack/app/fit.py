"""``tltrack fit``: a motion model's process noise, fitted to recorded tracks."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, cast

import typer

from tltrack.app.common import app, checked_file, console, say_error, say_warning

if TYPE_CHECKING:  # the engine is imported when a command runs, not when the CLI starts
    from tltrack.engine.fit import Fit, Kind, Reports


@app.command(
    epilog="Examples:\n\n    tltrack fit --truth-file examples/tracks/ais.csv --model cv\n\n"
    "    tltrack fit --truth-file a.csv --truth-file b.csv --model modes --out aircraft.toml"
)
def fit(
    truth_file: Annotated[
        list[Path], typer.Option(help="a recorded track (CSV t,x,y or t,lat,lon); repeatable")
    ],
    model: Annotated[
        str,
        typer.Option(
            help="cv, ct, modes (a straight and a turning mode) or manoeuvres (those and a "
            "manoeuvring mode)"
        ),
    ] = "cv",
    out: Annotated[
        Path | None, typer.Option(help="write the fitted noise as a config file (TOML) here")
    ] = None,
    Ts: Annotated[
        float, typer.Option("--ts", help="the filters' period, for the modes' transition [s]")
    ] = 1.0,
) -> None:
    """Fit process noise by maximum likelihood on the tracks' raw reports, at their own times;
    print each parameter with its 95% interval, and write a config that uses them."""
    from rich.table import Table

    from tltrack.config import ConfigError, make_config
    from tltrack.config.truth_file import TruthFileError, read_track, to_local
    from tltrack.engine import fit as fitting

    if model not in fitting.PARAMETERS:
        say_error(f"--model: use {', '.join(fitting.PARAMETERS)}")
        raise typer.Exit(2)
    try:  # the config it writes must load: Config's own rules for a period
        make_config(scenario="ct", Ts=Ts)
    except ConfigError as err:
        say_error(f"--ts: {err}")
        raise typer.Exit(2) from None
    if out is not None:
        checked_file(out)
    tracks = []
    try:
        for path in truth_file:
            track = read_track(path)
            xy, _origin = to_local(track)
            tracks.append(fitting.Reports(path.name, track.t - track.t[0], xy))
    except (TruthFileError, ValueError) as err:
        say_error(str(err))
        raise typer.Exit(2) from None
    with console.status(f"fitting {model} to {sum(len(r.t) for r in tracks)} reports"):
        result = fitting.fit(tracks, model)  # type: ignore[arg-type]
    t = Table(title=f"{model}: maximum likelihood on {result.reports} reports")
    for col in ("parameter", "value", "95% interval"):
        t.add_column(col, justify="left" if col == "parameter" else "right")
    for name, v in result.values.items():
        lo, hi = result.intervals[name]
        t.add_row(name, f"{v:.4g}", f"{lo:.4g} .. {hi:.4g}")
    t.caption = f"log-likelihood {result.loglik:.2f}"
    console.print(t)
    for text in past_the_grid(tracks, result):
        say_warning(text)
    if out is not None:
        out.write_text(config_text(result, Ts))
        console.print(f"wrote {out}")


#: how far past an estimate or an interval's end :func:`past_the_grid` looks [decades]
BEYOND = 0.1
#: a rise in log-likelihood smaller than this is round-off on a flat likelihood, not a maximum
TOLERANCE = 1e-3


def past_the_grid(tracks: Sequence[Reports], result: Fit) -> list[str]:
    """What the cv fit's grid cut off: an estimate with a higher likelihood past it, or a 95%
    interval still inside its level past its end.

    The cv fit reads q1 and sigma off a grid (:func:`tltrack.engine.fit.fit`) and cannot report
    a maximum or an interval end beyond it: real tracks reach its edges (an anchored ship's q1, a
    simulated track's sigma near 0). The likelihood :data:`BEYOND` past the value, the other
    parameter held at its estimate, is at most the profile's there, so each warning is sure: the
    maximum, or the interval, lies further out (the interval's level taken from the higher of
    the grid's best and the estimate's likelihood, the stricter). ``modes`` and ``manoeuvres``
    take q1_straight from the cv fit, which is checked for them; ``ct`` is searched without a
    grid.
    """
    from scipy.stats import chi2

    from tltrack.engine import fit as fitting

    if result.kind == "ct":
        return []
    cv = result if result.kind == "cv" else fitting.fit(tracks, "cv")
    shown = {"q1": "q1", "sigma": "sigma"} if result.kind == "cv" else {"q1": "q1_straight"}
    half = float(chi2.ppf(0.95, 1)) / 2.0
    found = []
    for p, name in shown.items():
        v, (lo, hi) = cv.values[p], cv.intervals[p]

        def ll(x: float, p: str = p) -> float:
            return fitting.loglik(tracks, "cv", {**cv.values, p: x})

        top = max(cv.loglik, ll(v))  # the grid's best, or the estimate's between its points
        for side in (-1, 1):
            past = v * 10.0 ** (side * BEYOND)
            if ll(past) > top + TOLERANCE:
                found.append(
                    f"{name} = {v:.4g} is not the maximum: the likelihood is higher at "
                    f"{past:.4g}, past the end of the fit's grid"
                )
        for end, side in ((lo, -1), (hi, 1)):
            past = end * 10.0 ** (side * BEYOND)
            if ll(past) >= top - half:
                found.append(
                    f"{name}'s 95% interval runs past {end:.4g}, where the fit's grid ends: "
                    f"it is wider than shown (the likelihood at {past:.4g} is still inside it)"
                )
    return found


def config_text(result: Fit, Ts: float) -> str:
    """A config (TOML) with the fitted noise: the scenario's q1 (and q2), or the modes and their
    chain over one period Ts."""
    from tltrack.config.target_classes import transition, uniform_rates
    from tltrack.engine.fit import mode_specs

    v = result.values
    head = f"# tltrack fit --model {result.kind} on {', '.join(result.tracks)}\n"
    if result.kind == "cv":
        return head + f'scenario = "cv"\nq1 = {v["q1"]:.6g}\n'
    if result.kind == "ct":
        return head + f'scenario = "ct"\nq1 = {v["q1"]:.6g}\nq2 = {v["q2"]:.6g}\n'
    specs = mode_specs(cast("Kind", result.kind), v)  # one of PARAMETERS, checked at the start
    Pi = transition(uniform_rates(len(specs), v["switch_rate"]), Ts)
    rows = ", ".join("[" + ", ".join(f"{p:.12g}" for p in row) + "]" for row in Pi)
    text = head + f'scenario = "ct"\nTs = {Ts!r}\nmode_transition = [{rows}]\n'
    for m in specs:
        text += f'\n[[motion_modes]]\nkind = "{m["kind"]}"\nq1 = {m["q1"]:.6g}\n'
        text += f"q2 = {m['q2']:.6g}\n" if "q2" in m else ""
    return text
