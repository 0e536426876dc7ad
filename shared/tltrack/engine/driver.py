"""The step driver: one place that steps the sources, carries their transfers, and steps the
primaries, for a batch of B runs.

Every user of the roles of :mod:`tltrack.filters.transfer` goes through here: the Monte-Carlo
engine (a batch of runs, :class:`Driver`), the live trackers (a batch of one; the source
operator's process holds :class:`Sources`, the primary's :class:`Primaries`), the benchmarks,
the examples and the studies' scripts. One step k:

1. each source filter (Algorithm 1) updates on its z_k and predicts; its transfer
   (eta_hat_{k+1}, P_eta_eta,k+1) goes into the :class:`Channel`;
2. each primary filter (Algorithm 2) takes its z_k and, by its role, the transfers the channel
   delivers for k (``tl-``, ``robust-tl-``), every source's raw z_k (``fusion-``) or nothing;
   a robust primary first judges the transfers (:class:`~tltrack.filters.decision.TransferPolicy`)
   and can roll back to its isolated twin.

After every filter's step the driver hands a :class:`StepRecord` to each collector (as the
``collect`` of ``particles``): scores, timings, diagnostics such as the effective sample size,
with no reach into a filter's private state.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from tltrack.config import LinkSpec
from tltrack.config.timeline import US, Timeline
from tltrack.engine.names import reported_name
from tltrack.engine.registry import FilterSpec, Role, build, parse, recovery, source_name
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.engine.streams import stream
from tltrack.filters.base import Estimate, Filter
from tltrack.filters.decision import TransferPolicy
from tltrack.filters.transfer import Primary, Source
from tltrack.models.observation import Observation
from tltrack.models.scan import Statement

Array = NDArray[np.float64]
#: a transfer's path: (the source filter's name, the source operator's id)
Link = tuple[str, str]


# ---- what a step tells ------------------------------------------------------------------------


@dataclass(frozen=True)
class StepRecord:
    """One filter's step k: its estimate, what it used or made, and its wall time."""

    k: int
    name: str  #: as reported (``source-pf/s2`` when there are several sources)
    role: Role
    filter: Filter
    estimate: Estimate
    seconds: float
    used: NDArray[np.bool_] | None = None  #: a primary's runs whose update used a transfer
    transfer: Observation | None = None  #: a source's (eta_hat, P_eta_eta) for k + 1
    #: per run, the NIS of the filter's own z_k before its update (None: no z_k)
    nis: Array | None = None
    operator: str = PRIMARY  #: whose step k this is (the source's id, for a source filter)


class Collector(Protocol):
    """Hears of every filter's step."""

    def __call__(self, record: StepRecord) -> None: ...


def _tell(collectors: Sequence[Collector], record: StepRecord) -> None:
    for c in collectors:
        c(record)


def effective_sample_size(filt: Filter) -> Array | None:
    """1 / sum w_i^2 per run, (B,), of a filter that keeps weights (``log_weights``); else None."""
    logw = getattr(filt, "log_weights", None)
    if logw is None:
        return None
    w = np.exp(logw - logw.max(axis=1, keepdims=True))
    w /= w.sum(axis=1, keepdims=True)
    return np.asarray(1.0 / (w * w).sum(axis=1))


# ---- the channel ------------------------------------------------------------------------------


class Channel(Protocol):
    """Carries each transfer from its source filter to the primaries."""

    def send(self, link: Link, k_apply: int, transfer: Observation) -> None:
        """The transfer made for step ``k_apply``."""

    def receive(self, link: Link, k: int) -> Observation | None:
        """What a primary on ``link`` takes at step k (None: nothing arrived). Reading twice
        gives the same answer: several primaries may listen to one source."""


