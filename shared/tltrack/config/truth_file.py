"""Recorded tracks as ground truth: read a CSV track, put it in the sensors' frame, and make it a
truth trajectory x_0..x_K sampled every Ts.

Simulated truths come from the same motion model the filters assume, which flatters them. A
recorded track (a ship's AIS reports, a GPS log) moves the way real objects do: it speeds up,
turns when it likes, and is reported at irregular times. This module turns such a file into what
the engine needs: positions every Ts, and the full state (velocity, turn rate or acceleration) the
filters start from and that NEES and the PCRLB are computed along.

The pipeline, one function per step (:func:`load_truth` runs them all)::

    track = read_track(path)                    # validate the file; refuse it whole if bad
    reports, origin = to_local(track, origin)   # lat/lon -> east-north metres at an origin
    positions = resample(track.t, reports, Ts)  # (K + 1, 2), every Ts, by interpolation
    check_clearance(positions, {"primary": (0, 0), "s1": (0, 0)})  # no sensor on the track
    x = full_state(positions, Ts, "ct")         # (K + 1, n_x): the truth to score against

The file
--------
A CSV whose first line is the header ``t,x,y`` (t in seconds, x east and y north in metres) or
``t,lat,lon`` (degrees, WGS84). Every other line holds three finite numbers; blank lines may only
end the file. Times must strictly increase, but need not be regular and need not start at 0 (the
first report is t = 0 of the truth). Any of these refuses the whole file, naming the file and the
line: a missing or unknown header, a wrong number of fields, a value that is not a number or is
NaN or infinite, a time that does not increase, a latitude outside [-90, 90] or a longitude outside
[-180, 180], an x or y beyond 1e9 m (:mod:`tltrack.models.components`), a gap between consecutive
reports longer than ``max_gap_s`` (default 120 s: AIS reports come about every minute, and an
interpolation across minutes of silence would be invention, not truth), and fewer than 3 reports.

Resampling
----------
The reports are interpolated at t_k = k Ts, k = 0..K, with K = floor(duration / Ts): K follows the
file. A shorter K may be asked for (the track's first K Ts seconds); a longer one is refused,
since nothing is known past the last report. The default interpolant is a cubic spline through
the reports (SciPy's ``CubicSpline``, not-a-knot ends) on each coordinate: it passes through every
report, and its velocity and turn rate are continuous, as a real vessel's are. ``method="linear"``
joins the reports by straight segments instead; its heading then jumps at each report, and its
turn rate is a spike there and zero between.

The frame
---------
A ``t,x,y`` file is already in the sensors' frame. A ``t,lat,lon`` file is converted to local
east-north metres on the tangent plane of the WGS84 ellipsoid at an origin (the exact ENU
transform, via Earth-centred Cartesian coordinates, at height 0, keeping east and north and
dropping up). The sensors' positions are in this frame, so the origin is where a sensor at (0, 0)
sits.

- ``origin=(lat, lon)`` puts the frame there.
- Otherwise the origin is placed ``standoff_m`` (default 2 km) south-west (bearing 225 degrees) of
  the track's most south-westerly report, the one with the least east + north: that report sits
  at (1, 1) standoff_m / sqrt(2) in the frame, ``standoff_m`` from the origin, and every other
  report is farther, since all of them satisfy east + north >= sqrt(2) standoff_m (the far side
  of the line through that report square to the south-west). With no position configured, the
  primary sensor and every source sit at (0, 0), so **the default sensors end up 2 km south-west
  of the track's most south-westerly report**. The interpolated track between reports may bulge
  closer than the reports (by 37 m on the shipped example, at its first turn);
  :func:`check_clearance` judges the resampled positions, whatever the origin.

The error of the frame. Rotating Earth-centred coordinates into east-north-up is exact; dropping
"up" projects each point orthogonally onto the tangent plane. A point at ground distance s from
the origin lands at s' = R sin(s / R) ~ s - s^3 / (6 R^2), R ~ 6.37e6 m, in the right direction:
4 mm short at 10 km, 0.11 m at 30 km, 4 m at 100 km. Distances along the track shrink by a factor
cos(s / R) at most, ~1 - s^2 / (2 R^2): 1.2e-6 at 10 km, so speeds and turn rates are exact to a
few parts per million. Checked against GeographicLib's geodesics on the shipped example (reports
2-13 km from the origin): every report within 1 cm of its geodesic distance and azimuth from the
origin, every distance between consecutive reports within 1.5e-6. Heights are ignored: the frame
is the plane, and a sensor's range is measured in it (a real radar's slant range would also see
the Earth's curvature, a drop of s^2 / (2 R), 8 m at 10 km).

The full state
--------------
From the resampled positions p_k = (x_k, y_k), k = 0..K (K >= 2), every Ts:

- position: p_k;
- velocity by differences, second order everywhere (``numpy.gradient`` with ``edge_order=2``):
  v_k = (p_{k+1} - p_{k-1}) / (2 Ts) inside, v_0 = (-3 p_0 + 4 p_1 - p_2) / (2 Ts) and
  v_K = (3 p_K - 4 p_{K-1} + p_{K-2}) / (2 Ts) at the ends;
- acceleration (CA) by second differences: a_k = (p_{k+1} - 2 p_k + p_{k-1}) / Ts^2 inside,
  a_0 = a_1 and a_K = a_{K-1} at the ends;
- turn rate Omega (CT) from the heading rate: the heading psi_k = atan2(vy_k, vx_k) (the CT
  model's Omega > 0 turns counter-clockwise, as psi increases), and
  Omega_k = wrap(psi_{k+1} - psi_{k-1}) / (2 Ts) inside, wrap(psi_1 - psi_0) / Ts and
  wrap(psi_K - psi_{K-1}) / Ts at the ends, wrap to (-pi, pi]. Where the speed at any point of
  the difference is below ``min_speed`` (default 0.5 m/s) the heading is noise, so Omega is 0.

On a circle travelled at constant speed the central differences give the heading exactly, so
Omega is exact at k = 2..K-2 (k = 1 and K - 1 difference a one-sided end velocity); the speed
comes out as V sin(w Ts) / (w Ts), 2e-5 short for a ship turning at 0.01 rad/s with Ts = 1 s.
Through a spline of reports a minute apart, the error is the interpolation's: on a 1 km circle at
5 m/s reported every 30-90 s (tests/test_truth_file.py) positions are within 1 m, velocities
1.5%, Omega 10% at worst and 2% RMS.

Which components go where is a :class:`StateLayout` (``n``, ``pos``, ``vel``, and ``acc`` or
``turn_rate``), made from a motion model's declared components by :meth:`StateLayout.of` (``cv``
[x, vx, y, vy], ``ct`` [x, vx, y, vy, Omega], ``ca`` [x, vx, ax, y, vy, ay]): a new model's
layout follows from its own declaration.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from tltrack.config.schema import Config
from tltrack.models.angles import wrap_angle
from tltrack.models.components import MAX_MAGNITUDE
from tltrack.models.kinds import MOTIONS

Array = NDArray[np.float64]

#: the two headers a truth file may have
HEADERS: dict[tuple[str, ...], bool] = {("t", "x", "y"): False, ("t", "lat", "lon"): True}
DEFAULT_MAX_GAP_S = 120.0
DEFAULT_STANDOFF_M = 2000.0
DEFAULT_MIN_DISTANCE_M = 100.0

# WGS84
_A = 6378137.0
_F = 1.0 / 298.257223563
_E2 = _F * (2.0 - _F)


class TruthFileError(ValueError):
    """A truth file was refused. The message names the file, and the line or step at fault."""


@dataclass(frozen=True)
class Track:
    """The reports of a truth file, validated, as the file gives them.

    ``values`` is (M, 2): [x, y] in metres, or [lat, lon] in degrees when ``geographic``.
    ``lines`` holds each report's line number in the file (the header is line 1).
    """

    name: str
    sha256: str
    geographic: bool
    t: Array
    values: Array
    lines: NDArray[np.int64]


@dataclass(frozen=True)
class TruthTrack:
    """A truth file made a truth trajectory: positions every Ts, in the sensors' frame.

    ``origin`` is the (lat, lon) of the frame's (0, 0) for a geographic file, None for a metric
    one. ``reports`` are the file's reports in the frame, at times ``report_t`` (from 0).
    """

    name: str
    sha256: str
    Ts: float
    K: int
    positions: Array
    origin: tuple[float, float] | None
    reports: Array
    report_t: Array


@dataclass(frozen=True)
class StateLayout:
    """Where a state vector keeps each component :func:`full_state` derives.

    ``pos``, ``vel`` and ``acc`` are (x-index, y-index) pairs; ``turn_rate`` one index. Every
    index 0..n-1 must be filled exactly once, so no component is left for the caller to guess.
    """

    n: int
    pos: tuple[int, int]
    vel: tuple[int, int]
    acc: tuple[int, int] | None = None
    turn_rate: int | None = None

    def __post_init__(self) -> None:
        used = [
            *self.pos,
            *self.vel,
            *(self.acc or ()),
            *(() if self.turn_rate is None else (self.turn_rate,)),
        ]
        if sorted(used) != list(range(self.n)):
            raise ValueError(f"state layout {self} must fill indices 0..{self.n - 1} exactly once")

    @classmethod
    def of(cls, components: tuple[str, ...]) -> StateLayout:
        """The layout a motion model declares by its components' names (``x_m``, ``vx_mps``,
        ``ax_mps2``, ``omega_radps``...); a ValueError names what a truth file cannot fill."""
        at = {c: i for i, c in enumerate(components)}

        def pair(a: str, b: str) -> tuple[int, int] | None:
            return (at[a], at[b]) if a in at and b in at else None

        pos, vel = pair("x_m", "y_m"), pair("vx_mps", "vy_mps")
        if pos is None or vel is None:
            raise ValueError(f"a truth file fills x, y, vx, vy: the state {components} lacks some")
        return cls(len(components), pos, vel, pair("ax_mps2", "ay_mps2"), at.get("omega_radps"))


# ---------------------------------------------------------------------------------------- reading


def read_track(path: str | Path, max_gap_s: float = DEFAULT_MAX_GAP_S) -> Track:
    """Read and validate a truth file; any fault refuses it whole, naming the line.

    Raises :class:`TruthFileError`.
    """
    if not max_gap_s > 0:
        raise ValueError(f"max_gap_s must be positive, not {max_gap_s}")
    p = Path(path)
    name = str(path)
    try:
        raw = p.read_bytes()
    except OSError as err:
        raise TruthFileError(f"{name}: cannot read: {err.strerror}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise TruthFileError(f"{name}: not UTF-8 text (byte {err.start})") from None

    def fail(line: int, problem: str) -> TruthFileError:
        return TruthFileError(f"{name}: line {line}: {problem}")

    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()  # blank lines may end the file
    if not lines:
        raise fail(1, "empty file; expected the header 't,x,y' or 't,lat,lon'")
    header = tuple(c.strip().lower() for c in lines[0].split(","))
    if header not in HEADERS:
        raise fail(1, f"unknown header {lines[0].strip()!r}; expected 't,x,y' or 't,lat,lon'")
    geographic = HEADERS[header]

    rows: list[tuple[float, float, float]] = []
    numbers: list[int] = []
    for i, line in enumerate(lines[1:], start=2):
        if not line.strip():
            raise fail(i, "blank line inside the data")
        fields = line.split(",")
        if len(fields) != 3:
            raise fail(i, f"{len(fields)} fields; expected 3 ({','.join(header)})")
        row = []
        for column, field in zip(header, fields, strict=True):
            try:
                v = float(field)
            except ValueError:
                raise fail(i, f"{column} = {field.strip()!r} is not a number") from None
            if not math.isfinite(v):
                raise fail(i, f"{column} = {field.strip()} is not finite")
            row.append(v)
        t, a, b = row
        if geographic and not -90.0 <= a <= 90.0:
            raise fail(i, f"lat = {a} is outside [-90, 90]")
        if geographic and not -180.0 <= b <= 180.0:
            raise fail(i, f"lon = {b} is outside [-180, 180]")
        if not geographic and max(abs(a), abs(b)) > MAX_MAGNITUDE:
            raise fail(i, f"x, y = {a:g}, {b:g}: a coordinate beyond {MAX_MAGNITUDE:g} m")
        if rows:
            dt = t - rows[-1][0]
            if dt <= 0:
                raise fail(i, f"t = {t} does not increase (line {numbers[-1]} has {rows[-1][0]})")
            if dt > max_gap_s:
                raise fail(
                    i,
                    f"gap of {dt:g} s since line {numbers[-1]} is longer than the "
                    f"{max_gap_s:g} s allowed",
                )
        rows.append((t, a, b))
        numbers.append(i)
    if len(rows) < 3:
        raise fail(len(lines), f"{len(rows)} point(s); a track needs at least 3")
    data = np.array(rows, dtype=float)
    return Track(
        name=name,
        sha256=hashlib.sha256(raw).hexdigest(),
        geographic=geographic,
        t=data[:, 0],
        values=data[:, 1:],
        lines=np.array(numbers, dtype=np.int64),
    )


# -------------------------------------------------------------------------------------- the frame


def _ecef(lat_deg: Array, lon_deg: Array) -> Array:
    """Earth-centred Cartesian coordinates (3, ...) of points on the WGS84 ellipsoid (height 0)."""
    phi, lam = np.radians(lat_deg), np.radians(lon_deg)
    N = _A / np.sqrt(1.0 - _E2 * np.sin(phi) ** 2)
    return np.stack(
        [N * np.cos(phi) * np.cos(lam), N * np.cos(phi) * np.sin(lam), N * (1 - _E2) * np.sin(phi)]
    )


def _enu_rotation(lat0: float, lon0: float) -> Array:
    """Rows: the east, north and up unit vectors at (lat0, lon0), in Earth-centred coordinates."""
    phi, lam = math.radians(lat0), math.radians(lon0)
    sp, cp, sl, cl = math.sin(phi), math.cos(phi), math.sin(lam), math.cos(lam)
    return np.array([[-sl, cl, 0.0], [-sp * cl, -sp * sl, cp], [cp * cl, cp * sl, sp]])


def geodetic_to_local(lat: Array, lon: Array, origin: tuple[float, float]) -> Array:
    """East-north metres (..., 2) of WGS84 points on the tangent plane at ``origin`` (lat, lon).

    Exact ENU, up dropped; see the module docstring for the error this makes.
    """
    lat0, lon0 = origin
    d = _ecef(np.asarray(lat, dtype=float), np.asarray(lon, dtype=float))
    d = d - _ecef(np.asarray(lat0), np.asarray(lon0)).reshape((3,) + (1,) * (d.ndim - 1))
    enu = np.tensordot(_enu_rotation(lat0, lon0), d, axes=1)
    return np.moveaxis(enu[:2], 0, -1)


def local_to_geodetic(
    east: float, north: float, origin: tuple[float, float]
) -> tuple[float, float]:
    """The (lat, lon) that :func:`geodetic_to_local` maps to (east, north): its exact inverse.

    The point of the tangent plane is moved along the origin's "up" onto the ellipsoid (the
    projection is orthogonal, so that is the point that projects there), then read as (lat, lon).
    """
    rot = _enu_rotation(*origin)
    P = _ecef(np.asarray(origin[0]), np.asarray(origin[1])) + rot.T @ np.array([east, north, 0.0])
    U = rot[2]
    W = np.array([1.0, 1.0, 1.0 / (1.0 - _E2)]) / _A**2  # the ellipsoid: X' W X = 1
    qa, qb, qc = float(U @ (W * U)), 2.0 * float(P @ (W * U)), float(P @ (W * P)) - 1.0
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0:
        raise ValueError(f"({east}, {north}) m from {origin} is off the Earth")
    roots = ((-qb + math.sqrt(disc)) / (2 * qa), (-qb - math.sqrt(disc)) / (2 * qa))
    X, Y, Z = P + min(roots, key=abs) * U
    # on the ellipsoid's surface, tan(lat) = Z / ((1 - e^2) sqrt(X^2 + Y^2)) exactly
    lat = math.atan2(Z, (1.0 - _E2) * math.hypot(X, Y))
    return math.degrees(lat), math.degrees(math.atan2(Y, X))


def default_origin(track: Track, standoff_m: float = DEFAULT_STANDOFF_M) -> tuple[float, float]:
    """The (lat, lon) ``standoff_m`` south-west of a geographic track's most south-westerly report.

    So a sensor left at (0, 0) sits that far from the track (module docstring, "The frame").
    """
    if not track.geographic:
        raise ValueError(f"{track.name}: a metric (t,x,y) track has no geographic origin")
    if not (math.isfinite(standoff_m) and standoff_m > 0):
        raise ValueError(f"standoff_m must be positive and finite, not {standoff_m}")
    lat, lon = track.values[:, 0], track.values[:, 1]
    origin = (float(lat[0]), float(lon[0]))
    step = standoff_m / math.sqrt(2.0)
    # "south-west" turns with the frame (meridians converge), so repeat in the new origin's own
    # frame until the most south-westerly report sits at (step, step) there: two or three passes
    for _ in range(8):
        local = geodetic_to_local(lat, lon, origin)
        sw = local[np.argmin(local[:, 0] + local[:, 1])]
        if abs(sw[0] - step) < 1e-7 and abs(sw[1] - step) < 1e-7:
            break
        origin = local_to_geodetic(float(sw[0] - step), float(sw[1] - step), origin)
    return origin


def to_local(
    track: Track,
    origin: tuple[float, float] | None = None,
    standoff_m: float = DEFAULT_STANDOFF_M,
) -> tuple[Array, tuple[float, float] | None]:
    """The reports in the sensors' frame (M, 2), and the frame's (lat, lon) origin if geographic.

    A metric track is returned as it is; giving it an origin is refused, since it has no latitude
    to put it at.
    """
    if not track.geographic:
        if origin is not None:
            raise TruthFileError(f"{track.name}: an origin applies only to a t,lat,lon file")
        return track.values.copy(), None
    if origin is None:
        origin = default_origin(track, standoff_m)
    else:
        lat0, lon0 = (float(v) for v in origin)
        if not (math.isfinite(lat0) and math.isfinite(lon0)):
            raise TruthFileError(f"{track.name}: origin {origin} is not finite")
        if not (-90.0 <= lat0 <= 90.0 and -180.0 <= lon0 <= 180.0):
            raise TruthFileError(f"{track.name}: origin {origin} is not a (lat, lon) in degrees")
        origin = (lat0, lon0)
    return geodetic_to_local(track.values[:, 0], track.values[:, 1], origin), origin


# ------------------------------------------------------------------------------------- resampling


def resample(
    t: Array,
    points: Array,
    Ts: float,
    K: int | None = None,
    method: Literal["cubic", "linear"] = "cubic",
    name: str = "truth file",
) -> Array:
    """Positions (K + 1, 2) at t_0 + k Ts, k = 0..K, interpolated through the reports.

    K defaults to the file's floor(duration / Ts); a smaller K shortens the track, a larger one
    is refused (nothing is known past the last report). Needs K >= 2, for the differences of
    :func:`full_state`.
    """
    if not (math.isfinite(Ts) and Ts > 0):
        raise ValueError(f"Ts must be positive and finite, not {Ts}")
    rel = np.asarray(t, dtype=float) - float(t[0])
    duration = float(rel[-1])
    k_file = math.floor(duration / Ts + 1e-9)
    if K is None:
        K = k_file
    elif k_file < K:
        raise TruthFileError(
            f"{name}: K = {K} steps of {Ts:g} s is longer than the track "
            f"({duration:g} s, at most K = {k_file})"
        )
    if K < 2:
        raise TruthFileError(
            f"{name}: {K + 1} sample(s) of {Ts:g} s over {min(duration, K * Ts):g} s; need K >= 2"
        )
    tk = np.minimum(np.arange(K + 1) * Ts, duration)  # the last sample never extrapolates
    if method == "cubic":
        from scipy.interpolate import CubicSpline  # on first use: every service loads this module

        return np.asarray(CubicSpline(rel, points, axis=0, bc_type="not-a-knot")(tk))
    if method == "linear":
        return np.stack([np.interp(tk, rel, points[:, j]) for j in range(2)], axis=1)
    raise ValueError(f"unknown interpolation method {method!r}; expected 'cubic' or 'linear'")


# -------------------------------------------------------------------------------------- clearance


def check_clearance(
    positions: Array,
    sensors: Mapping[str, tuple[float, float]],
    min_distance: float = DEFAULT_MIN_DISTANCE_M,
    name: str = "truth track",
) -> None:
    """Refuse a track that passes within ``min_distance`` of a sensor, naming it and the step.

    Range-bearing geometry degenerates on top of a sensor (the bearing of a target 10 m away
    swings by radians per step), so a truth there measures the geometry, not the filters.
    """
    pos = np.asarray(positions, dtype=float)
    for sensor_name, (sx, sy) in sensors.items():
        d = np.hypot(pos[:, 0] - sx, pos[:, 1] - sy)
        close = np.flatnonzero(d < min_distance)
        if close.size:
            k = int(close[0])
            raise TruthFileError(
                f"{name}: sensor {sensor_name!r} at ({sx:g}, {sy:g}) is {d[k]:.1f} m from the "
                f"track at step {k} (at least {min_distance:g} m required; closest "
                f"{d.min():.1f} m at step {int(np.argmin(d))})"
            )


# ------------------------------------------------------------------------------------- full state


def full_state(
    positions: Array,
    Ts: float,
    layout: StateLayout | str,
    min_speed: float = 0.5,
) -> Array:
    """The true states (K + 1, n) along resampled positions (K + 1, 2); formulas in the docstring.

    ``layout`` is a :class:`StateLayout` or a registered motion model's kind ("cv", "ct", "ca").
    """
    lay = StateLayout.of(MOTIONS.get(layout).components) if isinstance(layout, str) else layout
    p = np.asarray(positions, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3:
        raise ValueError(f"positions must be (K + 1, 2) with K >= 2, not {p.shape}")
    v = np.gradient(p, Ts, axis=0, edge_order=2)
    x = np.zeros((p.shape[0], lay.n))
    x[:, lay.pos] = p
    x[:, lay.vel] = v
    if lay.acc is not None:
        a = np.empty_like(p)
        a[1:-1] = (p[2:] - 2.0 * p[1:-1] + p[:-2]) / Ts**2
        a[0], a[-1] = a[1], a[-2]
        x[:, lay.acc] = a
    if lay.turn_rate is not None:
        x[:, lay.turn_rate] = _turn_rate(v, Ts, min_speed)
    return x


def _turn_rate(v: Array, Ts: float, min_speed: float) -> Array:
    """Omega_k from differences of the heading atan2(vy, vx); 0 where the speed is below min."""
    psi = np.arctan2(v[:, 1], v[:, 0])
    moving = np.hypot(v[:, 0], v[:, 1]) >= min_speed
    w = np.empty(len(psi))
    w[1:-1] = wrap_angle(psi[2:] - psi[:-2]) / (2.0 * Ts)
    w[0] = wrap_angle(psi[1] - psi[0]) / Ts
    w[-1] = wrap_angle(psi[-1] - psi[-2]) / Ts
    ok = moving.copy()
    ok[1:-1] = moving[2:] & moving[:-2]
    ok[0] = moving[0] & moving[1]
    ok[-1] = moving[-1] & moving[-2]
    return np.where(ok, w, 0.0)


# --------------------------------------------------------------------------------------- together


def load_truth(
    path: str | Path,
    Ts: float,
    K: int | None = None,
    origin: tuple[float, float] | None = None,
    max_gap_s: float = DEFAULT_MAX_GAP_S,
    standoff_m: float = DEFAULT_STANDOFF_M,
    method: Literal["cubic", "linear"] = "cubic",
) -> TruthTrack:
    """Read, convert and resample a truth file; raises :class:`TruthFileError`.

    The sensors are not checked here (the caller knows them): pass ``positions`` to
    :func:`check_clearance`, then to :func:`full_state` for the states.
    """
    track = read_track(path, max_gap_s)
    reports, frame_origin = to_local(track, origin, standoff_m)
    positions = resample(track.t, reports, Ts, K, method, track.name)
    return TruthTrack(
        name=Path(path).name,
        sha256=track.sha256,
        Ts=float(Ts),
        K=positions.shape[0] - 1,
        positions=positions,
        origin=frame_origin,
        reports=reports,
        report_t=track.t - track.t[0],
    )


# ---------------------------------------------------------------------------------- configuring


def file_truth(cfg: Config) -> Array:
    """The truth x_0..x_K (K + 1, n_x) of a config whose truth is a file (see
    :func:`tltrack.config.load.complete_from_truth_file`).

    Refuses a config whose x0 is not the track's first state: it was not completed by
    :func:`~tltrack.config.load.complete_from_truth_file`, and its filters would start somewhere
    else.
    """
    x = track_states(cfg, recorded_track(cfg))
    if len(x) < cfg.K + 1:
        raise TruthFileError(f"{cfg.truth_file}: K = {cfg.K} is longer than the track")
    if not np.allclose(x[0], cfg.x0, rtol=1e-9, atol=1e-9):
        raise TruthFileError(
            f"{cfg.truth_file}: the config's x0 is not the track's first state; build the config "
            "with tltrack.config.truth_file.configure"
        )
    return x[: cfg.K + 1]


def recorded_track(cfg: Config) -> TruthTrack:
    """The recorded track of a config whose truth is a file."""
    if cfg.truth_file is None:
        raise ValueError("this configuration's truth is not a file")
    return _load(str(cfg.truth_file), cfg.Ts, cfg.truth_origin, cfg.truth_max_gap_s)


@lru_cache(maxsize=8)
def _load(path: str, Ts: float, origin: tuple[float, float] | None, max_gap_s: float) -> TruthTrack:
    return load_truth(path, Ts, origin=origin, max_gap_s=max_gap_s)


def track_states(cfg: Config, track: TruthTrack) -> Array:
    return full_state(track.positions, cfg.Ts, cfg.scenario)
