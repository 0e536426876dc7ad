"""Process noise fitted to recorded tracks, by maximum likelihood on the raw reports.

A recorded track's reports are noisy positions at their own times t_1 < t_2 < ... (not the
resampled spline the truth is made of). Under a motion model with noise parameters theta and
reports of noise sigma (per axis), a Kalman filter run over the reports, each prediction over its
own interval (F(dt), Q(dt): :meth:`~tltrack.models.base.MotionModel.with_period`), gives the
likelihood of the reports as the product of its innovations' densities (the prediction error
decomposition; Harvey 1989, sec. 3.4). :func:`fit` maximises it over (theta, sigma) on every
track at once.

- ``cv``: q1 of the constant-velocity model (a linear Kalman filter);
- ``ct``: q1 and q2 of the coordinated turn (an unscented filter);
- ``modes``: a straight mode (q1) and a turning mode (q1, q2) with the rate lambda at which the
  target switches between them, so that over an interval dt the chain switches with probability
  (1 - exp(-2 lambda dt)) / 2 (an interacting multiple-model filter of unscented filters);
- ``manoeuvres``: those two and a manoeuvring mode (a coordinated turn with its own, larger,
  q1 and q2), each left at the rate lambda for either other alike (the chain exp(G dt):
  :func:`~tltrack.config.target_classes.transition`).

The 95% confidence interval of the cv fit is the likelihood ratio's: the values whose profile
log-likelihood lies within chi2_1(0.95) / 2 of the maximum (Pawitan 2001, sec. 2.6), read off a
grid; the others' is Wald's in log-space, from the observed information (the likelihood then costs
a filter pass per evaluation). The first two reports start the filter (position, and velocity by
difference); the likelihood is of every report after them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize
from scipy.stats import chi2, norm

from tltrack.config.target_classes import transition, uniform_rates
from tltrack.filters.imm import InteractingMultipleModel
from tltrack.filters.sigma_point import SigmaPointFilter, unscented
from tltrack.models.base import Layout, MotionModel
from tltrack.models.constant_velocity import ConstantVelocity
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.modes import Straight
from tltrack.models.observation import Observation
from tltrack.models.position import Position

Array = NDArray[np.float64]
Kind = Literal["cv", "ct", "modes", "manoeuvres"]

#: what each kind fits, in order (log-space for the optimiser); sigma is the reports' noise
PARAMETERS: dict[str, tuple[str, ...]] = {
    "cv": ("q1", "sigma"),
    "ct": ("q1", "q2", "sigma"),
    "modes": ("q1_straight", "q1_turn", "q2_turn", "switch_rate", "sigma"),
    "manoeuvres": (
        "q1_straight",
        "q1_turn",
        "q2_turn",
        "q1_manoeuvre",
        "q2_manoeuvre",
        "switch_rate",
        "sigma",
    ),
}
#: starting values (SI: m^2/s^4, rad^2/s^3, m, 1/s)
START = {
    "q1": 1.0,
    "q2": 1e-4,
    "sigma": 10.0,
    "q1_straight": 0.1,
    "q1_turn": 1.0,
    "q2_turn": 1e-4,
    "q2_manoeuvre": 1e-3,
    "switch_rate": 0.01,
}
#: the prior spread of the turn rate when a filter starts (rad/s): 5 deg/s
OMEGA0_SD = math.radians(5.0)


@dataclass(frozen=True)
class Reports:
    """One track's reports: times (M,) in seconds and positions (M, 2) in metres."""

    name: str
    t: Array
    xy: Array

    def __post_init__(self) -> None:
        if len(self.t) < 4 or np.any(np.diff(self.t) <= 0):
            raise ValueError(f"{self.name}: a fit needs 4 or more reports at increasing times")


@dataclass
class Fit:
    """What :func:`fit` found: each parameter's estimate and 95% interval, the maximised
    log-likelihood, and what it was fitted on."""

    kind: str
    values: dict[str, float]
    intervals: dict[str, tuple[float, float]]
    loglik: float
    reports: int
    tracks: list[str] = field(default_factory=list)


# ---- the likelihood ----------------------------------------------------------------------------