class Direct:
    """The identity: the transfer made for k is taken at k. ``lag`` (per source id) delays a
    source's transfers by whole steps while they still claim to be current: a stale source
    (:mod:`tltrack.engine.faults`)."""

    def __init__(self, lag: Mapping[str, int] | None = None, ahead: int = 1) -> None:
        """``ahead``: how many steps ahead a source's step sends for (a slower source's)."""
        self.lag = dict(lag or {})
        self.ahead = ahead
        self._made: dict[Link, dict[int, Observation]] = {}

    def send(self, link: Link, k_apply: int, transfer: Observation) -> None:
        made = self._made.setdefault(link, {})
        made[k_apply] = transfer
        made.pop(k_apply - self.lag.get(link[1], 0) - self.ahead - 1, None)

    def receive(self, link: Link, k: int) -> Observation | None:
        return self._made.get(link, {}).get(k - self.lag.get(link[1], 0))


class Lossy:
    """Each source's link to the primary as a vehicle's radio has it: lossy and late, per run,
    seeded (the config's ``sources[].link``, :class:`~tltrack.config.LinkSpec`).

    The transfer for step k_apply leaves its source when made, at (k_apply - 1) Ts. It is lost
    with probability ``loss``; else it arrives ``delay_s`` plus a uniform jitter in [0,
    ``jitter_s``] later. The primary takes it at step k_apply if it arrived by k_apply Ts +
    ``deadline_s`` (its wait after its own measurement); a later one is refused and counted
    (``late``), never applied to another step: that run's primary steps alone. A source's
    transfers of one step (one per source filter) share their fate, as one packet would. The
    draws come from the stream (seed, run, ``link/<source id>``), one pair per step. With a
    perfect link (no loss, no delay past the deadline) it is :class:`Direct`. The sources
    without a link go through ``others`` (a stale source's lag, say).
    """

    def __init__(
        self,
        runs: Sequence[int],
        seed: int,
        links: Mapping[str, LinkSpec],
        Ts: float,
        others: Channel | None = None,
        ahead: int = 1,
    ) -> None:
        """``ahead``: how many steps ahead a source's step sends for (a slower source's)."""
        self.runs, self.links, self.Ts, self.ahead = list(runs), dict(links), Ts, ahead
        self.others: Channel = others or Direct()
        self._rngs = {sid: [stream(seed, r, f"link/{sid}") for r in self.runs] for sid in links}
        #: per (source id, k_apply) of the last steps: the runs its transfers reach
        self.reached: dict[tuple[str, int], NDArray[np.bool_]] = {}
        self._made: dict[Link, dict[int, Observation]] = {}
        B = len(self.runs)
        #: per source id, per run: transfers lost, and transfers refused as late
        self.lost = {sid: np.zeros(B, dtype=np.int64) for sid in links}
        self.late = {sid: np.zeros(B, dtype=np.int64) for sid in links}

    def _arrives(self, sid: str, k_apply: int) -> NDArray[np.bool_]:
        if (sid, k_apply) not in self.reached:
            spec, rngs = self.links[sid], self._rngs[sid]
            lost = np.array([g.random() < spec.loss for g in rngs])
            delay = spec.delay_s + spec.jitter_s * np.array([g.random() for g in rngs])
            late = ~lost & (delay > self.Ts + spec.deadline_s)
            self.lost[sid] += lost
            self.late[sid] += late
            self.reached[sid, k_apply] = ~lost & ~late
            self.reached.pop((sid, k_apply - self.ahead - 1), None)
        return self.reached[sid, k_apply]

    def send(self, link: Link, k_apply: int, transfer: Observation) -> None:
        if link[1] not in self.links:
            self.others.send(link, k_apply, transfer)
            return
        ok = self._arrives(link[1], k_apply)
        made = self._made.setdefault(link, {})
        made.pop(k_apply - self.ahead - 1, None)
        if ok.any():
            made[k_apply] = replace(
                transfer, mask=ok if transfer.mask is None else ok & transfer.mask
            )

    def receive(self, link: Link, k: int) -> Observation | None:
        if link[1] not in self.links:
            return self.others.receive(link, k)
        return self._made.get(link, {}).get(k)


