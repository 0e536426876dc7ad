"""An operator's sensor in the federated topology: on each Tick of sensor_sim's clock it
publishes its measurement of that step on its owner's key, through its owner's router.

The measurements of an episode of run r come from the same per-run stream as ``tltrack
experiment``'s (the truth regenerated from the seeds, then this sensor's noise), so the live
episode still equals the engine's; no Truth message is needed, and none is read. With
``replay_csv`` it replays this sensor's recorded rows instead (:mod:`tltrack.live.replay`'s schema;
the file holds this sensor's rows only, as an operator has no other).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, FilePath
from pydantic_settings import SettingsConfigDict
from tltrack.config import Config
from tltrack.config.timeline import Timeline
from tltrack.engine.scenario import reports, truth
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.live import replay
from tltrack.live.episodes import Episodes
from tltrack.live.service import Service, ServiceSettings, load_settings, setup_logging
from tltrack.wire import keys
from tltrack.wire.messages import EpisodeStart, Measurement, Tick
from tltrack.wire.transport import Received, decode_received

log = logging.getLogger("sensor")
NAME = "sensor"


class Settings(ServiceSettings):
    """Environment ``TLTRACK_SENSOR_<FIELD>`` or ``--<field>``."""

    model_config = SettingsConfigDict(
        env_prefix="TLTRACK_SENSOR_", cli_prog_name=NAME, env_ignore_empty=True
    )

    sensor: str = Field(
        PRIMARY, pattern=r"^[A-Za-z0-9_-]{1,32}$", description="'primary' or a source id"
    )
    max_episodes: int = Field(4, ge=1, le=1000, description="episodes measured at once")
    replay_csv: FilePath | None = Field(None, description="replay this sensor's recorded rows")


def operator(sensor: str) -> str:
    """The operator that owns ``sensor``: its key prefix and its router."""
    return keys.PRIMARY if sensor == PRIMARY else keys.source_operator(sensor)


class Sensor:
    """Zenoh orders samples per key, not across keys: a tick can overtake its episode's start
    (it is held until the start comes) and the episode's end can overtake its last ticks (the
    episode is kept until the tick of its last step has been served)."""

    def __init__(self, settings: Settings, svc: Service) -> None:
        self.s, self.svc = settings, svc
        #: episode -> its scans, (M_k, n_z) for its own steps k = 1..K_i, and its timeline
        self.episodes: Episodes[Measured] = Episodes(settings.max_episodes, self._open)

    def key(self, e: str) -> str:
        return keys.meas(self.s.sensor, e)

    def handle(self, item: Received) -> None:
        info = self.svc.key_info(item)
        if info is None or info.episode is None:
            return
        if info.kind == "episode":
            self.episodes.handle(item, self.svc.rejects, recovery=False)
        elif info.kind == "clock":
            tick = decode_received(item, Tick, self.svc.rejects)
            if tick is not None:
                self._on_tick(info.episode, item.key, tick)

    def _on_tick(self, e: str, key: str, tick: Tick) -> None:
        """Tick n: measure if this sensor samples then (its own step k)."""
        ep = self.episodes.get(e)
        if ep is None:
            self.episodes.hold(e, key, lambda: self._on_tick(e, key, tick), self.svc.rejects)
            return
        if not 1 <= tick.k <= ep.timeline.ticks:
            self.svc.rejects.add(key, "too_far")
            return
        k = ep.timeline.at(tick.k).get(self.s.sensor)
        if k is not None:
            self.svc.publish(
                self.key(e),
                Measurement(
                    episode=e,
                    sender=NAME,
                    k=k,
                    t_sensor=time.time(),  # its own time: the tick's hop here is the simulation's
                    sensor=self.s.sensor,
                    z=ep.scans[k - 1],
                ),
            )
            self.svc.count("steps")
        self.episodes.retire(e, tick.k + 1)

    def _open(self, start: EpisodeStart, cfg: Config) -> Measured | None:
        sid = self.s.sensor
        if sid != PRIMARY and sid not in {src.id for src in cfg.sources}:
            log.info("episode %s has no sensor %s; ignored", start.episode, sid)
            return None
        setup = Setup(cfg)
        if self.s.replay_csv is not None and not cfg.timeline.synchronous:
            log.error("episode %s: a replayed file's steps share one clock; refused", start.episode)
            self.svc.count("replay_refused")
            return None
        if self.s.replay_csv is None:
            z = reports(setup, start.run, truth(setup, start.run), sid)
        else:
            try:
                z = [scan[sid] for scan in replay.load(self.s.replay_csv, setup, [sid])]
            except replay.ReplayError as err:
                log.error("episode %s: nothing to replay: %s", start.episode, err)
                self.svc.count("replay_refused")
                return None
        how = f"replaying {self.s.replay_csv}" if self.s.replay_csv else "measuring"
        log.info("episode %s (run %d): %s as %s", start.episode, start.run, how, sid)
        return Measured(z, cfg.timeline)


@dataclass(frozen=True)
class Measured:
    """One episode of this sensor: its scans at its own steps, and when it takes them."""

    scans: list[NDArray[np.float64]]
    timeline: Timeline


def main(argv: list[str] | None = None) -> None:
    settings = load_settings(Settings, argv)
    setup_logging(settings.log_level)
    with Service(NAME, operator(settings.sensor), settings.zenoh) as svc:
        inbox = svc.subscribe(keys.EPISODES, keys.CLOCKS)
        sensor = Sensor(settings, svc)
        for item in svc.running_episodes():
            sensor.handle(item)
        svc.announce()
        while not svc.stop.is_set():
            for item in svc.drain(inbox, timeout=0.2):
                sensor.handle(item)
            sensor.episodes.expire(svc.rejects)
            svc.publish_stats()