def _start(r: Reports, n: int, layout: Layout, sigma: float) -> tuple[Array, Array]:
    """x at the second report (position, velocity by difference; Omega 0), and its P."""
    dt = r.t[1] - r.t[0]
    v = (r.xy[1] - r.xy[0]) / dt
    x = np.zeros(n)
    x[list(layout.pos)], x[list(layout.vel)] = r.xy[1], v
    P = np.zeros((n, n))
    for i, j in zip(layout.pos, layout.vel, strict=True):
        P[i, i] = sigma**2
        P[i, j] = P[j, i] = sigma**2 / dt
        P[j, j] = 2.0 * sigma**2 / dt**2 + 25.0  # + (5 m/s)^2: the speed may change between
    if n == 5:
        P[4, 4] = OMEGA0_SD**2
    return x, P


def _cv_loglik(tracks: Sequence[Reports], q1: Array, sigma: Array) -> Array:
    """The log-likelihood under CV of every track, for each of P parameter pairs (P,)."""
    out = np.zeros(len(q1))
    layout = ConstantVelocity.layout
    for r in tracks:
        x0, _ = _start(r, 4, layout, 1.0)
        m = np.repeat(x0[:, None], len(q1), axis=1)  # (4, P)
        P = np.stack([_start(r, 4, layout, s)[1] for s in sigma])  # (P, 4, 4)
        H = np.zeros((2, 4))
        H[0, 0] = H[1, 2] = 1.0
        for k in range(2, len(r.t)):
            model = ConstantVelocity(T=float(r.t[k] - r.t[k - 1]), q=1.0)
            m = model.A @ m
            P = model.A @ P @ model.A.T + q1[:, None, None] * model.Q
            S = H @ P @ H.T + sigma[:, None, None] ** 2 * np.eye(2)
            nu = r.xy[k][:, None] - H @ m  # (2, P)
            Sinv = np.linalg.inv(S)
            out += -0.5 * (
                np.einsum("ip,pij,jp->p", nu, Sinv, nu)
                + np.log(np.linalg.det(S))
                + 2.0 * math.log(2.0 * math.pi)
            )
            K = P @ H.T @ Sinv
            m = m + np.einsum("pij,jp->ip", K, nu)
            P = P - K @ S @ K.transpose(0, 2, 1)
    return out


def mode_specs(kind: Kind, p: dict[str, float]) -> list[dict[str, Any]]:
    """The modes (``motion_modes`` entries) of a fit of ``modes`` or ``manoeuvres``."""
    specs = [
        {"kind": "cv", "q1": p["q1_straight"]},
        {"kind": "ct", "q1": p["q1_turn"], "q2": p["q2_turn"]},
    ]
    if kind == "manoeuvres":
        specs.append({"kind": "ct", "q1": p["q1_manoeuvre"], "q2": p["q2_manoeuvre"]})
    return specs


def _modes_of(kind: Kind, p: dict[str, float]) -> list[MotionModel]:
    if kind == "ct":
        return [CoordinatedTurn(T=1.0, q1=p["q1"], q2=p["q2"])]
    return [
        Straight(T=1.0, q1=m["q1"]) if m["kind"] == "cv" else CoordinatedTurn(1.0, m["q1"], m["q2"])
        for m in mode_specs(kind, p)
    ]


def _sigma_loglik(tracks: Sequence[Reports], kind: Kind, p: dict[str, float]) -> float:
    """The log-likelihood under CT or the modes, through unscented filters (B = 1)."""
    models = _modes_of(kind, p)
    M = len(models)
    rates = uniform_rates(M, p["switch_rate"]) if M > 1 else ((0.0,),)
    periods: dict[float, list[MotionModel]] = {}
    total = 0.0
    for r in tracks:
        x0, P0 = _start(r, 5, CoordinatedTurn.layout, p["sigma"])
        filters = [SigmaPointFilter(m, unscented(5, 2.0), x0[:, None], P0) for m in models]
        imm = InteractingMultipleModel(filters, np.eye(M), np.full(M, 1.0 / M))
        sensor = Position(CoordinatedTurn.layout, sigma_pos=p["sigma"])
        R = sensor.R(1.0)
        for k in range(2, len(r.t)):
            dt = float(r.t[k] - r.t[k - 1])
            if dt not in periods:  # a track's reports come at a few periods: each made once
                periods[dt] = [m.with_period(dt) for m in models]
            for f, m in zip(filters, periods[dt], strict=True):
                f.model = m
            if M > 1:
                imm.Pi = np.array(transition(rates, dt))
            imm.predict()
            imm.update([Observation.broadcast(sensor, r.xy[k], R)])
            total += float(imm.loglik[0])
    return total


