"""What the dashboard remembers: the last few episodes' truth and estimates, and the services'
liveliness and statistics.

Every input comes off the network, so everything is bounded: episodes (oldest evicted), estimate
streams per episode, steps per stream, services, and the keys of a service's statistics. The first
value of a step wins, as in the scorer's store, so a replayed message changes nothing.

RMSE follows the scorer for one episode: RMSE(k) is the position error at step k and the
episode's RMSE is its mean over k, so the page and ``/metrics`` agree with the scorer's table.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Literal

from tltrack.config.timeline import Timeline
from tltrack.engine.names import operator_of
from tltrack.engine.setup import PRIMARY, sensor_spec
from tltrack.filters import consistency
from tltrack.live import latency
from tltrack.wire.messages import EpisodeEnd, EpisodeStart, EstimateMsg, Truth, counts

Role = Literal["source", "tl", "isolated"]
Verdict = Literal["new", "duplicate", "capacity"]
XY = tuple[float, float]

MAX_SERVICES = 64
MAX_STATS_ENTRIES = 256  #: keys kept per mapping in a service's statistics


def _xy(pos: list[float]) -> XY:
    return (float(pos[0]), float(pos[1]))


def _thin(n: int, limit: int) -> range | list[int]:
    """Indices of at most ``limit`` evenly spaced items of ``n``, always keeping the last."""
    if n <= limit:
        return range(n)
    step = math.ceil(n / limit)
    idx = list(range(0, n, step))
    if idx[-1] != n - 1:
        idx.append(n - 1)
    return idx


@dataclass
class Track:
    """One filter's estimates in one episode, keyed by step."""

    role: Role
    operator: str = PRIMARY  #: whose samples its steps are (a source's id for a source's)
    pos: dict[int, XY] = field(default_factory=dict)
    used: dict[int, bool] = field(default_factory=dict)
    latency_ms: dict[int, float] = field(default_factory=dict)
    step_ms: dict[int, float] = field(default_factory=dict)
    stages: dict[int, tuple[float, ...]] = field(default_factory=dict)  #: tltrack.live.latency's
    err: dict[int, float] = field(default_factory=dict)  #: position error where truth is known
    err_sum: float = 0.0
    nis_window: float | None = None  #: the latest mean NIS over the filter's window
    windows: int = 0  #: steps with a full window
    above: int = 0  #: ... whose mean was above its 99% band
    below: int = 0  #: ... below it

    def record_nis(self, window: float | None, band: list[float] | None) -> None:
        if window is None or band is None:
            return
        self.nis_window = window
        self.windows += 1
        self.above += window > band[1]
        self.below += window < band[0]

    @property
    def consistency(self) -> str | None:
        """What the NIS says of the filter's model (tltrack.filters.consistency.verdict)."""
        if not self.windows:
            return None
        return consistency.verdict(self.above / self.windows, self.below / self.windows)

    def set_error(self, k: int, truth: XY) -> float:
        x, y = self.pos[k]
        e = math.hypot(x - truth[0], y - truth[1])
        self.err[k] = e
        self.err_sum += e
        return e

    @property
    def rmse(self) -> float | None:
        return self.err_sum / len(self.err) if self.err else None


@dataclass
class Episode:
    id: str
    run: int | None = None
    K: int | None = None
    steps_per_sec: float | None = None
    started: float | None = None
    ended: str | None = None  #: the end reason once EpisodeEnd arrived
    sensors: dict[str, tuple[XY, str]] = field(default_factory=dict)  #: id -> (where, kind)
    truth: dict[int, XY] = field(default_factory=dict)  #: by tick of the truth grid
    tracks: dict[str, Track] = field(default_factory=dict)
    #: when each operator samples (None until the start): a filter's step k is a truth tick
    timeline: Timeline | None = None

    def tick(self, track: Track, k: int) -> int:
        """The truth's tick of a filter's step k (k itself on the paper's shared clock)."""
        return k if self.timeline is None else self.timeline.tick(track.operator, k)

    def step(self, track: Track, n: int) -> int | None:
        """A filter's step at truth tick n, if its operator sampled then."""
        return n if self.timeline is None else self.timeline.at(n).get(track.operator)

    #: the latest step's scan of the primary as the simulation drew it: k, (x, y, is_clutter)
    scan: tuple[int, list[tuple[float, float, bool]]] = (0, [])


