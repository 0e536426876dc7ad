"""Algorithm 1 as a service: step on each measurement in order, publish estimate and transfer.

Beside them, a heartbeat every ``heartbeat_s`` that reaches the primary over the direct link
only (:mod:`tltrack.live.heartbeat`): its silence tells the primary that link is cut.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from functools import partial

from pydantic import Field
from pydantic_settings import SettingsConfigDict
from tltrack.config import Config, FilterKindName
from tltrack.filters.kinds import FILTERS
from tltrack.filters.warm import warm_up
from tltrack.live.episodes import StepQueue, TrackedEpisodes
from tltrack.live.heartbeat import HeartbeatSender
from tltrack.live.service import Service, ServiceSettings, load_settings, setup_logging
from tltrack.live.tracking import SourceEpisode, StepReport
from tltrack.wire import admission, keys
from tltrack.wire.messages import EpisodeStart, Measurement, Schedule
from tltrack.wire.transport import Received, decode_received

log = logging.getLogger("source_tracker")
NAME = "source_tracker"


class Settings(ServiceSettings):
    """Environment ``TLTRACK_SOURCE_<FIELD>`` or ``--<field>``."""

    model_config = SettingsConfigDict(
        env_prefix="TLTRACK_SOURCE_", cli_prog_name=NAME, env_ignore_empty=True
    )

    source_id: str = Field("s1", pattern=r"^[A-Za-z0-9_-]{1,32}$", description="operator id")
    filter: FilterKindName = Field("rpf", description="filter kind")
    recovery: bool = Field(True, description="reinitialise a particle filter that lost track")
    max_episodes: int = Field(4, ge=1, le=1000, description="episodes tracked at once")
    gap_timeout_s: float = Field(1.0, gt=0, description="predict through a step missing this long")
    heartbeat_s: float = Field(
        0.1, gt=0, le=10, description="heartbeat period on the direct link to the primary"
    )


@dataclass
class Episode:
    start: EpisodeStart
    tracker: SourceEpisode
    steps: StepQueue[Measurement] = field(default_factory=StepQueue)


class SourceTracker:
    def __init__(self, settings: Settings, svc: Service) -> None:
        self.s, self.svc = settings, svc
        self.episodes: TrackedEpisodes[Episode] = TrackedEpisodes(settings.max_episodes, self._open)

    def handle(self, item: Received) -> None:
        info = self.svc.key_info(item)
        if info is None:
            return
        if info.kind == "episode":
            self.episodes.handle(item, self.svc.rejects, self.s.recovery)
        elif info.kind == "source_meas" and info.episode is not None:
            z = decode_received(item, Measurement, self.svc.rejects)
            if z is not None:
                self.episodes.offer(info.episode, item.key, z, self.svc.rejects)
        elif info.kind == "schedule" and info.episode is not None:
            schedule = decode_received(item, Schedule, self.svc.rejects)
            if schedule is not None and (refused := admission.refusal(info, schedule)):
                self.svc.rejects.add(item.key, refused[0])
            elif schedule is not None:
                self._on_schedule(info.episode, item.key, schedule)

    def _on_schedule(self, e: str, key: str, schedule: Schedule) -> None:
        """The primary's schedule: the times its transfers are for (held until the episode
        opens here)."""
        ep = self.episodes.get(e)
        if ep is None:
            later = partial(self._on_schedule, e, key, schedule)
            self.episodes.hold(e, key, later, self.svc.rejects)
            return
        try:
            ep.tracker.heard(schedule)
        except ValueError as err:
            log.warning("episode %s: schedule refused: %s", e, err)
            self.svc.rejects.add(key, "invalid")

    def _open(self, start: EpisodeStart, cfg: Config) -> Episode | None:
        if self.s.source_id not in {src.id for src in cfg.sources}:
            log.info("episode %s has no source %s; ignored", start.episode, self.s.source_id)
            return None
        try:
            tracker = SourceEpisode(cfg, start.run, self.s.filter, self.s.source_id)
        except ValueError as err:  # a filter its config cannot make (a UKF's n + kappa <= 0)
            log.error("episode %s refused: %s", start.episode, err)
            self.svc.count("episodes_refused")
            return None
        log.info("episode %s (run %d): %s", start.episode, start.run, tracker.name)
        return Episode(start, tracker)

    def advance(self) -> None:
        """Step on every measurement in order; predict through steps missing too long."""
        self.episodes.expire(self.svc.rejects)
        for e, ep in self.episodes.items():
            if skipped := ep.steps.overdue(self.s.gap_timeout_s, time.monotonic()):
                log.warning("episode %s: no measurement for steps %s; predicting", e, skipped)
            for _ in skipped:  # on the clock, but nothing published: a gap, not a guess
                ep.tracker.step(None)
                self.svc.count("steps_skipped")
            while (z := ep.steps.ready()) is not None:
                ep.steps.release()
                self._step(e, ep, z)
            self.episodes.retire(e, ep.tracker.timeline.tick(self.s.source_id, ep.steps.next_k))

    def _step(self, e: str, ep: Episode, z: Measurement) -> None:
        k, t_sensor = z.k, z.t_sensor
        t_step, t0 = time.time(), time.perf_counter()
        est, eta = ep.tracker.step(z)
        step_ms = (time.perf_counter() - t0) * 1e3
        sid = self.s.source_id
        if not ep.tracker.addressed:  # off the shared clock, before the primary's schedule came
            self.svc.count("transfers_unaddressed")
        for j, t_apply, sent in ep.tracker.sends(eta):
            if j <= ep.start.K:  # none for the step past the primary's last
                message = partial(ep.tracker.transfer_message, sent, e, k, t_sensor, j, t_apply)
                self.svc.publish(keys.transfer(sid, e), message)
        StepReport(
            z,
            sid,
            ep.tracker.name,
            ep.tracker.layout,
            est,
            used=False,
            recovered=ep.tracker.recovered,
            t_step=t_step,
            step_ms=step_ms,
            nis=ep.tracker.monitor.last.get(ep.tracker.name),
        ).publish(self.svc, keys.source_estimate(sid, e))
        self.svc.count("steps")
        if not z.z:
            self.svc.count("empty_scans")


def main(argv: list[str] | None = None) -> None:
    settings = load_settings(Settings, argv)
    setup_logging(settings.log_level)
    if FILTERS.get(settings.filter).particle:
        warm_up()  # compiled kernels ready before the token says we are
    with Service(NAME, keys.source_operator(settings.source_id), settings.zenoh) as svc:
        inbox = svc.subscribe(
            keys.EPISODES, keys.source_meas(settings.source_id, keys.ANY), keys.SCHEDULES
        )
        tracker = SourceTracker(settings, svc)
        for item in svc.running_episodes():
            tracker.handle(item)
        svc.announce()
        beat = keys.heartbeat(settings.source_id)
        with HeartbeatSender(svc.session, beat, settings.heartbeat_s):
            while not svc.stop.is_set():
                for item in svc.drain(inbox, timeout=0.1):
                    tracker.handle(item)
                tracker.advance()
                svc.publish_stats()
