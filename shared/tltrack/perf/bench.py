"""``tltrack bench``: single-thread step times of the particle filters, side by side in one process.

Every timed filter runs one run (B = 1) of the same scenario (Scenario 2 by default: coordinated
turn, range-bearing, the paper preset) with the same N, and the steps are interleaved, so the
machine's noise hits them alike and the ratios are fair even on a busy machine. Reported figures
are medians over every step of every repeat.

What one "step" is, per name:

- ``pf``: an isolated primary step, predict + update on z_k + estimate;
- ``tl-pf``: the TL-PF primary step, the same with the source's transfer as a second likelihood;
- ``source-pf``: a source step (Algorithm 1): update on its z_k + estimate + predict + the
  predicted-observation moments (eta_hat, P_eta_eta) it transfers;
- ``numpy-baseline``: the straightforward NumPy SIR of docs/background.md ("peers") doing the
  TL-PF primary step:
  (5, N) layout, noise as Q_sqrt times ``standard_normal``, log-likelihoods with ``hypot`` and
  ``arctan2``, resampling with ``cumsum`` + ``searchsorted``, then the mean and covariance. It is a
  yardstick, deliberately untuned;
- ``rpf``, ``tl-rpf``, ``source-rpf``: the same steps of the auxiliary particle filter
  (papers/rpf/README.md), the TL one fed by ``source-rpf``;
- ``user-model``: the ``tl-pf`` step with sensors the fast path does not know (a user's own
  range-bearing class, :class:`UserRangeBearing`): the particle filter's generic NumPy path for
  the likelihood and the predicted observation, as any new sensor gets until it has a kernel;
- ``stonesoup``: Stone Soup's particle filter (``ParticlePredictor`` with its ``ConstantTurn``
  model, ``ParticleUpdater`` with ``CartesianToBearingRange`` and systematic resampling, then the
  mean and covariance); ``None`` when the optional ``stonesoup`` package is not installed.

``speedup`` is a yardstick's median divided by the ``tl-pf`` median.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from tltrack.config import Config, make_config
from tltrack.engine.driver import Primaries, Sources
from tltrack.engine.registry import parse
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.engine.streams import stream
from tltrack.models.angles import wrap_angle
from tltrack.models.base import MotionModel
from tltrack.models.kinds import SENSORS
from tltrack.models.observation import Observation
from tltrack.models.range_bearing import RangeBearing

Array = NDArray[np.float64]
NAMES = (
    "tl-pf",
    "pf",
    "source-pf",
    "tl-rpf",
    "rpf",
    "source-rpf",
    "user-model",
    "numpy-baseline",
    "stonesoup",
)


#: the steps that take the source's transfer: timed only once there is one (from k = 2)
TL_STEPS = ("tl-pf", "tl-rpf", "user-model", "numpy-baseline")
#: this step's transfer of each source filter (by its name)
Transfers = dict[str, Observation]


@dataclass(frozen=True)
class UserRangeBearing(RangeBearing):
    """The paper's sensor under a type the fast path does not list: a user's own model."""

    kind: ClassVar[str] = "user-range-bearing"


#: the user's sensor kind, registered as any plugin's would be
USER_KIND = SENSORS.register(UserRangeBearing).kind


class NumpyBaseline:
    """The plain NumPy SIR of docs/background.md, one run, (n_x, N): the yardstick, not tuned."""

    def __init__(
        self, model: MotionModel, x0_hat: Array, P0: Array, N: int, rng: np.random.Generator
    ) -> None:
        self.model, self.N, self.rng = model, N, rng
        self.x = x0_hat[:, None] + np.linalg.cholesky(P0) @ rng.standard_normal((len(x0_hat), N))

    def step(self, stmts: list[tuple[Array, Array, tuple[float, float]]]) -> tuple[Array, Array]:
        """Predict, weight by every (z, R, sensor position), resample, estimate."""
        L = self.model.Q_sqrt
        x = self.model.f(self.x) + L @ self.rng.standard_normal((L.shape[1], self.N))
        logw = np.zeros(self.N)
        ix, iy = self.model.layout.pos
        for z, R, (sx, sy) in stmts:
            dx, dy = x[ix] - sx, x[iy] - sy
            d0 = z[0] - np.hypot(dx, dy)
            d1 = wrap_angle(z[1] - np.arctan2(dy, dx))
            P = np.linalg.inv(R)
            logw -= 0.5 * (P[0, 0] * d0 * d0 + 2.0 * P[0, 1] * d0 * d1 + P[1, 1] * d1 * d1)
        w = np.exp(logw - logw.max())
        w /= w.sum()
        cdf = np.cumsum(w)
        cdf[-1] = 1.0
        idx = np.searchsorted(cdf, (np.arange(self.N) + self.rng.random()) / self.N, side="right")
        self.x = x[:, np.minimum(idx, self.N - 1)]
        mean = self.x.mean(axis=1)
        d = self.x - mean[:, None]
        return mean, d @ d.T / self.N + self.model.Q


def _stonesoup_stepper(
    setup: Setup, z: Array, x0_hat: Array, N: int, seed: int
) -> Callable[[int], Any] | None:
    """One Stone Soup PF step per call ``step(k)`` on the primary's z_k; None without Stone Soup."""
    try:
        from stonesoup.resampler.particle import SystematicResampler
        from stonesoup.types.hypothesis import SingleHypothesis
        from stonesoup.updater.particle import ParticleUpdater
        from tltrack.perf.stonesoup_anchor import anchor
    except ImportError:
        return None
    ss = anchor(setup, x0_hat, N, seed)
    updater = ParticleUpdater(ss.radar, resampler=SystematicResampler())
    state: list[Any] = [ss.prior]

    def step(k: int) -> Any:
        pred = ss.predictor.predict(state[0], timestamp=ss.at(k))
        state[0] = updater.update(SingleHypothesis(pred, ss.detection(z[k - 1, 0], z[k - 1, 1], k)))
        return state[0].mean, state[0].covar

    return step


