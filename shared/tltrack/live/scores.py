"""Each filter's score at each step, from the scorer's SQLite file: its position error against
the truth, its latency, and whether it used a transfer; and the estimates themselves.

The scorer's summary aggregates the scores (``tltrack.services.scorer.summary``: the RMSE over
episodes, the latency's percentiles); ``tltrack scores --jsonl`` writes them one by one, for a
notebook. Both compute them with :func:`squared_error` and
:func:`tltrack.live.latency.end_to_end_ms`, so a line of the file and the summary agree to the
last bit: ``error_m`` at k is the root of what the RMSE averages at k. :func:`estimates` reads an
episode's estimates, which ``tltrack scores --estimates`` writes as the ``estimates.csv`` of
``tltrack track`` (and ``tltrack.interop.stonesoup.to_tracks`` makes Stone Soup tracks of).

:func:`open_file` opens the file read-only, so that reading it beside a running scorer changes
nothing in it (SQLite's WAL lets a reader in while the scorer writes).
"""

from __future__ import annotations

import json
import math
import sqlite3
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tltrack.live import latency
from tltrack.models.components import MAX_MAGNITUDE

if TYPE_CHECKING:  # the scorer imports this module: none of the engine at run time
    from tltrack.engine.track import Estimated

#: the columns read here, of the tables of ``tltrack.services.scorer.store``
COLUMNS = {
    "episodes": ("episode", "started", "config"),
    "truth": ("episode", "k", "pos"),
    "estimates": ("episode", "filter", "k", "pos", "x", "P", "transfer_used", "t_sensor", "t_recv"),
}


class NotAScorerFileError(ValueError):
    """The file is missing, not SQLite, or not the scorer's; the message says which."""


def squared_error(pos: Sequence[float], truth: Sequence[float]) -> float:
    """The squared distance between an estimated and a true position (m²), as the RMSE takes it."""
    dx, dy = pos[0] - truth[0], pos[1] - truth[1]
    return dx**2 + dy**2  # ** as NumPy's scalars square: the summary's RMSE, bit for bit


def _position(text: str) -> list[float]:
    """A stored position, or ValueError: a damaged or foreign row must not end in a traceback."""
    pos = _json(text, "a position")  # takes NaN and Infinity, which no message carries
    numbers = isinstance(pos, list) and all(
        isinstance(v, int | float) and not isinstance(v, bool) and abs(v) <= MAX_MAGNITUDE
        for v in pos
    )  # NaN fails the bound; beyond it, no message carries one and its square may overflow
    if not (numbers and len(pos) == 2):
        raise ValueError(f"a position is two numbers within 1e9 m, not {text[:40]!r}")
    return pos


def _json(text: object, what: str) -> Any:
    """A stored JSON cell, or ValueError (a NULL, or text that is no JSON)."""
    if not isinstance(text, str | bytes):
        raise ValueError(f"{what} is {text!r}, not JSON text")
    return json.loads(text)  # json.JSONDecodeError is a ValueError


def _time(t: object, what: str) -> float:
    """A stored time (s), or ValueError (a NULL, or no number)."""
    if isinstance(t, bool) or not isinstance(t, int | float):
        raise ValueError(f"{what} is {t!r}, not a time")
    return float(t)


@dataclass(frozen=True)
class StepScore:
    """One filter at one step of one episode."""

    episode: str
    filter: str
    k: int
    error_m: float | None  #: None: no truth at k (a replay without one)
    latency_ms: float
    transfer_used: bool

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def open_file(path: Path) -> sqlite3.Connection:
    """The scorer's file at ``path``, read-only; :class:`NotAScorerFileError` otherwise."""
    if path.is_dir():
        raise NotAScorerFileError(f"{path}: a folder, not the scorer's file")
    if not path.is_file():
        raise NotAScorerFileError(f"{path}: no such file")
    try:
        db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)
        found = {t: {row[1] for row in db.execute(f"PRAGMA table_info({t})")} for t in COLUMNS}
    except sqlite3.DatabaseError as err:
        raise NotAScorerFileError(f"{path}: not an SQLite database ({err})") from None
    missing = [f"{t}.{c}" for t, cols in COLUMNS.items() for c in cols if c not in found[t]]
    if missing:
        db.close()
        raise NotAScorerFileError(
            f"{path}: not a scorer's database (no {', '.join(missing)}); the scorer writes one "
            "where TLTRACK_SCORER_DB says, `tltrack demo` in out/demo/scorer.sqlite"
        )
    return db


