"""The scorer service: subscribe to the truth and every estimate, persist, summarise, answer.

An episode is scored once it has ended and every filter has reported step K, or once no estimate
for it has arrived for ``grace_s`` after its end; then the summary table is printed. The current
summary (all episodes) answers gets on ``tltrack/scorer/summary`` as JSON. It is computed when
asked: a get returns the last one (computed at ``as_of``) and asks for a fresh one, ready within
about a second. A fresh one reads only the episodes not yet scored (a scored episode's scores are
kept, :class:`~tltrack.services.scorer.summary.Summarizer`), and a scorer nobody asks computes
none while an episode runs. A truth or an estimate
that overtakes its episode's start (another key, maybe another route) is held until the start
arrives (:mod:`tltrack.live.held`).
"""

from __future__ import annotations

import json
import logging
import sqlite3
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

from pydantic import Field
from pydantic_settings import SettingsConfigDict
from tltrack.config import PRIMARY
from tltrack.live.held import Held
from tltrack.live.service import Service, ServiceSettings, load_settings, setup_logging
from tltrack.live.summary import print_summary
from tltrack.services.scorer.store import Store
from tltrack.services.scorer.summary import Summarizer
from tltrack.wire import admission, keys
from tltrack.wire.messages import EpisodeEnd, EpisodeStart, EstimateMsg, Truth, decode_stats
from tltrack.wire.transport import Queryable, Received, decode_received

log = logging.getLogger("scorer")
NAME = "scorer"


class Settings(ServiceSettings):
    """Environment ``TLTRACK_SCORER_<FIELD>`` or ``--<field>``."""

    model_config = SettingsConfigDict(
        env_prefix="TLTRACK_SCORER_", cli_prog_name=NAME, env_ignore_empty=True
    )

    db: Path = Field(Path("tltrack-scorer.sqlite"), description="SQLite file")
    grace_s: float = Field(5.0, gt=0, description="wait for late estimates after an episode")