# ---- the two halves ---------------------------------------------------------------------------


class Sources:
    """Algorithm 1 for each (source filter, source id) of ``links``: a source operator's half."""

    def __init__(
        self,
        setup: Setup,
        links: Sequence[Link],
        x0_hat: Array,
        runs: Sequence[int],
        collectors: Sequence[Collector] = (),
    ) -> None:
        self.setup, self.collectors = setup, collectors
        self.roles: dict[Link, Source] = {}
        self.names: dict[Link, str] = {}
        n = len(setup.source_ids)
        for name, sid in links:
            spec = parse(name)
            own = setup.sensors[sid]
            operator = setup.operator(sid)
            start, P0 = operator.start(sid, x0_hat)
            filt = build(spec, operator, start, runs, source_id=sid, P0=P0)
            self.roles[name, sid] = Source(filt, own.model, own.R, recovery(spec, setup.cfg))
            self.names[name, sid] = reported_name(spec, sid, n)

    def step(
        self, k: int, z: Mapping[str, Statement | None], only: Iterable[Link] | None = None
    ) -> dict[Link, Observation]:
        """Step the source filters (those of ``only``, default all) on their operator's
        ``z[sid]`` (None: it never came; predict through it); returns each one's transfer for
        k + 1, named by its source."""
        out = {}
        for name, sid in self.roles if only is None else only:
            role = self.roles[name, sid]
            t0 = time.perf_counter()
            est, transfer = role.step(z[sid])
            dt = time.perf_counter() - t0
            transfer = replace(transfer, origin=sid)
            out[name, sid] = transfer
            name_ = self.names[name, sid]
            _tell(
                self.collectors,
                StepRecord(k, name_, "source", role.filter, est, dt, None, transfer, role.nis, sid),
            )
        return out

    @property
    def clock_spread_s(self) -> float:
        """The spread a source gives its horizon to the primary's sample, from the clock bound b:
        each clock within +-b of the truth, so the two differ by some constant tau, |tau| <= 2b.
        A constant error is a bias, not noise: only a spread of 2b makes the transfer's added
        covariance (2b)^2 v v' cover tau^2 v v' whatever tau is (papers/links/README.md).
        0 on the paper's shared clock."""
        return 2.0 * self.setup.cfg.max_clock_offset_s

    def sends(
        self, link: Link, k: int, transfer: Observation, timeline: Timeline | None = None
    ) -> list[tuple[int, int, Observation]]:
        """What source filter ``link``'s step k sends, its own transfer for k + 1 in hand: for
        each primary sample j until its next step (:meth:`Timeline.targets
        <tltrack.config.timeline.Timeline.targets>`), (j, the horizon in us, the transfer). Over
        its own period on a shared clock that is its own (the paper's); else :meth:`ahead`.
        ``timeline``: the source's view (a live source's, from the primary's published
        schedule); default the config's."""
        timeline = timeline or self.setup.timeline
        period = timeline.clocks[link[1]].period_us
        out = []
        for j, horizon in timeline.targets(link[1], k):
            own = horizon == period and not self.clock_spread_s
            out.append((j, horizon, transfer if own else self.ahead(link, horizon / US)))
        return out

    def ahead(self, link: Link, horizon_s: float) -> Observation:
        """Source filter ``link``'s transfer for ``horizon_s`` after its last step, off its own
        steps or with uncertain clocks (:meth:`~tltrack.filters.transfer.Source.ahead`)."""
        role = self.roles[link]
        sent = role.ahead(self.setup.motion.with_period, horizon_s, self.clock_spread_s)
        return replace(sent, origin=link[1])

    def recovered(self, link: Link) -> bool:
        """Did the last step reinitialise this source filter in any run?"""
        return _any(self.roles[link].recovered)


#: a primary's statements besides its own z_k, by its role
Feed = Callable[[FilterSpec], list[Statement]]