@dataclass(frozen=True)
class ErrorUpdate:
    """A newly known RMSE(k) of a filter, and its episode RMSE so far (for the metrics)."""

    filter: str
    k: int
    error: float
    rmse: float


@dataclass
class ServiceHealth:
    operator: str
    service: str
    alive: bool = False
    changed: float = 0.0  #: time.time() of the last liveliness change
    stats: dict[str, Any] = field(default_factory=dict)
    stats_at: float | None = None

    @property
    def name(self) -> str:
        return f"{self.operator}/{self.service}"


def _link_map(value: Any) -> dict[str, str]:
    """The primary's link to each source, ``up`` or ``cut`` (tltrack.live.heartbeat), from
    untrusted JSON: anything else is left out."""
    out: dict[str, str] = {}
    if isinstance(value, dict):
        for sid, state in value.items():
            if len(out) >= MAX_STATS_ENTRIES:
                break
            if isinstance(sid, str) and state in ("up", "cut"):
                out[sid[:64]] = state
    return out


def clean_stats(raw: dict[str, Any]) -> dict[str, Any]:
    """The parts of a service's statistics (an object: :func:`~tltrack.wire.messages.decode_stats`)
    the dashboard uses, each of the type it expects or left out."""
    rejected = raw.get("rejected")
    if not isinstance(rejected, dict):
        rejected = {}
    dropped = raw.get("dropped")
    return {
        "counters": counts(raw.get("counters"), MAX_STATS_ENTRIES),
        "rejected_by_key": counts(rejected.get("by_key"), MAX_STATS_ENTRIES),
        "rejected_by_reason": counts(rejected.get("by_reason"), MAX_STATS_ENTRIES),
        "dropped": dropped if type(dropped) is int and dropped >= 0 else 0,
        "links": _link_map(raw.get("links")),
    }


