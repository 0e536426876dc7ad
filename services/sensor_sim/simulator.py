"""Publishes episodes: EpisodeStart, then for each tick n of the truth grid a Tick on the world
clock, the truth (referee only) and, in the single-router topology, the measurement of each
sensor that samples at n (its own step k, :mod:`tltrack.config.timeline`) on its owner's key,
then EpisodeEnd. On the paper's shared clock tick n is every sensor's step n. In the federated
topology (``--measurements false``) each operator's own sensor service answers the Tick instead,
so no raw data passes through the referee.

The truth and measurements of episode i are run ``first_run + i`` of ``tltrack experiment`` with
the same configuration: the same per-run random streams, so trackers can replay it exactly.
Before the first episode it waits for the liveliness tokens of the services it feeds, so the
services may start in any order.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, FilePath, field_validator, model_validator
from pydantic_settings import NoDecode, SettingsConfigDict
from tltrack.config import Config, load_config
from tltrack.engine.scenario import Run, simulate
from tltrack.engine.scene import primary_scan
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.live import replay
from tltrack.live.service import Service, ServiceSettings, load_settings, setup_logging
from tltrack.wire import keys
from tltrack.wire.messages import EpisodeEnd, EpisodeStart, Measurement, Tick, Truth, encode
from tltrack.wire.transport import LivelinessWatcher, Queryable, split_list

log = logging.getLogger("sensor_sim")
NAME = "sensor_sim"


#: the tokens sensor_sim awaits by default: the default stack's trackers and scorer
WAIT_FOR = ("source/s1:source_tracker", "primary:primary_tracker", "referee:scorer")


class Settings(ServiceSettings):
    """Environment ``TLTRACK_SIM_<FIELD>`` or ``--<field>``."""

    model_config = SettingsConfigDict(
        env_prefix="TLTRACK_SIM_", cli_prog_name=NAME, env_ignore_empty=True
    )

    # The experiment's fields, passed to the config, which validates them (tltrack.config)
    config: Path | None = Field(None, description="TOML/JSON experiment config")
    scenario: str | None = Field(None, description="the config's scenario")
    preset: str | None = Field(None, description="the config's preset")
    truth: str | None = Field(None, description="the config's truth mode")
    truth_file: Path | None = Field(None, description="a recorded track (CSV) as the truth")
    seed: int | None = Field(None, description="the config's seed")
    steps: int | None = Field(None, description="the config's K, steps per episode")
    particles: int | None = Field(None, description="the config's particles")
    primary_intensity: float | None = Field(None, description="the config's primary_intensity")
    episodes: int = Field(1, ge=1)
    first_run: int = Field(0, ge=0, description="run index of the first episode")
    episode_prefix: str = Field("ep", pattern=r"^[A-Za-z0-9_-]{1,40}$")
    pace: float = Field(20.0, ge=0, description="steps per second; 0 = as fast as possible")
    lead_s: float = Field(
        0.5, ge=0, le=60, description="wait from an episode's start to its first tick"
    )
    realtime: bool = Field(False, description="pace at one tick of the truth grid per its period")
    replay_csv: FilePath | None = Field(None, description="publish recorded measurements instead")
    measurements: bool = Field(
        True, description="publish every sensor's measurements (false: each operator's sensor)"
    )
    wait_for: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: list(WAIT_FOR),
        description="operator:service tokens to await before starting",
    )
    #: a day at most: a longer wait overflows the clock's deadline (inf crashed the wait)
    wait_timeout_s: float = Field(60.0, gt=0, le=86_400)
    linger_s: float = Field(
        1.0, ge=0, le=3600, description="wait before closing, so the link drains"
    )

    @model_validator(mode="after")
    def _replay(self) -> Settings:
        if self.replay_csv and not self.measurements:
            raise ValueError(
                "with --measurements false each operator's sensor replays its own rows "
                "(TLTRACK_SENSOR_REPLAY_CSV); give sensor_sim only --steps"
            )
        return self

    @field_validator("wait_for", mode="before")
    @classmethod
    def _list(cls, v: Any) -> Any:
        """A JSON list, or tokens separated by commas (as the zenoh endpoints are)."""
        return split_list(v)

    @field_validator("wait_for")
    @classmethod
    def _tokens(cls, v: list[str]) -> list[str]:
        """Each an ``operator:service`` that can be a token's key (a wrong one would be waited
        for until the timeout, or crash the wait)."""
        for token in v:
            operator, sep, service = token.partition(":")
            if not sep:
                raise ValueError(f"{token!r} is not operator:service, e.g. primary:primary_tracker")
            keys.alive(operator, service)  # ValueError naming the bad part
        return v

    def load_config(self) -> Config:
        over: dict[str, Any] = {
            "scenario": self.scenario,
            "preset": self.preset,
            "truth": self.truth,
            "seed": self.seed,
            "K": self.steps,
            "particles": self.particles,
            "primary_intensity": self.primary_intensity,
            "truth_file": self.truth_file,
        }
        return load_config(self.config, **over)


class Simulator:
    def __init__(self, settings: Settings, cfg: Config, svc: Service) -> None:
        self.s, self.cfg, self.svc = settings, cfg, svc
        self.setup = setup = Setup(cfg)
        self.layout = setup.layout
        self.sensors = [PRIMARY, *(src.id for src in cfg.sources)] if settings.measurements else []
        if modelled := [src.id for src in cfg.sources if src.link is not None]:
            log.warning(
                "sources %s: a config's link is the engine's model; live, the real link applies",
                ", ".join(modelled),
            )
        self.recorded = (
            replay.load(settings.replay_csv, setup, self.sensors) if settings.replay_csv else None
        )
        if self.recorded is not None:
            self.cfg = cfg.with_(K=len(self.recorded))

    @property
    def period(self) -> float:
        if self.s.realtime:
            return self.cfg.timeline.grid_s
        return 1.0 / self.s.pace if self.s.pace > 0 else 0.0

    def wait_for_services(self) -> bool:
        wanted = [keys.alive(*w.split(":", 1)) for w in self.s.wait_for]
        if not wanted:
            return True
        with LivelinessWatcher(self.svc.session, keys.ALIVE) as watcher:
            deadline = time.monotonic() + self.s.wait_timeout_s
            for key in wanted:
                left = deadline - time.monotonic()
                if left <= 0 or not watcher.wait_until(key, True, left):
                    log.error("gave up waiting for %s", key)
                    return False
        log.info("all %d services alive", len(wanted))
        return True

    def run_episode(self, i: int) -> None:
        run = self.s.first_run + i
        e = f"{self.s.episode_prefix}-r{run}"
        sim = None if self.recorded is not None else simulate(self.setup, run)
        timeline = self.cfg.timeline
        if sim is not None:  # per tick: each sensor that samples then, its step and its scan
            scans = [
                {sid: (k, sim.detections(sid, k)) for sid, k in timeline.at(n).items()
                 if sid in self.sensors}
                for n in range(1, timeline.ticks + 1)
            ]  # fmt: skip
        else:
            scans = [{sid: (k, z) for sid, z in row.items()} for k, row in
                     enumerate(self.recorded or [], start=1)]  # fmt: skip
        start = EpisodeStart(
            episode=e,
            sender=NAME,
            k=0,
            t_sensor=time.time(),
            run=run,
            config=self.cfg.model_dump(mode="json"),
            K=self.cfg.K,
            steps_per_sec=1.0 / self.period if self.period else 0.0,
        )
        self.svc.publish(keys.episode(e), start)
        log.info("episode %s: run %d, %d steps", e, run, self.cfg.K)
        # a service that (re)starts mid-episode asks for the start it missed
        with Queryable(self.svc.session, keys.episode(e), lambda _params: encode(start)):
            # Every service opens the episode first; a sensor regenerates its truth from the
            # seeds (58 ms at K = 5000). Ticks sent meanwhile would queue behind that work.
            self.svc.stop.wait(self.s.lead_s)
            self._publish_steps(e, scans, sim)

    def _truth(self, e: str, n: int, t: float, sim: Run) -> Truth:
        """The truth at tick n, with the primary's scan as drawn if it samples then."""
        x = sim.truth[n]
        k = self.cfg.timeline.at(n).get(PRIMARY)
        drawn = None if k is None else primary_scan(self.setup, sim, k)
        return Truth(
            episode=e,
            sender=NAME,
            k=n,
            t_sensor=t,
            x=x,
            pos=self.layout.position(x),
            scan=drawn[0] if drawn else [],
            scan_clutter=drawn[1].tolist() if drawn else [],
        )

    def _publish_steps(
        self, e: str, scans: list[dict[str, tuple[int, NDArray[np.float64]]]], sim: Run | None
    ) -> None:
        """Tick n's Tick, truth (with the primary's scan as drawn) and the scan of each sensor
        that samples then (``scans[n - 1]``: its step k and detections) on its owner's key."""
        t_next = time.monotonic()
        n = 0
        for n in range(1, len(scans) + 1):
            if self.svc.stop.is_set():
                break
            t_next += self.period
            t = time.time()
            self.svc.publish(keys.clock(e), Tick(episode=e, sender=NAME, k=n, t_sensor=t))
            if sim is not None:
                self.svc.publish(keys.truth(e), self._truth(e, n, t, sim))
            for sid, (k_own, z) in scans[n - 1].items():
                self.svc.publish(
                    keys.meas(sid, e),
                    Measurement(
                        episode=e,
                        sender=NAME,
                        k=k_own,
                        t_sensor=time.time(),  # when this sensor measures: its publication
                        sensor=sid,
                        z=z,
                    ),
                )
            self.svc.count("steps")
            self.svc.publish_stats()
            if (pause := t_next - time.monotonic()) > 0:
                self.svc.stop.wait(pause)
        done = not self.svc.stop.is_set()
        self.svc.publish(
            keys.episode(e),
            EpisodeEnd(
                episode=e,
                sender=NAME,
                k=n,
                t_sensor=time.time(),
                reason="complete" if done else "aborted",
                steps_sent=n if done else n - 1,  # ticks of the truth grid
            ),
        )


def main(argv: list[str] | None = None) -> None:
    settings = load_settings(Settings, argv)
    setup_logging(settings.log_level)
    try:
        cfg = settings.load_config()
    except ValueError as err:  # a ConfigError, or a truth file refused
        log.error("invalid configuration: %s", err)
        raise SystemExit(2) from None
    if settings.replay_csv and not cfg.timeline.synchronous:
        log.error(
            "a replayed file's step k is every sensor's, on one clock; the config gives an "
            "operator its own period_s, phase_s or clock_offset_s"
        )
        raise SystemExit(2)
    with Service(NAME, keys.REFEREE, settings.zenoh) as svc:
        svc.announce()
        try:
            sim = Simulator(settings, cfg, svc)
        except replay.ReplayError as err:
            log.error("%s", err)
            raise SystemExit(2) from None
        if not sim.wait_for_services():
            raise SystemExit(3)
        for i in range(settings.episodes):
            if svc.stop.is_set():
                break
            sim.run_episode(i)
        # Closing a session may drop what is still queued for the link: at full pace the last
        # steps and the EpisodeEnd would be lost. Give the link time to drain first.
        svc.stop.wait(settings.linger_s)
