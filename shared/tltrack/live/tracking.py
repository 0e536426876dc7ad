"""One episode of a live tracker: the same filters, streams and start as the Monte-Carlo engine.

A live tracker is the engine with a batch of one run: it builds its filter through
:func:`tltrack.engine.registry.build`, starts it at the run's x0_hat, and draws from the run's own
random stream. So a lock-step replay of run r computes, to rounding, exactly what
``tltrack experiment`` computes for run r. Wire messages are turned into
:class:`~tltrack.models.observation.Observation` here, and nowhere else.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from tltrack.config import Config
from tltrack.config.timeline import US, Clock, Timeline, us
from tltrack.engine.driver import Link, Primaries, Sources, StepRecord
from tltrack.engine.montecarlo import check_filters
from tltrack.engine.names import reported_name
from tltrack.engine.registry import FilterSpec, parse
from tltrack.engine.scenario import initial_estimate
from tltrack.engine.setup import PRIMARY, OwnSensor, Setup, from_spec
from tltrack.filters import consistency
from tltrack.filters.base import Array, Estimate
from tltrack.live.service import Service
from tltrack.models.base import Layout, PositionFix
from tltrack.models.observation import Observation
from tltrack.models.scan import Statement
from tltrack.wire.messages import EstimateMsg, Measurement, Schedule, Transfer


def transfer(msg: Transfer, source_id: str, layout: Layout) -> Observation:
    """N(eta_hat_k; h_source(x_k), P_eta_eta,k): the source's statement about its own sensor,
    which the transfer itself describes."""
    s = from_spec(msg.sensor, layout)
    obs = Observation.broadcast(s, np.asarray(msg.eta), np.asarray(msg.P_eta))
    return dataclasses.replace(obs, origin=source_id)


def statement(own: OwnSensor, z: Measurement | None) -> Statement | None:
    """What the filters take of a measurement message (None: it never came; they predict)."""
    if z is None:
        return None
    return own.report(np.asarray(z.z, dtype=float).reshape(len(z.z), own.model.n_z))


def wire_covariance(P: np.ndarray) -> np.ndarray:
    """P made fit for a message: symmetric, eigenvalues at least 1e-9 max(1, trace P).

    The paper's particle covariance (sample covariance + Q_v) of a cloud collapsed onto one
    particle is the singular Q_v; a receiver rightly refuses that as not positive-definite.
    """
    P = 0.5 * (P + P.T)
    w, V = np.linalg.eigh(P)
    floor = 1e-9 * max(1.0, float(np.trace(P)))
    P = (V * np.maximum(w, floor)) @ V.T
    return 0.5 * (P + P.T)


@dataclass(frozen=True)
class NisReading:
    """A filter's consistency at a step: the NIS of its own z_k (None: no z_k), the mean of its
    last NIS over the window (None until the window is full) and that mean's 99% band."""

    nis: float | None
    window: float | None
    band: tuple[float, float]


class NisMonitor:
    """The NIS windows of an episode's filters (:mod:`tltrack.filters.consistency`): a collector
    of the step driver's records."""

    def __init__(self, n_z: int) -> None:
        self.band = consistency.band(n_z)
        self._windows: dict[str, consistency.Window] = {}
        self.last: dict[str, NisReading] = {}

    def __call__(self, record: StepRecord) -> None:
        window = self._windows.setdefault(record.name, consistency.Window())
        if record.nis is None:  # a step with no z_k leaves the window as it was
            self.last[record.name] = NisReading(None, None, self.band)
            return
        nis = float(record.nis[0])
        mean = float(window.push(record.nis)[0])
        finite = np.isfinite(nis)
        self.last[record.name] = NisReading(
            nis if finite else None, mean if np.isfinite(mean) else None, self.band
        )


@dataclass(frozen=True)
class StepReport:
    """Filter ``name``'s estimate at the step of ``z``, begun at ``t_step``: what a tracker
    publishes. With when ``z`` arrived, it times each stage of the latency."""

    z: Measurement
    sender: str
    name: str
    layout: Layout
    est: Estimate
    used: bool
    recovered: bool
    t_step: float
    step_ms: float
    nis: NisReading | None = None

    def message(self) -> EstimateMsg:
        return EstimateMsg(
            episode=self.z.episode,
            sender=self.sender,
            k=self.z.k,
            t_sensor=self.z.t_sensor,
            filter=self.name,
            x=self.est.mean[0],
            pos=self.layout.position(self.est.mean[0]),
            P=wire_covariance(self.est.cov[0]),
            transfer_used=self.used,
            recovered=self.recovered,
            t_sent=time.time(),
            step_ms=self.step_ms,
            t_received=self.z.received_at,
            t_step=self.t_step,
            nis=None if self.nis is None else self.nis.nis,
            nis_window=None if self.nis is None else self.nis.window,
            nis_band=None if self.nis is None else list(self.nis.band),
        )

    def publish(self, svc: Service, key: str) -> None:
        """Publish on ``key`` (the message is built only when it is sent, so that a failure to
        build counts as a failed publication), and count the step as on track or a recovery."""
        svc.publish(key, self.message)
        svc.count("recoveries" if self.recovered else "steps_on_track")