class State:
    """Thread-safe: the Zenoh loop writes, the web handlers read :meth:`snapshot`."""

    def __init__(
        self,
        max_episodes: int = 4,
        max_steps: int = 20_000,
        max_filters: int = 8,
        max_points: int = 2_000,
        poll_ms: int = 250,
    ) -> None:
        self.max_episodes, self.max_steps = max_episodes, max_steps
        self.max_filters, self.max_points, self.poll_ms = max_filters, max_points, poll_ms
        self._lock = threading.Lock()
        self._episodes: OrderedDict[str, Episode] = OrderedDict()
        self._services: dict[str, ServiceHealth] = {}
        self._received: dict[str, int] = {}
        self.version = 0  #: bumped on every change; the page skips redraws when it is unchanged
        self._cache: tuple[int, str | None, dict[str, Any]] | None = None

    # ---- writes (Zenoh thread) ------------------------------------------------------------

    def _episode(self, e: str) -> Episode:
        """The episode, created if unknown (the dashboard may start mid-episode)."""
        ep = self._episodes.get(e)
        if ep is None:
            ep = self._episodes[e] = Episode(e)
            while len(self._episodes) > self.max_episodes:
                self._episodes.popitem(last=False)
        return ep

    def on_received(self, pattern: str) -> None:
        with self._lock:
            if pattern in self._received or len(self._received) < MAX_STATS_ENTRIES:
                self._received[pattern] = self._received.get(pattern, 0) + 1

    def on_start(self, m: EpisodeStart) -> None:
        with self._lock:
            ep = self._episode(m.episode)
            self._episodes.move_to_end(m.episode)  # a new episode becomes the one on show
            ep.run, ep.K, ep.started = m.run, m.K, m.t_sensor
            ep.steps_per_sec = m.steps_per_sec
            cfg = m.parsed_config()  # validated on receipt
            ep.timeline = cfg.timeline
            for name, tr in ep.tracks.items():  # estimates that came before the start
                tr.operator = operator_of(name, [s.id for s in cfg.sources])
            ep.sensors = {}
            for sid in [PRIMARY, *(s.id for s in cfg.sources[:16])]:
                spec = sensor_spec(cfg, sid)
                ep.sensors[sid] = (_pair(spec.position), spec.kind)
            self.version += 1

    def on_end(self, m: EpisodeEnd) -> None:
        with self._lock:
            self._episode(m.episode).ended = m.reason
            self.version += 1

    def on_truth(self, m: Truth) -> tuple[Verdict, list[ErrorUpdate]]:
        with self._lock:
            ep = self._episode(m.episode)
            if m.k in ep.truth:
                return "duplicate", []
            if len(ep.truth) >= self.max_steps:
                return "capacity", []
            ep.truth[m.k] = t = _xy(m.pos)
            if m.k > ep.scan[0]:
                ep.scan = (
                    m.k,
                    [(x, y, c) for (x, y), c in zip(m.scan, m.scan_clutter, strict=True)],
                )
            updates = []
            for name, tr in ep.tracks.items():
                if (k := ep.step(tr, m.k)) is not None and k in tr.pos:
                    e = tr.set_error(k, t)
                    updates.append(ErrorUpdate(name, k, e, tr.rmse or 0.0))
            self.version += 1
            return "new", updates

    def on_estimate(
        self, role: Role, m: EstimateMsg, t_recv: float
    ) -> tuple[Verdict, ErrorUpdate | None]:
        with self._lock:
            ep = self._episode(m.episode)
            tr = ep.tracks.get(m.filter)
            if tr is None:
                if len(ep.tracks) >= self.max_filters:
                    return "capacity", None
                tl = ep.timeline
                sources = [] if tl is None else [sid for sid in tl.clocks if sid != tl.primary]
                operator = operator_of(m.filter, sources) if sources else PRIMARY
                tr = ep.tracks[m.filter] = Track(role, operator)
            if m.k in tr.pos:
                return "duplicate", None
            if len(tr.pos) >= self.max_steps:
                return "capacity", None
            tr.pos[m.k] = _xy(m.pos)
            tr.used[m.k] = m.transfer_used
            tr.latency_ms[m.k] = latency.end_to_end_ms(m.t_sensor, t_recv)
            tr.step_ms[m.k] = m.step_ms
            tr.record_nis(m.nis_window, m.nis_band)
            if (split := latency.of(m, t_recv)) is not None:
                tr.stages[m.k] = split
            update = None
            if (t := ep.truth.get(ep.tick(tr, m.k))) is not None:
                update = ErrorUpdate(m.filter, m.k, tr.set_error(m.k, t), tr.rmse or 0.0)
            self.version += 1
            return "new", update

    def nis_above_band(self, episode: str, name: str) -> float | None:
        """The share of filter ``name``'s full windows above their band in ``episode``."""
        with self._lock:
            ep = self._episodes.get(episode)
            tr = None if ep is None else ep.tracks.get(name)
            return tr.above / tr.windows if tr is not None and tr.windows else None

    def on_liveliness(self, operator: str, service: str, alive: bool) -> None:
        with self._lock:
            h = self._health(operator, service)
            if h is not None and h.alive != alive:
                h.alive, h.changed = alive, time.time()
                self.version += 1

    def on_stats(self, operator: str, service: str, raw: dict[str, Any]) -> None:
        """Record a service's statistics."""
        stats = clean_stats(raw)
        with self._lock:
            h = self._health(operator, service)
            if h is not None:
                if h.stats != stats:
                    self.version += 1
                h.stats, h.stats_at = stats, time.time()

    def _health(self, operator: str, service: str) -> ServiceHealth | None:
        name = f"{operator}/{service}"
        h = self._services.get(name)
        if h is None and len(self._services) < MAX_SERVICES:
            h = self._services[name] = ServiceHealth(operator, service)
        return h

    # ---- reads (web threads, metrics) -----------------------------------------------------

    def services(self) -> list[ServiceHealth]:
        """Copies, for the metrics collector."""
        with self._lock:
            return [
                ServiceHealth(h.operator, h.service, h.alive, h.changed, dict(h.stats), h.stats_at)
                for h in self._services.values()
            ]

    def snapshot(self, episode: str | None = None) -> dict[str, Any]:
        """Everything the page draws, as plain JSON-ready data (cached per version)."""
        with self._lock:
            if self._cache is not None and self._cache[:2] == (self.version, episode):
                return self._cache[2]
            snap = self._snapshot(episode)
            self._cache = (self.version, episode, snap)
            return snap

    def _snapshot(self, episode: str | None) -> dict[str, Any]:
        now = time.time()
        ep = self._episodes.get(episode) if episode else None
        if ep is None and self._episodes:
            ep = next(reversed(self._episodes.values()))
        services = [
            self._service_json(h, now)
            for h in sorted(self._services.values(), key=lambda h: h.name)
        ]
        by_reason: dict[str, int] = {}
        for h in self._services.values():
            for reason, n in h.stats.get("rejected_by_reason", {}).items():
                by_reason[reason] = by_reason.get(reason, 0) + n
        return {
            "version": self.version,
            "server_time": now,
            "poll_ms": self.poll_ms,
            "episodes": [
                {"id": e.id, "run": e.run, "K": e.K, "ended": e.ended}
                for e in self._episodes.values()
            ],
            "episode": None if ep is None else self._episode_json(ep),
            "services": services,
            "rejected": {
                "total": sum(s["rejected_total"] for s in services),
                "by_service": {s["name"]: s["rejected_total"] for s in services},
                "by_reason": by_reason,
            },
            "received": dict(self._received),
        }

    def _episode_json(self, ep: Episode) -> dict[str, Any]:
        truth = sorted(ep.truth.items())
        filters = []
        transfer: list[list[int]] = []
        for name, tr in sorted(ep.tracks.items(), key=lambda kv: (_ROLE_ORDER[kv[1].role], kv[0])):
            ks = sorted(tr.pos)
            errs = sorted(tr.err.items())
            used = sum(tr.used.values())
            filters.append(
                {
                    "name": name,
                    "role": tr.role,
                    "steps": len(ks),
                    "last_k": ks[-1] if ks else None,
                    "points": [
                        [k, *tr.pos[k]] for k in (ks[i] for i in _thin(len(ks), self.max_points))
                    ],
                    "error": [list(errs[i]) for i in _thin(len(errs), self.max_points)],
                    "rmse": tr.rmse,
                    "rmse_k": errs[-1][1] if errs else None,
                    "latency_ms": latency.percentiles(list(tr.latency_ms.values())),
                    "step_ms": latency.percentiles(list(tr.step_ms.values())),
                    "stages_ms": latency.p50(list(tr.stages.values())),
                    "transfer_used": used,
                    "transfer_skipped": len(ks) - used,
                    "nis_window": tr.nis_window,
                    "nis_above_band": tr.above / tr.windows if tr.windows else None,
                    "consistency": tr.consistency,
                }
            )
            if tr.role == "tl" and not transfer:
                transfer = [[k, int(tr.used[k])] for k in ks]
        last = max(
            [k for k, _ in truth[-1:]] + [max(tr.pos, default=0) for tr in ep.tracks.values()] + [0]
        )
        return {
            "id": ep.id,
            "run": ep.run,
            "K": ep.K,
            "steps_per_sec": ep.steps_per_sec,
            "started": ep.started,
            "ended": ep.ended,
            "last_k": last,
            "sensors": [
                {"name": n, "x": p[0], "y": p[1], "kind": kind}
                for n, (p, kind) in ep.sensors.items()
            ],
            "truth": [[truth[i][0], *truth[i][1]] for i in _thin(len(truth), self.max_points)],
            "scan": {"k": ep.scan[0], "points": [[x, y, int(c)] for x, y, c in ep.scan[1]]},
            "filters": filters,
            "transfer": transfer,
        }

    @staticmethod
    def _service_json(h: ServiceHealth, now: float) -> dict[str, Any]:
        s = h.stats
        return {
            "name": h.name,
            "operator": h.operator,
            "service": h.service,
            "alive": h.alive,
            "since_s": now - h.changed if h.changed else None,
            "stats_age_s": None if h.stats_at is None else now - h.stats_at,
            "counters": s.get("counters", {}),
            "rejected_total": sum(s.get("rejected_by_reason", {}).values()),
            "rejected_by_reason": s.get("rejected_by_reason", {}),
            "dropped": s.get("dropped", 0),
            "links": s.get("links", {}),
        }


_ROLE_ORDER: dict[str, int] = {"source": 0, "tl": 1, "isolated": 2}


def _pair(v: Any) -> XY:
    if (
        isinstance(v, list | tuple)
        and len(v) == 2
        and all(isinstance(c, int | float) and math.isfinite(c) for c in v)
    ):
        return (float(v[0]), float(v[1]))
    return (0.0, 0.0)
