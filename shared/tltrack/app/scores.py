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

from tltrack.app.common import app, console, say_error, say_warning


@app.command(
    epilog="Examples:\n\n    tltrack scores --jsonl scores.jsonl\n\n"
    "    tltrack scores --jsonl - --db scorer.sqlite --episode ep-r0 | jq .error_m"
)
def scores(
    jsonl: Annotated[
        Path | None, typer.Option(help="the JSON Lines file to write ('-': stdout)")
    ] = None,
    db: Annotated[
        Path,
        typer.Option(
            envvar="TLTRACK_SCORER_DB", help="the scorer's SQLite file (`tltrack demo` writes this)"
        ),
    ] = Path("out/demo/scorer.sqlite"),
    episode: Annotated[str | None, typer.Option(help="only this episode")] = None,
    estimates: Annotated[
        Path | None,
        typer.Option(help="write the episode's estimates here, as `tltrack track`'s estimates.csv"),
    ] = None,
) -> None:
    """Write one JSON object per filter and step: episode, filter, k, error_m, latency_ms,
    transfer_used.

    `error_m` is the distance between the estimate's position and the truth's at k (null without
    a truth), `latency_ms` the time from the sensor's publication of z_k to the estimate's
    arrival at the scorer: the values the scorer's summary aggregates into its RMSE and latency
    percentiles. The file is read-only to this command, so a running scorer may keep writing it.

    `--estimates` writes one episode's estimates (`--episode`, needed when the file holds
    several) in the CSV of `tltrack track`: k, filter, the state's components, the position's
    covariance.
    """
    from tltrack.live.scores import NotAScorerFileError, open_file, scored_episodes

    if jsonl is None and estimates is None:
        say_error("say what to write: --jsonl FILE, --estimates FILE, or both")
        raise typer.Exit(2)
    try:
        conn = open_file(db)
    except NotAScorerFileError as err:
        say_error(f"--db: {err}")
        raise typer.Exit(2) from None
    with contextlib.closing(conn):
        try:
            held = scored_episodes(conn)
        except sqlite3.DatabaseError as err:
            say_error(f"--db: {db}: {err}")
            raise typer.Exit(2) from None
        if episode is not None and episode not in held:  # before any file is written
            say_error(f"--episode: {db} holds no estimate of episode {episode!r} (it has {held})")
            raise typer.Exit(2)
        if estimates is not None:
            _write_estimates(conn, db, episode, estimates)
        if jsonl is not None:
            _write_jsonl(conn, db, episode, jsonl)


def _write_estimates(conn: sqlite3.Connection, db: Path, episode: str | None, path: Path) -> None:
    from tltrack.engine.track import write_estimates
    from tltrack.live.scores import estimates

    try:
        scenario, rows = estimates(conn, episode)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_estimates(path, scenario, rows)
    except OSError as err:
        say_error(f"--estimates: cannot write {path}: {err.strerror}")
        raise typer.Exit(2) from None
    except (sqlite3.DatabaseError, ValueError, KeyError, TypeError) as err:  # a cell of no state
        say_error(f"--db: {db}: {err}")
        raise typer.Exit(2) from None
    console.print(f"wrote {len(rows)} estimates to {path}")


def _write_jsonl(conn: sqlite3.Connection, db: Path, episode: str | None, jsonl: Path) -> None:
    from tltrack.live.scores import step_scores

    n = 0
    try:
        with _output(jsonl) as out:
            for score in step_scores(conn, episode):
                out.write(json.dumps(score.as_dict()) + "\n")
                n += 1
    except OSError as err:
        say_error(f"--jsonl: cannot write {jsonl}: {err.strerror}")
        raise typer.Exit(2) from None
    except (sqlite3.DatabaseError, ValueError) as err:  # a damaged file, or a foreign row
        say_error(f"--db: {db}: unreadable at its row {n + 1}: {err}")
        raise typer.Exit(2) from None
    if n == 0:
        say_warning(f"{db} holds no estimate yet")
    console.print(f"wrote {n} lines to {'stdout' if str(jsonl) == '-' else jsonl}")


@contextlib.contextmanager
def _output(path: Path) -> Iterator[TextIO]:
    """``path`` opened for writing, or stdout for ``-``. A regular file appears whole or not at
    all: a row that cannot be read leaves no half-written file (nor clobbers an older one). A
    device, a pipe or a link (``/dev/stdout``, ``>(gzip ...)``) is written through as it is."""
    if str(path) == "-":
        yield sys.stdout
        return
    if path.is_symlink() or (path.exists() and not path.is_file()):
        with path.open("w") as f:
            yield f
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    part = path.with_name(f".{path.name}.part")
    try:
        with part.open("w") as f:
            yield f
        part.replace(path)
    finally:
        part.unlink(missing_ok=True)
