"""The episodes a live service follows, and each one's measurements in step order.

Zenoh delivers an episode's start, its measurements and its end on different keys, with order kept
per key only, and a sender may repeat, skip or flood steps. :class:`Episodes` opens and retires
each episode a service follows (at most a few at once); :class:`TrackedEpisodes` also queues each
tracker's measurements in step order (:class:`StepQueue`), after checking that its sensor could
have made them. No filter runs here: the sensors and the scorer's side need this bookkeeping
without the engine, the trackers (:mod:`tltrack.live.tracking`) with it.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Generic, Protocol, TypeVar

from tltrack.config import Config
from tltrack.live.held import Handling, Held
from tltrack.models.components import first_problem
from tltrack.wire.messages import EpisodeEnd, EpisodeStart, Measurement, Message, RejectCounter
from tltrack.wire.transport import Received, decode_received

T = TypeVar("T")


class StepQueue(Generic[T]):
    """Releases step-indexed items in order k = 1, 2, ..., holding early ones.

    ``offer`` refuses a duplicate, a step already released (stale) or one more than ``window``
    steps ahead, so a flood of bogus steps cannot grow memory. When a step is missing while later
    ones wait, :meth:`stalled` reports how long; the caller may then :meth:`skip` it
    (:meth:`overdue` does both).
    """

    def __init__(self, window: int = 256) -> None:
        self.next_k = 1
        self.window = window
        self._held: dict[int, T] = {}
        self._stall_since: float | None = None

    def offer(self, k: int, item: T) -> str:
        """``"accepted"``, ``"duplicate"``, ``"stale"`` or ``"too_far"``."""
        if k < self.next_k:
            return "stale"
        if k >= self.next_k + self.window:
            return "too_far"
        if k in self._held:
            return "duplicate"
        self._held[k] = item
        return "accepted"

    def ready(self) -> T | None:
        """The item for ``next_k`` if it has arrived."""
        return self._held.get(self.next_k)

    def release(self) -> T:
        item = self._held.pop(self.next_k)
        self.next_k += 1
        self._stall_since = None
        return item

    def stalled(self, now: float) -> float:
        """Seconds that ``next_k`` has been missing while a later step waits (0 if not)."""
        if self.next_k in self._held or not self._held:
            self._stall_since = None
            return 0.0
        if self._stall_since is None:
            self._stall_since = now
        return now - self._stall_since

    def skip(self) -> list[int]:
        """Give up on every missing step up to the next one held; returns the skipped steps."""
        first = self.next_k
        self.next_k = min(self._held)
        self._stall_since = None
        return list(range(first, self.next_k))

    def overdue(self, gap_timeout_s: float, now: float) -> list[int]:
        """The steps a tracker gives up on at ``now``: :meth:`skip`'s, once ``next_k`` has been
        :meth:`stalled` for more than ``gap_timeout_s``; else none."""
        return self.skip() if self.stalled(now) > gap_timeout_s else []


class Sensing(Protocol):
    """What a tracker's episode tells of its own sensor
    (:class:`~tltrack.live.tracking.SourceEpisode`,
    :class:`~tltrack.live.tracking.PrimaryEpisode`)."""

    @property
    def n_z(self) -> int: ...

    @property
    def components(self) -> tuple[str, ...]: ...

    @property
    def one_detection(self) -> bool:
        """Does its sensor report exactly one detection per step (the paper's sensor)?"""
        ...


class Tracked(Protocol):
    """What an episode's state needs for :meth:`TrackedEpisodes.offer`: its queue of
    measurements, and its tracker, which knows its sensor's measurement."""

    steps: StepQueue[Measurement]

    @property
    def tracker(self) -> Sensing: ...


S = TypeVar("S")
E = TypeVar("E", bound=Tracked)


class Episodes(Generic[S]):
    """The episodes a service follows, each with its state ``S``.

    An :class:`EpisodeStart` opens one (through ``open``, which may decline with None); an
    :class:`EpisodeEnd` marks its last step, and :meth:`retire` forgets it once that step is taken.
    At most ``capacity`` are kept; the oldest goes first, so a flood of episodes is bounded.

    Zenoh keeps order per key, not across keys, so a measurement can overtake its episode's start:
    :meth:`hold` keeps the handling of a few such (already validated) messages for later, and
    :meth:`on_message` hands them back once the episode opens. A message of an episode already
    closed here (retired, evicted or declined) is not held: it is counted as ``episode_closed``.
    """

    CLOSED = 64  #: closed episodes remembered

    def __init__(self, capacity: int, open: Callable[[EpisodeStart, Config], S | None]) -> None:
        self.capacity = capacity
        self._open = open
        self._state: dict[str, S] = {}
        self._last_k: dict[str, int] = {}
        self._held = Held()
        self._closed: deque[str] = deque(maxlen=self.CLOSED)

    def handle(self, item: Received, rejects: RejectCounter, recovery: bool) -> None:
        """Act on a sample of an episode key; a replayed start is counted as a duplicate."""
        msg = decode_received(item, (EpisodeStart, EpisodeEnd), rejects)
        if isinstance(msg, EpisodeStart) and msg.episode in self._state:
            rejects.add(item.key, "duplicate")
        elif msg is not None:
            for later in self.on_message(msg, recovery, rejects):
                later()

    def hold(self, e: str, key: str, handling: Handling, rejects: RejectCounter) -> None:
        """Keep the handling of a sample of the not-yet-opened episode ``e`` (:class:`Held`)."""
        if e in self._closed:
            rejects.add(key, "episode_closed")
        else:
            self._held.hold(e, key, handling, rejects)

    def expire(self, rejects: RejectCounter) -> None:
        """Count what waited too long for an episode that never started (:meth:`Held.expire`)."""
        self._held.expire(rejects)

    def on_message(self, msg: Message, recovery: bool, rejects: RejectCounter) -> list[Handling]:
        """Open or end an episode; returns the samples held for an episode it opens (those
        held for one it declines are counted as ``episode_closed``).

        ``recovery`` is the tracker's own setting, not the episode's.
        """
        if isinstance(msg, EpisodeEnd):
            if msg.episode in self._state:
                self._last_k[msg.episode] = msg.steps_sent
            return []
        if not isinstance(msg, EpisodeStart) or msg.episode in self._state:
            return []
        state = self._open(msg, msg.parsed_config().with_(recovery=recovery))
        if state is None:
            self._held.drop(msg.episode, "episode_closed", rejects)
            self._closed.append(msg.episode)
            return []
        while len(self._state) >= self.capacity:
            oldest = next(iter(self._state))
            self._state.pop(oldest)
            self._last_k.pop(oldest, None)
            self._closed.append(oldest)
        self._state[msg.episode] = state
        return self._held.release(msg.episode)

    def get(self, e: str) -> S | None:
        return self._state.get(e)

    def items(self) -> list[tuple[str, S]]:
        return list(self._state.items())

    def retire(self, e: str, next_k: int) -> None:
        """Forget episode ``e`` if it has ended and its last step is behind ``next_k``."""
        last = self._last_k.get(e)
        if last is not None and next_k > last:
            del self._state[e]
            del self._last_k[e]
            self._closed.append(e)


class TrackedEpisodes(Episodes[E]):
    """The episodes a tracker follows: each state also queues its measurements in step order."""

    def offer(self, e: str, key: str, z: Measurement, rejects: RejectCounter) -> None:
        """Queue ``z`` in its episode's step order; held while the episode is not yet open.

        A measurement of the wrong size for the sensor, one with a value no sensor measures
        (:mod:`tltrack.models.components`), a duplicate, a stale step, one far
        ahead, one of an episode closed here, or one the hold cannot keep (:mod:`tltrack.live.held`)
        is counted under its key.
        """
        ep = self.get(e)
        if ep is None:
            self.hold(e, key, lambda: self.offer(e, key, z, rejects), rejects)
            return
        own = ep.tracker
        if any(len(d) != own.n_z for d in z.z) or (own.one_detection and len(z.z) != 1):
            rejects.add(key, "bad_shape")
            return
        if any(first_problem(own.components, d) for d in z.z):
            rejects.add(key, "out_of_range")
            return
        verdict = ep.steps.offer(z.k, z)
        if verdict != "accepted":
            rejects.add(key, verdict)
