"""Algorithm 2 as a service.

Step k needs z_k and, from every source of the episode, the transfer with ``k_apply == k``. The
primary waits for missing transfers at most ``deadline_ms`` after z_k is ready, and not at all for
a source whose liveliness token is gone, nor for one whose heartbeat has been silent for two of its
periods (``heartbeat_s``): its direct link is cut (:mod:`tltrack.live.heartbeat`), though its token
still arrives through the referee's router. Then it takes the step with what it has (an isolated
step if nothing). ``lockstep`` waits without a deadline, and whatever the heartbeat says, as long
as the source's token lives: for tests and exact replays.

The isolated twin is there only for comparison. It steps ``twin_delay_ms`` after the TL estimate
is out, when that estimate's hops to its receivers no longer compete with it for the CPU.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass, field

from pydantic import Field
from pydantic_settings import SettingsConfigDict
from tltrack.config import PRIMARY, Config, FilterKindName
from tltrack.config.timeline import US
from tltrack.filters.kinds import FILTERS
from tltrack.filters.warm import warm_up
from tltrack.live.episodes import StepQueue, TrackedEpisodes
from tltrack.live.heartbeat import LinkWatch
from tltrack.live.service import Service, ServiceSettings, load_settings, setup_logging
from tltrack.live.tracking import PrimaryEpisode, StepReport
from tltrack.wire import admission, keys
from tltrack.wire.messages import EpisodeStart, Measurement, Schedule, Transfer
from tltrack.wire.transport import Received, decode_received

log = logging.getLogger("primary_tracker")
NAME = "primary_tracker"
SOURCE_TRACKER = "source_tracker"


class Settings(ServiceSettings):
    """Environment ``TLTRACK_PRIMARY_<FIELD>`` or ``--<field>``."""

    model_config = SettingsConfigDict(
        env_prefix="TLTRACK_PRIMARY_", cli_prog_name=NAME, env_ignore_empty=True
    )

    filter: FilterKindName = Field("rpf", description="filter kind")
    robust: bool = Field(False, description="robust-tl: judge each transfer before using it")
    deadline_ms: float = Field(250.0, gt=0, le=60_000, description="longest wait for a transfer")
    transfer_tolerance_ms: float = Field(
        1.0,
        ge=0,
        le=60_000,
        description="a transfer's t_apply may differ this much from its sample's time",
    )
    clock_skew_ms: float = Field(
        1000.0,
        gt=0,
        le=3_600_000,
        description="the hosts' wall clocks differ by up to this: a transfer stamped later than "
        "now by more is refused",
    )
    lockstep: bool = Field(False, description="wait for every live source's transfer, no deadline")
    heartbeat_s: float = Field(
        0.1,
        gt=0,
        le=10,
        description="the sources' heartbeat period: two to three missed (as the link's jitter "
        "asks) mean a cut link",
    )
    gap_timeout_s: float = Field(
        1.0, gt=0, le=3600, description="step without a measurement missing this long"
    )
    twin_delay_ms: float = Field(
        2.0, ge=0, le=1000, description="step the isolated twin this long after the TL estimate"
    )
    recovery: bool = Field(True, description="reinitialise a particle filter that lost track")
    #: each holds its filters' clouds: a thousand at 6000 particles is some 2 GB
    max_episodes: int = Field(4, ge=1, le=1000, description="episodes tracked at once")


@dataclass
class Episode:
    start: EpisodeStart
    tracker: PrimaryEpisode
    sources: list[str]
    steps: StepQueue[Measurement] = field(default_factory=StepQueue)
    transfers: dict[int, dict[str, Transfer]] = field(default_factory=dict)
    ready_since: float | None = None  # when z_{next_k} was first ready (monotonic)
    #: the twin's steps still to take, in order: (z_k or None for a gap, when due, monotonic)
    twins: deque[tuple[Measurement | None, float]] = field(default_factory=deque)


class PrimaryTracker:
    def __init__(self, settings: Settings, svc: Service) -> None:
        self.s, self.svc = settings, svc
        self.episodes: TrackedEpisodes[Episode] = TrackedEpisodes(settings.max_episodes, self._open)
        self.alive: set[str] = set()  # source ids whose tracker token is up
        self.seen: set[str] = set()  # ... or ever was
        self.links = LinkWatch(settings.heartbeat_s)  # whose direct link is up, by heartbeat

    # ---- inputs ---------------------------------------------------------------------------

    def handle(self, item: Received) -> None:
        info = self.svc.key_info(item)
        if info is None:
            return
        if info.kind == "alive" and info.source is not None:
            if info.service == SOURCE_TRACKER:
                self._on_liveliness(info.source, item.is_put)
        elif info.kind == "heartbeat" and info.source is not None:
            if item.is_put and not item.payload:
                self._on_heartbeat(info.source, item.t_recv)
            else:
                self.svc.rejects.add(item.key, "invalid")  # a heartbeat carries nothing
        elif info.kind == "episode":
            self.episodes.handle(item, self.svc.rejects, self.s.recovery)
        elif info.kind == "primary_meas" and info.episode is not None:
            z = decode_received(item, Measurement, self.svc.rejects)
            if z is not None:
                self.episodes.offer(info.episode, item.key, z, self.svc.rejects)
        elif info.kind == "transfer" and info.episode is not None and info.source is not None:
            t = decode_received(item, Transfer, self.svc.rejects)
            if t is not None and (refused := admission.refusal(info, t)):
                self.svc.rejects.add(item.key, refused[0])  # none may speak for another source
            elif t is not None:
                self._on_transfer(info.episode, info.source, item.key, t)

    def _on_liveliness(self, sid: str, up: bool) -> None:
        log.info("source %s %s", sid, "alive" if up else "gone")
        if up:
            self.alive.add(sid)
            self.seen.add(sid)
        else:
            self.alive.discard(sid)

    def _on_heartbeat(self, sid: str, t_recv: float) -> None:
        """A heartbeat of ``sid``, dated when it arrived (not when this loop got to it)."""
        arrived = time.monotonic() - max(0.0, time.time() - t_recv)
        if self.links.beat(sid, arrived):
            log.info("link to source %s back: waiting for its transfers again", sid)
            self._links_changed()
        elif sid not in self.svc.status.get("links", {}):
            self._links_changed()

    def check_links(self) -> None:
        """Mark the links whose heartbeat went silent as cut (call it once the inbox is read)."""
        for sid in self.links.check(time.monotonic()):
            log.warning(
                "link to source %s cut (no heartbeat for %.0f ms): stepping without its transfers",
                sid,
                self.links.timeout_s(sid) * 1e3,
            )
            self.svc.count("link_cuts")
            self._links_changed()

    def _links_changed(self) -> None:
        self.svc.status["links"] = self.links.states()
        self.svc.publish_stats(force=True)  # the dashboard shows a change at once

    def _open(self, start: EpisodeStart, cfg: Config) -> Episode | None:
        try:
            tracker = PrimaryEpisode(cfg, start.run, self.s.filter, self.s.robust)
        except ValueError as err:  # not comparable, or a filter its config cannot make
            log.error("episode %s refused: %s", start.episode, err)
            self.svc.count("episodes_refused")
            return None
        log.info("episode %s (run %d): %s and %s", start.episode, start.run, *tracker.names)
        self._announce(start.episode, tracker)
        return Episode(start, tracker, [s.id for s in cfg.sources])

    def _announce(self, e: str, tracker: PrimaryEpisode) -> None:
        """Publish this primary's schedule for its sources, off the paper's shared clock (on
        it, each transfer is simply for k + 1). Again at each step, for a source that joins
        late."""
        if not tracker.timeline.synchronous:
            t0 = tracker.timeline.stamp(PRIMARY, 0) / US
            msg = Schedule(episode=e, sender=keys.PRIMARY, k=0, t_sensor=time.time(),
                           period_s=tracker.cfg.Ts, t0_s=t0)  # fmt: skip
            self.svc.publish(keys.schedule(e), msg)

    def _on_transfer(self, e: str, sid: str, key: str, t: Transfer) -> None:
        """Keep a transfer of source ``sid`` (its sender, :meth:`handle` checked) for its step."""
        ep = self.episodes.get(e)
        if ep is None:
            self.episodes.hold(e, key, lambda: self._on_transfer(e, sid, key, t), self.svc.rejects)
            return
        if t.k_apply < ep.steps.next_k:
            self.svc.rejects.add(key, "late_transfer")
            return
        if not self._on_time(ep, t):
            self.svc.rejects.add(key, "wrong_time")
            return
        if t.t_sensor - time.time() > self.s.clock_skew_ms / 1e3:  # made later than now
            self.svc.rejects.add(key, "from_the_future")
            return
        if t.k_apply >= ep.steps.next_k + ep.steps.window:
            self.svc.rejects.add(key, "too_far")
            return
        slot = ep.transfers.setdefault(t.k_apply, {})
        if sid in slot:
            self.svc.rejects.add(key, "duplicate")
            return
        slot[sid] = t

    def _on_time(self, ep: Episode, t: Transfer) -> bool:
        """Is a transfer for the time of the sample it names, on this primary's schedule? On
        the paper's shared clock it may leave ``t_apply`` out; otherwise it must give it within
        ``transfer_tolerance_ms``: never applied to another time. (One stamped, by the wall clock
        of the host that made it, later than now by more than ``clock_skew_ms`` is refused too:
        ``from_the_future``.)
        """
        timeline = ep.tracker.timeline
        if t.t_apply is None:
            return timeline.synchronous
        own = timeline.stamp(PRIMARY, t.k_apply) / US
        return abs(t.t_apply - own) <= self.s.transfer_tolerance_ms / 1e3

    # ---- stepping -------------------------------------------------------------------------

    def advance(self) -> float | None:
        """Take every step that can be taken; the seconds until the next deadline, if any."""
        self.episodes.expire(self.svc.rejects)
        self.check_links()  # a step waiting for a source whose link is cut waits no longer
        wait: float | None = None
        for e, ep in self.episodes.items():
            if skipped := ep.steps.overdue(self.s.gap_timeout_s, time.monotonic()):
                log.warning("episode %s: no measurement for steps %s; predicting", e, skipped)
            for k in skipped:  # on the clock, but nothing published: a gap, not a guess
                ep.tracker.step(None, ep.transfers.pop(k, {}))
                self._twin_later(e, ep, None)
                self.svc.count("steps_skipped")
            while (z := ep.steps.ready()) is not None:
                now = time.monotonic()
                if ep.ready_since is None:
                    ep.ready_since = now
                timeline = ep.tracker.timeline
                # the paper's source sends nothing for k = 1; others by their schedule
                have = ep.transfers.get(z.k, {}) if z.k > 1 or not timeline.synchronous else {}
                waiting = [
                    sid
                    for sid in ep.sources
                    if sid not in have and timeline.expects(sid, z.k) and self._worth_waiting(sid)
                ]
                if waiting and not self.s.lockstep:
                    left = ep.ready_since + self.s.deadline_ms / 1e3 - now
                    if left > 0:
                        wait = _sooner(wait, left)
                        break
                    self.svc.count("deadlines_passed")  # a live source's transfer came too late
                elif waiting:
                    break  # lock-step: wait as long as the source lives
                ep.steps.release()
                ep.transfers.pop(z.k, None)
                ep.ready_since = None
                self._step(e, ep, z, have)
            if (due := self._step_twins(e, ep)) is not None:
                wait = _sooner(wait, due)
            else:
                self.episodes.retire(e, ep.tracker.timeline.tick(PRIMARY, ep.steps.next_k))
        return wait

    def _worth_waiting(self, sid: str) -> bool:
        """A source whose token went away is not waited for, nor one whose link is cut; an unseen
        one is (it may be late). Lock-step waits as long as the token lives, whatever the
        heartbeat says: a loaded host can delay a heartbeat past its timeout (a false cut), and an
        exact replay must not step on without a transfer that is still coming."""
        alive = sid in self.alive or sid not in self.seen
        return alive and (self.s.lockstep or not self.links.is_cut(sid))

    def _step(self, e: str, ep: Episode, z: Measurement, transfers: dict[str, Transfer]) -> None:
        """The TL estimate goes out first; the isolated twin's later (:meth:`_step_twins`)."""
        tracker = ep.tracker
        t_step, t0 = time.time(), time.perf_counter()
        tl = tracker.step(z, transfers)
        tl_ms = (time.perf_counter() - t0) * 1e3
        used = tracker.used_transfer
        StepReport(
            z,
            keys.PRIMARY,
            tracker.tl_name,
            tracker.layout,
            tl,
            used,
            tracker.recovered[0],
            t_step,
            tl_ms,
            tracker.monitor.last.get(tracker.tl_name),
        ).publish(self.svc, keys.primary_estimate("tl", e))
        self._twin_later(e, ep, z)
        self._announce(e, tracker)
        self.svc.count("steps")
        if not z.z:
            self.svc.count("empty_scans")
        self.svc.count("steps_with_transfer" if used else "steps_without_transfer")
        if tracker.rolled_back:
            self.svc.count("rollbacks_to_isolated")

    def _twin_later(self, e: str, ep: Episode, z: Measurement | None) -> None:
        """Queue the twin's step of ``z``. A twin that stepped inside the TL step (robust) has
        its estimate already, and it goes out at once, before the next step replaces it."""
        inside = ep.tracker.twin_in_step
        delay = 0.0 if inside else self.s.twin_delay_ms / 1e3
        ep.twins.append((z, time.monotonic() + delay))
        if inside:
            self._step_twins(e, ep)

    def _step_twins(self, e: str, ep: Episode) -> float | None:
        """Take the twin's steps that are due, in order; the seconds until the next, if any."""
        while ep.twins:
            z, due = ep.twins[0]
            if (left := due - time.monotonic()) > 0:
                return left
            ep.twins.popleft()
            t_twin, t0 = time.time(), time.perf_counter()
            iso = ep.tracker.step_twin(z)
            iso_ms = (time.perf_counter() - t0) * 1e3
            if z is not None:  # a gap's prediction is not published
                StepReport(
                    z,
                    keys.PRIMARY,
                    ep.tracker.iso_name,
                    ep.tracker.layout,
                    iso,
                    False,
                    ep.tracker.recovered[1],
                    t_twin,
                    iso_ms,
                    ep.tracker.monitor.last.get(ep.tracker.iso_name),
                ).publish(self.svc, keys.primary_estimate("isolated", e))
        return None