def loglik(tracks: Sequence[Reports], kind: Kind, values: dict[str, float]) -> float:
    """The reports' log-likelihood under ``kind`` with these parameter values."""
    if kind == "cv":
        return float(_cv_loglik(tracks, np.array([values["q1"]]), np.array([values["sigma"]]))[0])
    return _sigma_loglik(tracks, kind, values)


# ---- the fit -----------------------------------------------------------------------------------


#: the coarse grid of the cv fit, log10 of (q1 in m^2/s^4, sigma in m), and the fine grid's half
#: widths and points around the coarse maximum
COARSE = ((-4.0, 4.0, 17), (-1.0, 3.0, 13))
FINE = ((1.0, 31), (0.5, 15))


def _fit_cv(tracks: Sequence[Reports]) -> Fit:
    """The cv fit on a grid (its likelihood is cheap, one vectorised filter pass per grid):
    coarse, then fine about the coarse maximum; q1's interval from its profile (sigma
    maximised at each q1), where it crosses the maximum less chi2_1(0.95) / 2."""
    (q_lo, q_hi, nq), (s_lo, s_hi, ns) = COARSE
    lq, ls = np.meshgrid(np.linspace(q_lo, q_hi, nq), np.linspace(s_lo, s_hi, ns), indexing="ij")
    ll = _cv_loglik(tracks, 10.0 ** lq.ravel(), 10.0 ** ls.ravel()).reshape(lq.shape)
    best = np.unravel_index(np.argmax(ll), ll.shape)
    (dq, nq), (ds, ns) = FINE
    lq, ls = np.meshgrid(
        np.linspace(lq[best] - dq, lq[best] + dq, nq),
        np.linspace(ls[best] - ds, ls[best] + ds, ns),
        indexing="ij",
    )
    ll = _cv_loglik(tracks, 10.0 ** lq.ravel(), 10.0 ** ls.ravel()).reshape(lq.shape)
    profile_q, profile_s = ll.max(axis=1), ll.max(axis=0)
    top = float(ll.max())
    level = top - float(chi2.ppf(0.95, 1)) / 2.0

    def interval(grid: Array, profile: Array) -> tuple[float, float]:
        inside = np.flatnonzero(profile >= level)
        lo, hi = inside[0], inside[-1]  # the profile is unimodal on the fine grid's span
        a = grid[lo] if lo == 0 else np.interp(level, profile[[lo - 1, lo]], grid[[lo - 1, lo]])
        b = (
            grid[hi]
            if hi == len(grid) - 1
            else np.interp(level, profile[[hi + 1, hi]], grid[[hi + 1, hi]])
        )
        return float(10.0**a), float(10.0**b)

    def vertex(grid: Array, profile: Array, at: int) -> float:
        """The maximum of the parabola through the profile's three points about its best."""
        if at == 0 or at == len(grid) - 1:
            return float(10.0 ** grid[at])
        y0, y1, y2 = profile[at - 1 : at + 2]
        h = grid[1] - grid[0]
        curve = y0 - 2.0 * y1 + y2
        shift = 0.5 * h * (y0 - y2) / curve if curve < 0 else 0.0
        return float(10.0 ** (grid[at] + shift))

    i, j = int(np.argmax(profile_q)), int(np.argmax(profile_s))
    values = {"q1": vertex(lq[:, 0], profile_q, i), "sigma": vertex(ls[0], profile_s, j)}
    intervals = {"q1": interval(lq[:, 0], profile_q), "sigma": interval(ls[0], profile_s)}
    return Fit("cv", values, intervals, top, sum(len(r.t) - 2 for r in tracks),
               [r.name for r in tracks])  # fmt: skip