def scored_episodes(db: sqlite3.Connection) -> list[str]:
    """The episodes the file holds estimates of, in the order they started."""
    rows = db.execute(
        "SELECT e.episode FROM estimates e LEFT JOIN episodes s ON s.episode = e.episode"
        " GROUP BY e.episode ORDER BY min(s.started), e.episode"
    )
    return [e for (e,) in rows]


def step_scores(db: sqlite3.Connection, episode: str | None = None) -> Iterator[StepScore]:
    """Every estimate's score, by episode (in the order they started), filter and step; only
    ``episode``'s if given."""
    rows = db.execute(
        "SELECT e.episode, e.filter, e.k, e.pos, t.pos, e.t_sensor, e.t_recv, e.transfer_used"
        " FROM estimates e"
        " LEFT JOIN truth t ON t.episode = e.episode AND t.k = e.k"
        " LEFT JOIN episodes s ON s.episode = e.episode"
        " WHERE ?1 IS NULL OR e.episode = ?1"
        " ORDER BY s.started, e.episode, e.filter, e.k",
        (episode,),
    )
    for ep, name, k, pos, truth, t_sensor, t_recv, used in rows:
        error = None
        if pos is not None and truth is not None:
            error = math.sqrt(squared_error(_position(pos), _position(truth)))
        delay = latency.end_to_end_ms(_time(t_sensor, "t_sensor"), _time(t_recv, "t_recv"))
        yield StepScore(ep, name, k, error, delay, bool(used))


def estimates(db: sqlite3.Connection, episode: str | None = None) -> tuple[str, list[Estimated]]:
    """The motion model (``scenario``) of one episode's config and its every estimate
    (k, filter, mean, covariance), by step and filter. ``episode`` may be left out when the file
    holds one; ValueError naming the episodes otherwise, or when a state does not fit the model."""
    from tltrack.models.kinds import MOTIONS

    held = [e for (e,) in db.execute("SELECT episode FROM episodes ORDER BY started, episode")]
    if episode is None:
        if len(held) != 1:
            raise ValueError(f"name one episode (--episode) of the {len(held)} held: {held}")
        episode = held[0]
    row = db.execute("SELECT config FROM episodes WHERE episode = ?", (episode,)).fetchone()
    if row is None:
        raise ValueError(f"no episode {episode!r} (held: {held})")
    config = json.loads(row[0])
    scenario = config.get("scenario") if isinstance(config, dict) else None
    if not isinstance(scenario, str):
        raise ValueError(f"episode {episode!r}: its config names no motion model (scenario)")
    n_x = len(MOTIONS.get(scenario).components)
    out: list[Estimated] = []
    query = "SELECT k, filter, x, P FROM estimates WHERE episode = ? ORDER BY k, filter"
    for k, name, x, P in db.execute(query, (episode,)):
        mean = np.asarray(_json(x, f"{name}'s x at k = {k}"), dtype=float)
        cov = np.asarray(_json(P, f"{name}'s P at k = {k}"), dtype=float)
        if mean.shape != (n_x,) or cov.shape != (n_x, n_x):
            raise ValueError(
                f"{name} at k = {k}: a state of shape {mean.shape} and a covariance of "
                f"{cov.shape}, not {scenario}'s ({n_x},) and ({n_x}, {n_x})"
            )
        out.append((k, name, mean, cov))
    return scenario, out