def _sooner(a: float | None, b: float) -> float:
    return b if a is None else min(a, b)


def main(argv: list[str] | None = None) -> None:
    settings = load_settings(Settings, argv)
    setup_logging(settings.log_level)
    if FILTERS.get(settings.filter).particle:
        warm_up()  # compiled kernels ready before the token says we are
    with Service(NAME, keys.PRIMARY, settings.zenoh) as svc:
        inbox = svc.subscribe(keys.EPISODES, keys.PRIMARY_MEAS, keys.TRANSFERS, keys.HEARTBEATS)
        liveliness = svc.subscribe(
            keys.alive(keys.source_operator(keys.ANY), SOURCE_TRACKER), liveliness=True
        )
        tracker = PrimaryTracker(settings, svc)
        for item in svc.running_episodes():
            tracker.handle(item)
        svc.announce()
        wait: float | None = None
        while not svc.stop.is_set():
            for item in liveliness.drain():
                tracker.handle(item)
            # while a step waits for a transfer or the twin for its turn, poll liveliness at 50 Hz;
            # and wake up when a link's heartbeat is due
            timeout = 0.2 if wait is None else min(wait, 0.02)
            if (due := tracker.links.due(time.monotonic())) is not None:
                timeout = min(timeout, due + 1e-3)
            for item in svc.drain(inbox, timeout=timeout):
                tracker.handle(item)
            for item in liveliness.drain():
                tracker.handle(item)
            wait = tracker.advance()
            svc.publish_stats()