class Scorer:
    def __init__(self, settings: Settings, svc: Service, store: Store) -> None:
        self.s, self.svc, self.store = settings, svc, store
        self.K: dict[str, int] = dict(store.rows("SELECT episode, K FROM episodes"))
        #: per episode and filter: the steps it takes (its operator's, at its own rate)
        self.need: dict[str, dict[str, int]] = defaultdict(dict)
        self.expected: dict[str, int] = {}  # filters per episode: one per source, TL, isolated
        self.ended: dict[str, float] = {}  # episode -> monotonic time of its end
        self.last_seen: dict[str, float] = {}
        self.counts: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
        self.scored: set[str] = {
            e for (e,) in store.rows("SELECT episode FROM episodes WHERE ended IS NOT NULL")
        }
        self.summarizer = Summarizer(store)
        self.held = Held()
        self._summary = b"{}"
        self._summary_at = 0.0  # monotonic
        self._asked = threading.Event()
        self._lock = threading.Lock()
        self.refresh()

    def answer(self, _params: dict[str, str]) -> bytes:
        """The last summary; the main thread, which owns the store, computes a fresh one."""
        self._asked.set()
        with self._lock:
            return self._summary

    def refresh_if_asked(self, every: float = 1.0) -> None:
        """A fresh summary if one was asked for and the last is ``every`` seconds old."""
        if self._asked.is_set() and time.monotonic() - self._summary_at >= every:
            self.refresh()

    def refresh(self) -> None:
        self._asked.clear()
        summary = self.summarizer.summary(final=self.scored)
        for ep in summary["episodes"]:
            ep["scored"] = ep["episode"] in self.scored
        summary["as_of"] = time.time()
        with self._lock:
            self._summary = json.dumps(summary).encode()
            self._summary_at = time.monotonic()

    def handle(self, item: Received) -> None:
        info = self.svc.key_info(item)
        if info is None:
            return
        if info.kind == "episode":
            self._on_episode(item)
        elif info.kind == "truth":
            truth = decode_received(item, Truth, self.svc.rejects)
            if (
                truth is not None
                and self._admissible(item, info, truth)
                and self._stored(item.key, self.store.truth(truth))
            ):
                self.summarizer.forget(truth.episode)  # if scored, this row is late: read again
        elif info.kind in ("source_estimate", "primary_estimate"):
            est = decode_received(item, EstimateMsg, self.svc.rejects)
            if (
                est is not None
                and self._admissible(item, info, est)
                and self._stored(item.key, self.store.estimate(est, item.t_recv))
            ):
                self.counts[est.episode][est.filter] += 1
                self.need[est.episode][est.filter] = self._last_step(info, est)
                self.last_seen[est.episode] = time.monotonic()
                self.summarizer.forget(est.episode)
        elif info.kind == "stats" and info.operator and info.service:
            self._on_stats(item, info.operator, info.service)

    def _admissible(self, item: Received, info: keys.KeyInfo, msg: Truth | EstimateMsg) -> bool:
        """Only the key's owner, about its key's episode (:mod:`tltrack.wire.admission`), for a
        step 1..K; else counted, dropped.

        A sample of an episode not yet started is held, and handled again once it starts.
        """
        K = self.K.get(msg.episode)
        if refused := admission.refusal(info, msg):
            reason = refused[0]
        elif K is None:
            self.held.hold(msg.episode, item.key, lambda: self.handle(item), self.svc.rejects)
            return False
        elif not 1 <= msg.k <= self._last_step(info, msg):
            reason = "bad_step"
        else:
            return True
        self.svc.rejects.add(item.key, reason)
        return False

    def _last_step(self, info: keys.KeyInfo, msg: Truth | EstimateMsg) -> int:
        """The last k of a truth (a tick of the truth grid) or of an operator's estimates (its
        own steps, :mod:`tltrack.config.timeline`): K for all on the paper's shared clock."""
        timeline = self.summarizer.timeline(msg.episode)
        if isinstance(msg, Truth):
            return timeline.ticks
        sid = info.source if info.kind == "source_estimate" else None
        return timeline.steps(sid or PRIMARY)

    def _stored(self, key: str, inserted: bool) -> bool:
        """A record already stored for its (episode, [filter,] k) is a replay."""
        if not inserted:
            self.svc.rejects.add(key, "duplicate")
        return inserted

    def catch_up(self, items: list[Received]) -> None:
        """Learn the episodes under way when (re)started mid-episode; known ones are no replay."""
        for item in items:
            start = decode_received(item, EpisodeStart, self.svc.rejects)
            if start is not None and self.store.episode_start(start):
                self._started(start)

    def _on_episode(self, item: Received) -> None:
        msg = decode_received(item, (EpisodeStart, EpisodeEnd), self.svc.rejects)
        if isinstance(msg, EpisodeEnd):
            self.store.episode_end(msg)
            self.ended[msg.episode] = time.monotonic()
        elif isinstance(msg, EpisodeStart) and self._stored(
            item.key, self.store.episode_start(msg)
        ):
            self._started(msg)

    def _started(self, start: EpisodeStart) -> None:
        self.K[start.episode] = start.K
        self.expected[start.episode] = 2 + len(start.config.get("sources", []))
        for later in self.held.release(start.episode):
            later()

    def _on_stats(self, item: Received, operator: str, service: str) -> None:
        try:
            stats = decode_stats(item.payload)
        except ValueError:
            self.svc.rejects.add(item.key, "bad_stats")
            return
        self.store.service_stats(operator, service, time.time(), stats)

    def score_finished(self) -> None:
        """Score every ended episode that is complete, or quiet for ``grace_s``."""
        now = time.monotonic()
        for e, t_end in list(self.ended.items()):
            K, counts, need = self.K.get(e), self.counts.get(e, {}), self.need.get(e, {})
            complete = (
                K is not None
                and len(counts) >= self.expected.get(e, 3)
                and all(n >= need.get(f, K) for f, n in counts.items())
            )
            quiet = now - max(t_end, self.last_seen.get(e, t_end)) > self.s.grace_s
            if complete or quiet:
                del self.ended[e]
                self.scored.add(e)
                self.store.commit()
                self.refresh()
                print_summary(self.summarizer.summary([e]))
                log.info("episode %s scored", e)


def main(argv: list[str] | None = None) -> None:
    settings = load_settings(Settings, argv)
    setup_logging(settings.log_level)
    # Zenoh's callback thread stamps each arrival (the latency's end), and needs the GIL for
    # it. At Python's default 5 ms switch interval, a main thread busy in Python made each
    # arrival wait up to 5 ms, and a burst of them queue: 0.5 ms keeps the stamps exact.
    sys.setswitchinterval(5e-4)
    try:
        store = Store(settings.db)
    except (OSError, sqlite3.Error) as err:  # a folder, a foreign file, an unwritable path
        said = f"error: db {settings.db}: no SQLite file the scorer can write: {err}"
        print(said, file=sys.stderr)
        raise SystemExit(2) from None
    try:
        with Service(NAME, keys.REFEREE, settings.zenoh) as svc:
            scorer = Scorer(settings, svc, store)
            inbox = svc.subscribe(*keys.REFEREE_READS)
            scorer.catch_up(svc.running_episodes())
            with Queryable(svc.session, keys.SCORER_SUMMARY, scorer.answer):
                svc.announce()
                while not svc.stop.is_set():
                    for item in svc.drain(inbox, timeout=0.2):
                        scorer.handle(item)
                    store.commit()
                    scorer.held.expire(svc.rejects)
                    scorer.score_finished()
                    scorer.refresh_if_asked()
                    svc.publish_stats()
    finally:
        store.close()