def _one_pass(
    cfg: Config, steps: int, seed: int, times: dict[str, list[float]], with_stonesoup: bool
) -> bool:
    """Run every filter over ``steps`` steps of one run, appending each step's seconds to ``times``.

    Every filter steps through the step driver's halves, one filter per call. Returns whether
    Stone Soup took part.
    """
    setup = Setup(cfg.with_(seed=seed))
    sim = simulate(setup, 0)
    sid = cfg.sources[0].id
    s_p, s_s = setup.sensor(PRIMARY), setup.sensor(sid)
    if not all(isinstance(s, RangeBearing) for s in (s_p, s_s)):
        raise ValueError("the bench compares range-bearing filters: both sensors must be one")
    R_p = setup.sensors[PRIMARY].R
    x0 = sim.x0_hat[:, None]
    sources = Sources(setup, [("source-pf", sid), ("source-rpf", sid)], x0, [0])
    primaries = Primaries(setup, [parse(n) for n in ("tl-pf", "pf", "tl-rpf", "rpf")], x0, [0])
    # the user's: the same sensors under a kind the fast path does not list
    mine = Setup(
        setup.cfg.with_(
            primary_sensor={**setup.sensors[PRIMARY].spec.model_dump(), "kind": USER_KIND},
            sources=[
                {"id": sid, "sensor": {**setup.sensors[sid].spec.model_dump(), "kind": USER_KIND}}
            ],
        )
    )
    user = Primaries(mine, [parse("tl-pf")], x0, [0])
    u_p, u_s = mine.sensor(PRIMARY), mine.sensor(sid)
    base = NumpyBaseline(
        setup.motion, sim.x0_hat, setup.P0, cfg.particles, stream(seed, 0, "numpy-baseline")
    )
    ss = (
        _stonesoup_stepper(setup, sim.z[PRIMARY], sim.x0_hat, cfg.particles, seed)
        if with_stonesoup
        else None
    )

    def baseline(k: int, t: Observation | None) -> None:
        stmts = [(sim.z[PRIMARY][k - 1], R_p, s_p.position)]
        if t is not None:
            stmts.append((t.mean[:, 0], t.cov[0], s_s.position))
        base.step(stmts)

    def source_step(name: str, k: int, z_s: Observation) -> Observation:
        return sources.step(k, {sid: z_s}, only=[(name, sid)])[name, sid]

    def tl_step(
        half: Primaries, name: str, k: int, z_p: Observation, t: Observation | None
    ) -> None:
        half.step(k, z_p, lambda spec: [t] if t is not None and spec.role == "tl" else [], [name])

    def user_step(k: int, z_p: Observation, t: Observation | None) -> None:
        mine_t = None if t is None else replace(t, sensor=u_s)
        tl_step(user, "tl-pf", k, replace(z_p, sensor=u_p), mine_t)

    #: name -> one step, given (k, z_p, z_s, the transfers for k by source); a source returns
    #: its next transfer
    steppers: dict[str, Callable[[int, Observation, Observation, Transfers], Any]] = {
        "source-pf": lambda k, z_p, z_s, t: source_step("source-pf", k, z_s),
        "tl-pf": lambda k, z_p, z_s, t: tl_step(primaries, "tl-pf", k, z_p, t.get("source-pf")),
        "pf": lambda k, z_p, z_s, t: tl_step(primaries, "pf", k, z_p, None),
        "source-rpf": lambda k, z_p, z_s, t: source_step("source-rpf", k, z_s),
        "tl-rpf": lambda k, z_p, z_s, t: tl_step(primaries, "tl-rpf", k, z_p, t.get("source-rpf")),
        "rpf": lambda k, z_p, z_s, t: tl_step(primaries, "rpf", k, z_p, None),
        "user-model": lambda k, z_p, z_s, t: user_step(k, z_p, t.get("source-pf")),
        "numpy-baseline": lambda k, z_p, z_s, t: baseline(k, t.get("source-pf")),
    }
    if ss is not None:
        steppers["stonesoup"] = lambda k, z_p, z_s, t: ss(k)
    names = [n for n in NAMES if n in steppers]

    transfers: Transfers = {}
    clock = time.perf_counter
    order = np.random.default_rng(seed)
    for k in range(1, steps + 1):
        z_p = setup.sensors[PRIMARY].observe(sim.z[PRIMARY][k - 1])
        z_s = setup.sensors[sid].observe(sim.z[sid][k - 1])
        upcoming: Transfers = {}
        # a fresh order every step: no filter always runs right after the same one (whose memory
        # traffic it would inherit). The transfer for k + 1 waits until k + 1: any order works.
        for i in order.permutation(len(names)):
            name = names[i]
            t0 = clock()
            got = steppers[name](k, z_p, z_s, transfers)
            dt = clock() - t0
            if name.startswith("source-"):
                upcoming[name] = got
            if transfers or name not in TL_STEPS:
                times[name].append(dt)  # k = 1 has no transfer yet: not a TL step
        transfers = upcoming
    return ss is not None