class Primaries:
    """Algorithm 2 for each primary filter of ``specs``: the primary operator's half.

    A robust primary steps an isolated twin of its kind, on the same random numbers, that it
    judges transfers against and rolls back to. With ``share_twins`` that twin *is* the isolated
    primary of its kind when ``specs`` has one (as the live primary reports its twin), so it is
    stepped once; otherwise each robust primary has its own (the engine times each filter apart).
    """

    def __init__(
        self,
        setup: Setup,
        specs: Sequence[FilterSpec],
        x0_hat: Array,
        runs: Sequence[int],
        collectors: Sequence[Collector] = (),
        *,
        share_twins: bool = False,
    ) -> None:
        self.setup, self.collectors = setup, collectors
        cfg = setup.cfg
        self.roles: dict[str, tuple[FilterSpec, Primary]] = {}
        self._twin_of: dict[str, str] = {}  #: isolated name -> the robust primary stepping it
        own = setup.operator(PRIMARY)
        x0_hat, P0 = own.start(PRIMARY, x0_hat)
        for spec in sorted(specs, key=lambda s: s.role == "robust"):  # isolated ones first
            filt = build(spec, own, x0_hat, runs, P0=P0)
            policy = twin = None
            if spec.role == "robust":
                policy = TransferPolicy(cfg.gate_probability, cfg.transfer_budget)
                shared = self.roles.get(spec.kind) if share_twins else None
                if shared is not None and spec.kind not in self._twin_of:
                    twin = shared[1]
                    self._twin_of[spec.kind] = spec.name
                else:
                    iso = parse(spec.kind)
                    twin = Primary(build(iso, own, x0_hat, runs, P0=P0), None, recovery(iso, cfg))
            role = Primary(filt, policy, recovery(spec, cfg), twin)
            self.roles[spec.name] = (spec, role)
        self.roles = {s.name: self.roles[s.name] for s in specs}  # in the order asked for

    def step(
        self, k: int, z: Statement | None, feed: Feed, only: Iterable[str] | None = None
    ) -> dict[str, Estimate]:
        """Step the primaries (those named in ``only``, in their order; default all) on their
        own ``z`` (None: it never came) and what ``feed`` gives each by its role.

        A twin shared with a robust primary is not stepped again: its estimate is the one the
        robust primary's step made, so step the robust one first.
        """
        out = {}
        for name in self.roles if only is None else only:
            spec, role = self.roles[name]
            t0 = time.perf_counter()
            if name in self._twin_of:
                owner = self.roles[self._twin_of[name]][1]
                est = owner.twin_estimate
                if est is None:
                    raise RuntimeError(f"{name} is {self._twin_of[name]}'s twin: step that first")
                owner.twin_estimate = None
            else:
                est = role.step(z, feed(spec))
            dt = time.perf_counter() - t0
            used = None if name in self._twin_of else role.used
            record = StepRecord(k, name, spec.role, role.filter, est, dt, used, None, role.nis)
            _tell(self.collectors, record)
            out[name] = est
        return out

    def robust(self, name: str) -> bool:
        """Does primary ``name`` judge transfers (and step a twin inside its step)?"""
        return self.roles[name][1].policy is not None

    def used(self, name: str) -> bool:
        """Did its last step use a transfer, in any run?"""
        return _any(self.roles[name][1].used)

    def recovered(self, name: str) -> bool:
        """Did its last step reinitialise it (it had lost the track), in any run?"""
        return _any(self.roles[name][1].recovered)

    def rolled_back(self, name: str) -> bool:
        """Did its last step roll it back to its isolated twin, in any run?"""
        return _any(self.roles[name][1].rolled_back)


def _any(runs: NDArray[np.bool_] | None) -> bool:
    return runs is not None and bool(runs.any())


# ---- both halves, for a batch of runs ---------------------------------------------------------


