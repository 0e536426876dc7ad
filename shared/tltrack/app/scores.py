"""``tltrack scores``: the scorer's per-step scores as JSON Lines, for notebooks."""

from __future__ import annotations

import contextlib
import json
import sqlite3
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, TextIO

import typer

from tltrack.app.common import app, console


@app.command(
    epilog="Examples:\n\n    tltrack scores --jsonl scores.jsonl\n\n"
    "    tltrack scores --jsonl - --db scorer.sqlite --episode ep-r0 | jq .error_m"
)
def scores(
    jsonl: Annotated[Path, typer.Option(help="the JSON Lines file to write ('-': stdout)")],
    db: Annotated[
        Path,
        typer.Option(
            envvar="TLTRACK_SCORER_DB", help="the scorer's SQLite file (`tltrack demo` writes this)"
        ),
    ] = Path("out/demo/scorer.sqlite"),
    episode: Annotated[str | None, typer.Option(help="only this episode")] = None,
) -> None:
    """Write one JSON object per filter and step: episode, filter, k, error_m, latency_ms,
    transfer_used.

    `error_m` is the distance between the estimate's position and the truth's at k (null without
    a truth), `latency_ms` the time from the sensor's publication of z_k to the estimate's
    arrival at the scorer: the values the scorer's summary aggregates into its RMSE and latency
    percentiles. The file is read-only to this command, so a running scorer may keep writing it.
    """
    from tltrack.live.scores import NotAScorerFileError, open_file, step_scores

    try:
        conn = open_file(db)
    except NotAScorerFileError as err:
        console.print(f"[red]error:[/red] --db: {err}")
        raise typer.Exit(2) from None
    n = 0
    try:
        with contextlib.closing(conn), _output(jsonl) as out:
            for score in step_scores(conn, episode):
                out.write(json.dumps(score.as_dict()) + "\n")
                n += 1
    except OSError as err:
        console.print(f"[red]error:[/red] --jsonl: cannot write {jsonl}: {err.strerror}")
        raise typer.Exit(2) from None
    except (sqlite3.DatabaseError, ValueError) as err:  # a damaged file, or a foreign row
        console.print(f"[red]error:[/red] --db: {db}: unreadable at its row {n + 1}: {err}")
        raise typer.Exit(2) from None
    if n == 0:
        what = f"episode {episode!r}" if episode else "any episode"
        console.print(f"[yellow]warning:[/yellow] {db} holds no estimate of {what}")
    console.print(f"wrote {n} lines to {'stdout' if str(jsonl) == '-' else jsonl}")


@contextlib.contextmanager
def _output(path: Path) -> Iterator[TextIO]:
    """``path`` opened for writing, or stdout for ``-``."""
    if str(path) == "-":
        yield sys.stdout
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w") as f:
        yield f