class _Operator:
    """What either half of an episode knows of itself: the episode's models, its own sensor (what
    its measurement messages must hold) and the NIS monitor of its filter."""

    def _start(self, cfg: Config, run: int, sensor: str) -> tuple[Setup, Array]:
        """The episode's models and run ``run``'s x0_hat (n_x, 1), as the engine starts that run."""
        self.cfg = cfg
        setup = Setup(cfg)
        self.timeline = setup.timeline
        self.layout = setup.layout
        self.own: OwnSensor = setup.sensors[sensor]
        self.monitor = NisMonitor(self.own.model.n_z)
        return setup, initial_estimate(cfg, run)[:, None]

    @property
    def n_z(self) -> int:
        return self.own.model.n_z

    @property
    def components(self) -> tuple[str, ...]:
        return tuple(self.own.model.components)

    @property
    def one_detection(self) -> bool:
        return self.own.detection.trivial


class SourceEpisode(_Operator):
    """Algorithm 1 for one episode: ``step(z_k)`` -> (estimate at k, (eta, P) for k + 1).

    The step driver's source half (:class:`~tltrack.engine.driver.Sources`) with one filter.
    """

    def __init__(self, cfg: Config, run: int, kind: str, source_id: str) -> None:
        self.source_id = source_id
        setup, x0_hat = self._start(cfg, run, source_id)
        spec = parse(f"source-{kind}")
        self.name = reported_name(spec, source_id, len(cfg.sources))  # as the engine reports it
        self._link: Link = (spec.name, source_id)
        self._estimates: dict[str, Estimate] = {}
        self._half = Sources(setup, [self._link], x0_hat, [run], [self._keep, self.monitor])
        self.k = 0
        self._view: Timeline | None = None  #: its timeline with the primary's published schedule

    def _keep(self, record: StepRecord) -> None:
        self._estimates[record.name] = record.estimate

    def step(self, z: Measurement | None) -> tuple[Estimate, Observation]:
        """``None``: the measurement of this step never came; predict through it."""
        self.k += 1
        eta = self._half.step(self.k, {self.source_id: statement(self.own, z)})[self._link]
        return self._estimates.pop(self.name), eta

    def heard(self, schedule: Schedule) -> None:
        """The primary's published schedule: where its samples are on its clock. ValueError if
        it cannot be the episode's: a period other than Ts, or a first sample that no phase in
        [0, Ts) and clock offset within max_clock_offset_s gives."""
        ours, cfg = self.timeline, self.cfg
        if round(schedule.period_s * US) != ours.clocks[PRIMARY].period_us:
            raise ValueError(f"period_s = {schedule.period_s:g} s, not the episode's Ts")
        most = us(cfg.max_clock_offset_s)  # in whole microseconds, as the primary stamps it
        if not -most <= round(schedule.t0_s * US) < us(cfg.Ts) + most:
            raise ValueError(f"t0_s = {schedule.t0_s:g} s: no phase and clock offset give it")
        primary = Clock(round(schedule.period_s * US), 0, round(schedule.t0_s * US))
        self._view = dataclasses.replace(ours, clocks={**ours.clocks, PRIMARY: primary})

    @property
    def addressed(self) -> bool:
        """Can it address its transfers: on the paper's shared clock (each for k + 1), or off it
        once it has heard the primary's schedule?"""
        return self.timeline.synchronous or self._view is not None

    def sends(self, eta: Observation) -> list[tuple[int, float | None, Observation]]:
        """What the last step sends, its own transfer ``eta`` for k + 1 in hand: for each of the
        primary's samples until its next step, (k_apply, t_apply, the transfer), as the engine's
        step driver sends them; t_apply (s, the primary's schedule) None on the paper's clock.
        Nothing before it is :attr:`addressed`."""
        if self.timeline.synchronous:
            return [(j, None, sent) for j, _h, sent in self._half.sends(self._link, self.k, eta)]
        if self._view is None:
            return []
        view = self._view
        return [
            (j, view.stamp(PRIMARY, j) / US, sent)
            for j, _horizon, sent in self._half.sends(self._link, self.k, eta, view)
        ]

    def transfer_message(
        self,
        eta: Observation,
        episode: str,
        k: int,
        t_sensor: float,
        k_apply: int | None = None,
        t_apply: float | None = None,
    ) -> Transfer:
        """What it sends after step ``k``: (eta_hat, P_eta_eta) for the primary's sample
        ``k_apply`` (default k + 1) at ``t_apply``, described by its own sensor."""
        return Transfer(
            episode=episode,
            sender=self.source_id,
            k=k,
            t_sensor=t_sensor,
            k_apply=k + 1 if k_apply is None else k_apply,
            t_apply=t_apply,
            sensor=self.own.spec,
            eta=eta.mean[:, 0],
            P_eta=wire_covariance(eta.cov[0]),
        )

    @property
    def recovered(self) -> bool:
        """Did the last step reinitialise the filter (it had lost the track)?"""
        return self._half.recovered(self._link)


