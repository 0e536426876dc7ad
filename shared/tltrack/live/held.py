"""Messages that overtook the start of their episode.

Zenoh keeps the order of the samples on one key, not across keys, so a measurement, a transfer, a
truth or an estimate can arrive before the :class:`~tltrack.wire.messages.EpisodeStart` it
belongs to, above all when they travel different routes (per-operator routers). A service that
refused them would lose the first steps of an episode for no fault of the sender. :class:`Held`
keeps the handling of a few such (already validated) messages and hands them back once the
episode opens.

Everything comes off the network, so the hold is bounded: a few episodes (the oldest is dropped
first), a few messages each, and a few seconds (:meth:`Held.expire`; a start is late by
milliseconds, not seconds). What cannot be held, or waited too long, is counted as
``unknown_episode``.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from tltrack.wire.messages import RejectCounter

Handling = Callable[[], None]


class Held:
    """Handlings of messages waiting for their episode to open, per episode."""

    def __init__(self, episodes: int = 4, per_episode: int = 64, ttl_s: float = 10.0) -> None:
        self.episodes, self.per_episode, self.ttl_s = episodes, per_episode, ttl_s
        #: episode -> (when its first sample was held, its samples: (key, handling))
        self._held: dict[str, tuple[float, list[tuple[str, Handling]]]] = {}

    def hold(self, e: str, key: str, handling: Handling, rejects: RejectCounter) -> None:
        """Keep ``handling`` (of a sample on ``key``) until episode ``e`` opens.

        When ``e`` has no room left, the sample is counted under ``key``; when too many episodes
        wait, the oldest one's samples are dropped and counted under theirs.
        """
        if e not in self._held:
            if len(self._held) >= self.episodes:
                self.drop(next(iter(self._held)), "unknown_episode", rejects)
            self._held[e] = (time.monotonic(), [])
        samples = self._held[e][1]
        if len(samples) >= self.per_episode:
            rejects.add(key, "unknown_episode")
            return
        samples.append((key, handling))

    def drop(self, e: str, reason: str, rejects: RejectCounter) -> None:
        """Count what was held for ``e`` under ``reason``: the episode will not open here."""
        for key, _ in self._held.pop(e, (0.0, []))[1]:
            rejects.add(key, reason)

    def expire(self, rejects: RejectCounter, now: float | None = None) -> None:
        """Count and drop the samples of every episode whose start has not come ``ttl_s`` after
        its first sample: a service calls this in its loop."""
        now = time.monotonic() if now is None else now
        for e in [e for e, (since, _) in self._held.items() if now - since > self.ttl_s]:
            self.drop(e, "unknown_episode", rejects)

    def release(self, e: str) -> list[Handling]:
        """The handlings held for ``e``, in arrival order, now that it has opened."""
        return [handling for _, handling in self._held.pop(e, (0.0, []))[1]]
