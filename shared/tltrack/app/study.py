"""``tltrack study``: the studies beyond the paper."""

from __future__ import annotations

import functools
from collections.abc import Callable
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

#: study realizations' defaults
REALIZATIONS = 100
REALIZATION_FILTERS = "pf,tl-pf,ukf,tl-ukf,ckf3,tl-ckf3,ckf5,tl-ckf5"
#: study manoeuvres' tracks
TRACKS = Path("examples/tracks")


@app.command(
    epilog="Examples:\n\n    tltrack study robust --runs 200\n\n"
    "    tltrack study robust --kind rpf --source-filter pf --preset paper --truth fixed\n\n"
    "    tltrack study heterogeneous --runs 200\n\n"
    "    tltrack study realizations --realizations 100 --runs 50 --preset paper\n\n"
    "    tltrack study manoeuvres --runs 200\n\n"
    "    tltrack study clutter --runs 200\n\n"
    "    tltrack study links --runs 200"
)
def study(
    name: Annotated[
        str,
        typer.Argument(
            help="robust, sources, budget, heterogeneous, presets, intensities, realizations, "
            "manoeuvres, clutter or links"
        ),
    ],
    runs: Annotated[
        int, typer.Option(min=2, help="Monte-Carlo runs per configuration; 2 for an error bar")
    ] = 200,
    out: Annotated[Path, typer.Option(help="output directory")] = Path("out/studies"),
    seed: Annotated[int, typer.Option(help="master seed (the robust design was tuned on 1)")] = 0,
    kind: Annotated[str, typer.Option(help="the filter kind studied (pf, ukf, ...)")] = "pf",
    source_filter: Annotated[
        str | None, typer.Option(help="the sources' filter kind (default: --kind)")
    ] = None,
    preset: Annotated[str, typer.Option(help="paper or arasaratnam-haykin")] = "arasaratnam-haykin",
    truth: Annotated[str, typer.Option(help="fixed, random or noise-free")] = "noise-free",
    truth_file: Annotated[
        Path | None, typer.Option(help="a recorded track as the truth (not realizations)")
    ] = None,
    particles: Annotated[
        int | None, typer.Option(min=10, help="particles per PF (default: the study's own)")
    ] = None,
    realizations: Annotated[
        int | None, typer.Option(help="study realizations: how many [100]")
    ] = None,
    filters: Annotated[
        str | None,
        typer.Option(help=f"study realizations: the filters [{REALIZATION_FILTERS}]"),
    ] = None,
    tracks: Annotated[
        Path | None,
        typer.Option(help="study manoeuvres: the recorded tracks' folder [examples/tracks]"),
    ] = None,
    workers: Workers = None,
    batch_size: BatchSize = None,
    scheduler: Scheduler = None,
    checkpoint: CheckpointDir = None,
) -> None:
    """A study beyond the paper: a markdown report, its numbers (JSON) and a figure."""
    from tltrack import studies
    from tltrack.filters.kinds import FILTERS

    def known_kind(k: str | None) -> bool:
        try:
            return k is None or FILTERS.get(k, trusted=True) is not None
        except ValueError:
            return False

    by_name: dict[str, Callable[[studies.Setting, studies.Runner, Path], Path]] = {
        "robust": studies.robust,
        "sources": studies.sources,
        "budget": studies.budget,
        "heterogeneous": studies.heterogeneous,
        "presets": studies.presets,
        "intensities": studies.intensities,
        "manoeuvres": functools.partial(studies.manoeuvres, tracks=tracks or TRACKS),
        "clutter": studies.clutter,
        "links": studies.links,
    }
    known = [*by_name, "realizations"]
    problems = [
        "" if name in known else f"unknown study {name!r}; use {', '.join(known)}",
        "" if known_kind(kind) else f"--kind: unknown kind {kind!r}",
        "" if known_kind(source_filter) else f"--source-filter: unknown {source_filter!r}",
        "" if realizations is None or realizations >= 2 else "--realizations must be at least 2",
        *(
            f"{option} is an option of study {owner}, not of {name}"
            for option, owner, given in (
                ("--realizations", "realizations", realizations),
                ("--filters", "realizations", filters),
                ("--tracks", "manoeuvres", tracks),
            )
            if given is not None and name != owner and name in known
        ),
    ]
    if any(problems):
        say_error("; ".join(p for p in problems if p))
        raise typer.Exit(2)
    setting = studies.Setting(runs, seed, kind, source_filter, preset, truth, truth_file, particles)
    configurations = {
        "realizations": realizations or REALIZATIONS,
        "manoeuvres": studies.MANOEUVRE_CONFIGS,
        "clutter": studies.CLUTTER_SWEEPS,
        "links": len(studies.link_cells()),
    }
    total = runs * configurations.get(name, 1)
    checkpoint = checked_checkpoint(checkpoint)
    checked_folder(out, writes=(f"{name}.md", f"{name}.json"))  # its figures' names vary
    with engine_pool(scheduler, workers) as executor, progress_bar(total, name) as bar:
        task = bar.add_task(name, total=total if name in configurations else None)
        runner = studies.Runner(
            lambda n: bar.advance(task, n), workers, batch_size, executor, checkpoint
        )
        try:
            if name == "realizations":
                listed = filters or REALIZATION_FILTERS
                names = [f.strip() for f in listed.split(",") if f.strip()]
                count = realizations or REALIZATIONS
                path = studies.realizations(setting, runner, out, count=count, filters=names)
            else:
                path = by_name[name](setting, runner, out)
        except ValueError as err:  # a refused configuration or filter
            say_error(str(err))
            raise typer.Exit(2) from None
    console.print(Path(path).read_text(), markup=False)
    console.print(f"wrote {path}")