def source_links(names: Sequence[str], setup: Setup) -> list[Link]:
    """(source filter, source id) of every source filter to run: those the TL filters listen to,
    and those asked for by name (for every source)."""
    ids = setup.source_ids
    pairs = []
    for spec in (parse(n) for n in dict.fromkeys(names)):
        if spec.role in ("tl", "robust"):
            pairs += [(source_name(spec, setup.cfg, sid), sid) for sid in ids]
    pairs += [
        (spec.name, sid) for spec in map(parse, names) if spec.role == "source" for sid in ids
    ]
    return list(dict.fromkeys(pairs))


def primary_specs(names: Sequence[str]) -> list[FilterSpec]:
    """The primary filters among ``names`` (no source filter), each once."""
    return [s for s in (parse(n) for n in dict.fromkeys(names)) if s.role != "source"]


class Driver:
    """Every filter of ``names`` (and the sources its TL filters need) over a batch of runs.

    ``setups`` may add configurations that differ from the first only in the primary's sensor
    noise (an intensity sweep): the sources step once and feed the primaries of each.

    Operators with their own periods, phases and clocks (:mod:`tltrack.config.timeline`) are
    stepped by :meth:`tick`, one truth-grid tick at a time; :meth:`step` is the paper's
    synchronous step k, which is tick k there.
    """

    def __init__(
        self,
        setups: Sequence[Setup],
        names: Sequence[str],
        x0_hat: Array,
        runs: Sequence[int],
        *,
        channel: Channel | None = None,
        collectors: Sequence[Sequence[Collector]] = (),
    ) -> None:
        """``collectors[i]`` hear of setup i's filters (the sources' steps go to every one)."""
        self.setups = list(setups)
        base = self.setups[0]
        self.timeline = base.timeline
        hear = list(collectors) or [[] for _ in self.setups]
        everyone = [c for cs in hear for c in cs]
        self.channel: Channel = channel or Direct(ahead=self.timeline.sends_ahead)
        self.sources = Sources(base, source_links(names, base), x0_hat, runs, everyone)
        specs = primary_specs(names)
        self.primaries = [
            Primaries(s, specs, x0_hat, runs, cs) for s, cs in zip(self.setups, hear, strict=True)
        ]

    def step(self, k: int, z: Sequence[Mapping[str, Statement | None]]) -> None:
        """Step k of synchronous operators: ``z[i]`` maps each sensor id of setup i to its z_k
        (the sources' are read from the first)."""
        if not self.timeline.synchronous:
            raise ValueError("operators with their own periods, phases or clocks step by tick()")
        self.tick(k, z)

    def tick(self, n: int, z: Sequence[Mapping[str, Statement | None]]) -> None:
        """Truth-grid tick n: the sources that sample now step, each sending its transfers for
        the primary's samples until its next step (:meth:`Timeline.targets
        <tltrack.config.timeline.Timeline.targets>`), then the primary steps if it samples now.
        ``z[i]`` maps each sensor id of setup i that samples at n to its statement."""
        now = self.timeline.at(n)
        for sid, k in now.items():
            if sid == PRIMARY:
                continue
            links = [link for link in self.sources.roles if link[1] == sid]
            for link, transfer in self.sources.step(k, z[0], only=links).items():
                for j, _horizon, sent in self.sources.sends(link, k, transfer):
                    self.channel.send(link, j, sent)
        if PRIMARY not in now:
            return
        k = now[PRIMARY]
        cfg = self.setups[0].cfg
        ids = self.setups[0].source_ids

        def feed(spec: FilterSpec) -> list[Statement]:
            if spec.role in ("tl", "robust"):
                got = (self.channel.receive((source_name(spec, cfg, i), i), k) for i in ids)
                return [t for t in got if t is not None]
            if spec.role == "fusion":
                return [o for i in ids if (o := z[0].get(i)) is not None]
            return []

        for zi, half in zip(z, self.primaries, strict=True):
            half.step(k, zi[PRIMARY], feed)
