"""Simulated manoeuvring targets, as recorded tracks (CSV ``t,x,y``) for ``--truth-file``.

- :func:`turn_sequence`: straight legs and turns at stated rates, at constant speed (the
  manoeuvre study's sequence: a stated one, in the manner of the Blair-Watson benchmark tracks);
- :func:`circling_aircraft`: a light aircraft circling at constant airspeed and bank in a steady
  wind, so that its ground speed swings through each circle, as an ADS-B track of one does.

Both start far enough from the sensors at the origin that every sensor sees them (the truth file's
clearance check).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: the stated sequence: (seconds, turn rate in deg/s): straight, a hard right turn, straight, a
#: left turn back, straight, a gentle turn, straight
SEQUENCE: tuple[tuple[float, float], ...] = (
    (60.0, 0.0),
    (30.0, -6.0),
    (40.0, 0.0),
    (45.0, 4.0),
    (60.0, 0.0),
    (60.0, 1.5),
    (60.0, 0.0),
)


def turn_sequence(
    legs: Sequence[tuple[float, float]] = SEQUENCE,
    speed: float = 150.0,
    report: float = 1.0,
    start: tuple[float, float] = (6000.0, -4000.0),
    heading_deg: float = 120.0,
) -> tuple[Array, Array, Array]:
    """(t, x, y) of a target at ``speed`` m/s through ``legs`` of (seconds, turn rate deg/s),
    reported every ``report`` seconds."""
    t = np.arange(0.0, sum(d for d, _ in legs) + 1e-9, report)
    ends = np.cumsum([d for d, _ in legs])
    rates = np.deg2rad([r for _, r in legs])
    fine = np.arange(0.0, t[-1] + 1e-9, 0.01)  # integrate the heading finely, then sample
    leg = np.minimum(np.searchsorted(ends, fine, side="right"), len(legs) - 1)
    heading = np.deg2rad(heading_deg) + np.concatenate([[0.0], np.cumsum(rates[leg[:-1]] * 0.01)])
    vx, vy = speed * np.cos(heading), speed * np.sin(heading)
    x = start[0] + np.concatenate([[0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]) * 0.01)])
    y = start[1] + np.concatenate([[0.0], np.cumsum(0.5 * (vy[1:] + vy[:-1]) * 0.01)])
    at = np.rint(t / 0.01).astype(int)
    return t, x[at], y[at]


def circling_aircraft(
    duration: float = 600.0,
    report: float = 5.0,
    airspeed: float = 92.5,
    turn_deg_s: float = 5.0,
    wind: tuple[float, float] = (42.0, 20.0),
    start: tuple[float, float] = (-12500.0, -3000.0),
) -> tuple[Array, Array, Array]:
    """(t, x, y) of an aircraft turning at ``turn_deg_s`` through the air at ``airspeed``, carried
    by ``wind`` (m/s): ground speed airspeed - |wind| .. airspeed + |wind| through each circle
    (46-139 m/s by default, as the ADS-B track of a circling light aircraft that every filter
    lost with the paper's noise). It drifts past the sensors at the origin, 3 km away at most."""
    t = np.arange(0.0, duration + 1e-9, report)
    w = np.deg2rad(turn_deg_s)
    psi = w * t
    x = start[0] + airspeed / w * np.sin(psi) + wind[0] * t
    y = start[1] + airspeed / w * (1.0 - np.cos(psi)) + wind[1] * t
    return t, x, y


def write_csv(path: Path, t: Array, x: Array, y: Array) -> Path:
    """A truth file ``t,x,y`` (seconds, metres)."""
    rows = "".join(f"{a:.3f},{b:.3f},{c:.3f}\n" for a, b, c in zip(t, x, y, strict=True))
    path.write_text("t,x,y\n" + rows)
    return path
