"""tltrack's estimates as Stone Soup tracks, and Stone Soup tracks as tltrack's estimates.csv.

An estimate is (k, filter, mean, covariance), as :class:`tltrack.engine.track.Tracks` collects
them (``tltrack track``, the engine's collectors). Step k is at ``start + k * period``: Stone Soup
keys a state by its time, tltrack by its step. Each filter becomes one
:class:`~stonesoup.types.track.Track` of Gaussian states, whose ``id`` is the filter's name, so
Stone Soup's metrics and plotters take tltrack's results; :func:`write_csv` writes Stone Soup
tracks in the CSV ``tltrack track`` writes, so tltrack's readers take Stone Soup's.
"""

from __future__ import annotations

import datetime
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
from stonesoup.types.array import CovarianceMatrix, StateVector
from stonesoup.types.state import GaussianState
from stonesoup.types.track import Track

from tltrack.engine.track import Estimated, write_estimates


def to_tracks(
    estimates: Iterable[Estimated], *, start: datetime.datetime, period: datetime.timedelta
) -> dict[str, Track]:
    """One Stone Soup track per filter of ``estimates``, in step order."""
    states: dict[str, list[tuple[int, GaussianState]]] = {}
    for k, name, x, P in estimates:
        state = GaussianState(
            StateVector(np.asarray(x, dtype=float)),
            CovarianceMatrix(np.asarray(P, dtype=float)),
            timestamp=start + k * period,
        )
        states.setdefault(name, []).append((k, state))
    return {
        name: Track([s for _, s in sorted(rows, key=lambda r: r[0])], id=name)
        for name, rows in states.items()
    }


def from_tracks(
    tracks: Mapping[str, Track], *, start: datetime.datetime, period: datetime.timedelta
) -> list[Estimated]:
    """The estimates of Stone Soup tracks (by filter name), whose states carry a covariance and
    a time a whole number of periods after ``start`` (its step k, within a tenth of a period),
    one per step; else a ValueError naming the state (one without, or off the grid, made a
    rounded duplicate)."""
    out: list[Estimated] = []
    for name, track in tracks.items():
        seen: set[int] = set()
        for i, state in enumerate(track.states):
            where = f"{name}'s state {i} ({state.timestamp})"
            if state.timestamp is None or not hasattr(state, "covar"):
                raise ValueError(f"{where}: an estimate has a time and a covariance")
            steps = (state.timestamp - start) / period
            k = round(steps)
            if abs(steps - k) > 0.1:  # datetime's microseconds: 1/30 s is 33333 us, and drifts
                raise ValueError(f"{where}: not a whole number of periods {period} after {start}")
            if k in seen:
                raise ValueError(f"{where}: a second state at step {k}")
            seen.add(k)
            x = np.asarray(state.state_vector, dtype=float)[:, 0]
            out.append((k, name, x, np.asarray(state.covar, dtype=float)))
    return sorted(out, key=lambda r: (r[0], r[1]))


def write_csv(
    path: Path,
    tracks: Mapping[str, Track],
    *,
    scenario: str,
    start: datetime.datetime,
    period: datetime.timedelta,
) -> None:
    """Stone Soup tracks of states of the motion model ``scenario`` (its components' order), as
    ``tltrack track``'s estimates.csv."""
    write_estimates(path, scenario, from_tracks(tracks, start=start, period=period))