class PrimaryEpisode(_Operator):
    """Algorithm 2 for one episode, with an isolated twin run alongside for comparison.

    The step driver's primary half (:class:`~tltrack.engine.driver.Primaries`) with two filters:
    ``tl-<kind>`` and ``<kind>``. ``robust`` makes the first ``robust-tl-<kind>``: transfers are
    first judged for consistency (and the config's budget), exactly as the engine's filter of
    that name; its twin is then the isolated filter, which it rolls back to.
    """

    def __init__(self, cfg: Config, run: int, kind: str, robust: bool = False) -> None:
        setup, x0_hat = self._start(cfg, run, PRIMARY)
        self.tl_name, self.iso_name = f"{'robust-' if robust else ''}tl-{kind}", kind
        if robust:
            check_filters(cfg, [self.tl_name])
        specs = [parse(self.tl_name), parse(self.iso_name)]
        self._half = Primaries(setup, specs, x0_hat, [run], [self.monitor], share_twins=True)
        self._k = {self.tl_name: 0, self.iso_name: 0}

    def _step(self, name: str, z: Measurement | None, extra: list[Observation]) -> Estimate:
        self._k[name] += 1

        def feed(spec: FilterSpec) -> list[Statement]:
            return list(extra) if spec.role in ("tl", "robust") else []

        return self._half.step(self._k[name], statement(self.own, z), feed, only=[name])[name]

    def step(self, z: Measurement | None, transfers: dict[str, Transfer]) -> Estimate:
        """The TL estimate at k; ``transfers`` maps source id -> its transfer for k. The isolated
        estimate comes from :meth:`step_twin`, so the TL estimate can go out first.

        ``z=None``: the primary's own measurement never came; the transfers alone update.
        Transfers come in the engine's order: the episode's sources first, then any other
        source (each transfer describes its own sensor), by id.
        """
        known = [s.id for s in self.cfg.sources]
        order = [*known, *sorted(set(transfers) - set(known))]
        extra = [transfer(transfers[sid], sid, self.layout) for sid in order if sid in transfers]
        if self.twin_in_step:  # robust: only what it can judge (check_filters)
            extra = [t for t in extra if isinstance(t.sensor, PositionFix)]
        return self._step(self.tl_name, z, extra)

    @property
    def twin_in_step(self) -> bool:
        """Does :meth:`step` step the twin too? A robust primary judges transfers against it."""
        return self._half.robust(self.tl_name)

    def step_twin(self, z: Measurement | None) -> Estimate:
        """The isolated twin's estimate at the step of ``z``, the steps taken in order.

        The twin has its own random stream, so when it steps changes no number: a live primary
        may step it well after the TL estimate is out. If :attr:`twin_in_step`, the twin has
        already stepped inside :meth:`step`: this is that estimate, so call it before the next
        :meth:`step`.
        """
        return self._step(self.iso_name, z, [])

    @property
    def names(self) -> tuple[str, str]:
        """The reported names of its (TL, isolated) filters."""
        return self.tl_name, self.iso_name

    @property
    def used_transfer(self) -> bool:
        """Did the last TL step use a transfer (a robust primary may have judged it out)?"""
        return self._half.used(self.tl_name)

    @property
    def recovered(self) -> tuple[bool, bool]:
        """Did the last step reinitialise (TL filter, isolated filter)?"""
        return self._half.recovered(self.tl_name), self._half.recovered(self.iso_name)

    @property
    def rolled_back(self) -> bool:
        """Did the last step roll the robust primary back to its isolated twin?"""
        return self._half.rolled_back(self.tl_name)