def _hessian(f: Callable[[Array], float], x: Array, h: float = 0.1) -> Array:
    """The Hessian of f at x by central differences (step h in log-space)."""
    n = len(x)
    H = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            e_i, e_j = np.eye(n)[i] * h, np.eye(n)[j] * h
            H[i, j] = H[j, i] = (
                f(x + e_i + e_j) - f(x + e_i - e_j) - f(x - e_i + e_j) + f(x - e_i - e_j)
            ) / (4.0 * h * h)
    return H


def fit(tracks: Sequence[Reports], kind: Kind = "cv", start: dict[str, float] | None = None) -> Fit:
    """The maximum-likelihood parameters of ``kind`` on ``tracks``, with 95% intervals.

    ``modes`` and ``manoeuvres`` are fitted in stages, each a fit of its own model (a search
    over all their parameters, a second of CPU per evaluation, did not end in an hour on four
    ships): q1_straight from the cv fit, q1_turn, q2_turn and sigma from the ct fit, then the
    switching rate (and the manoeuvring mode's noise) with those held; each parameter's interval
    is its own stage's.
    """
    if kind == "cv":
        return _fit_cv(tracks)
    cv = _fit_cv(tracks)
    if kind == "ct":
        q1 = cv.values["q1"]  # the nested straight model's fit: where the search starts
        first = {**START, "q1": q1, "sigma": cv.values["sigma"], **(start or {})}
        return _search(tracks, kind, first, {})
    ct = fit(tracks, "ct", start)
    held = {
        "q1_straight": (cv.values["q1"], cv.intervals["q1"]),
        "q1_turn": (ct.values["q1"], ct.intervals["q1"]),
        "q2_turn": (ct.values["q2"], ct.intervals["q2"]),
        "sigma": (ct.values["sigma"], ct.intervals["sigma"]),
    }
    first = {**START, "q1_manoeuvre": 10.0 * ct.values["q1"], **(start or {})}
    return _search(tracks, kind, first, held)


def _search(
    tracks: Sequence[Reports],
    kind: Kind,
    first: dict[str, float],
    held: dict[str, tuple[float, tuple[float, float]]],
) -> Fit:
    """Nelder-Mead in log-space over the parameters of ``kind`` not ``held`` (value, interval),
    from ``first``; Wald intervals from the observed information."""
    names = [n for n in PARAMETERS[kind] if n not in held]
    fixed = {n: v for n, (v, _) in held.items()}
    theta0 = np.log([first[n] for n in names])

    def nll(theta: Array) -> float:
        v = loglik(tracks, kind, {**fixed, **dict(zip(names, np.exp(theta), strict=True))})
        return -v if math.isfinite(v) else 1e300

    # a simplex a factor e wide in each parameter: the start is a guess to within decades
    simplex = np.vstack([theta0, theta0 + np.eye(len(names))])
    options = {"initial_simplex": simplex, "xatol": 1e-3, "fatol": 1e-3, "maxiter": 3000}
    best = minimize(nll, theta0, method="Nelder-Mead", options=options)
    theta, top = best.x, -float(best.fun)
    H = _hessian(nll, theta)
    w = np.linalg.eigvalsh(H)
    # a likelihood too flat (or too rough) to bound a parameter gives no interval, not a false one
    var = np.diag(np.linalg.inv(H)) if w.min() > 0 else np.full(len(names), np.inf)
    se = np.sqrt(np.where(var > 0, var, np.inf))
    z = float(norm.ppf(0.975))
    found = dict(zip(names, np.exp(theta).tolist(), strict=True))
    intervals = {
        n: (float(np.exp(theta[i] - z * se[i])), float(np.exp(theta[i] + z * se[i])))
        for i, n in enumerate(names)
    }
    order = PARAMETERS[kind]
    return Fit(
        kind,
        {n: found[n] if n in found else fixed[n] for n in order},
        {n: intervals[n] if n in intervals else held[n][1] for n in order},
        top,
        sum(len(r.t) - 2 for r in tracks),
        [r.name for r in tracks],
    )