def run_bench(
    particles: int = 6000,
    steps: int | None = None,
    repeats: int = 3,
    seed: int = 0,
    cfg: Config | None = None,
    stonesoup: bool = True,
) -> dict[str, Any]:
    """Median ms per step of each filter and the speedups of ``tl-pf`` over the yardsticks.

    ``cfg`` defaults to Scenario 2 with the paper preset; ``steps`` to its K. Returns
    ``{"ms_per_step": {name: ms or None},
    "speedup": {"numpy-baseline": x, "stonesoup": x or None}}``.
    """
    cfg = (cfg or make_config()).with_(particles=particles)
    K = min(steps or cfg.K, cfg.K)
    if K < 2:
        raise ValueError("the bench needs at least 2 steps (the first has no transfer)")
    times: dict[str, list[float]] = {name: [] for name in NAMES}
    _one_pass(
        cfg.with_(particles=min(particles, 500)), 3, seed, {n: [] for n in NAMES}, stonesoup
    )  # warm-up: numba's cached kernels load, NumPy's paths warm
    had_stonesoup = False
    enabled = gc.isenabled()
    gc.disable()
    try:
        for rep in range(repeats):
            had_stonesoup = _one_pass(cfg, K, seed + rep, times, stonesoup)
            gc.collect()
    finally:
        if enabled:
            gc.enable()
    ms: dict[str, float | None] = {
        n: float(np.median(times[n]) * 1e3) if times[n] else None for n in NAMES
    }
    if not had_stonesoup:
        ms["stonesoup"] = None
    tl = ms["tl-pf"]
    assert tl is not None

    def ratio(name: str) -> float | None:
        v = ms[name]
        return None if v is None else v / tl

    def over(a: str, b: str) -> float | None:
        x, y = ms[a], ms[b]
        return None if x is None or not y else x / y

    return {
        "ms_per_step": ms,
        "speedup": {"numpy-baseline": ratio("numpy-baseline"), "stonesoup": ratio("stonesoup")},
        "user_model_over_numpy_baseline": over("user-model", "numpy-baseline"),
        "rpf_over_pf": {r: over(f"{r}rpf", f"{r}pf") for r in ("", "tl-", "source-")},
    }


def format_table(result: dict[str, Any]) -> str:
    """The bench result as a small text table."""
    lines = [f"{'filter':<16}{'ms/step':>10}"]
    for name, v in result["ms_per_step"].items():
        lines.append(f"{name:<16}{'n/a' if v is None else f'{v:.3f}':>10}")
    for name, v in result["speedup"].items():
        lines.append(f"tl-pf speedup vs {name}: {'n/a' if v is None else f'{v:.1f}x'}")
    u = result.get("user_model_over_numpy_baseline")
    lines.append(f"user-model / numpy-baseline: {'n/a' if u is None else f'{u:.2f}x'}")
    for role, v in result.get("rpf_over_pf", {}).items():
        lines.append(f"{role}rpf / {role}pf: {'n/a' if v is None else f'{v:.2f}x'}")
    return "\n".join(lines)
