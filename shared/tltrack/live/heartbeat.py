"""The source-primary link's heartbeat: a cut link noticed in two heartbeat periods.

A source's liveliness token reaches the primary through any route between routers, the referee's
too, so it outlives a cut of the direct link, over which alone transfers travel (the referee's
router drops them). The heartbeat travels where transfers do and nowhere else: each router's
access control lets ``tltrack/source/<sid>/heartbeat`` out of the source's router, into the
primary's from that source's router only, and never through the referee's
(``shared/tltrack/access/templates/``). Its silence therefore means the direct link is down, and
the primary stops waiting for that source's transfers until it beats again.

- :class:`HeartbeatSender` (the source): an empty put every period, from a thread of its own, so
  that a long filter step does not hold it back, and congestion control DROP, so that a stalled
  link never blocks the source.
- :class:`LinkWatch` (the primary): the state of each source's link from its heartbeats. It is
  given the time, so its logic is tested without a clock. A source that never beat (one that
  predates heartbeats) is never declared cut: the primary then relies on its liveliness token and
  deadline, as before.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Literal

import zenoh
from tltrack.wire.transport import Publisher

LinkState = Literal["up", "cut"]

#: heartbeat periods without a beat that make a cut
MISSED = 2


class HeartbeatSender:
    """Puts an empty sample on ``key`` every ``period_s`` until closed; use as a context."""

    def __init__(self, session: zenoh.Session, key: str, period_s: float) -> None:
        if period_s <= 0:
            raise ValueError(f"heartbeat period must be > 0 s, not {period_s}")
        self.period_s = period_s
        self._pub = Publisher(session, key, block=False, express=True)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="heartbeat", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._pub.put(b"")
            except zenoh.ZError:  # the session is closing
                return
            self._stop.wait(self.period_s)

    @property
    def sent(self) -> int:
        return self._pub.sent

    def __enter__(self) -> HeartbeatSender:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self._thread.join(2)
        self._pub.close()


@dataclass
class _Link:
    last: float  #: when its last heartbeat arrived (monotonic seconds)
    state: LinkState = "up"


@dataclass
class LinkWatch:
    """Each source's direct link from its heartbeats: ``up`` while they arrive, ``cut`` after
    :data:`MISSED` periods of ``period_s`` without one, ``up`` again at the next."""

    period_s: float
    missed: int = MISSED
    cuts: int = 0  #: how many times a link went from up to cut
    _links: dict[str, _Link] = field(default_factory=dict)

    @property
    def timeout_s(self) -> float:
        return self.missed * self.period_s

    def beat(self, sid: str, now: float) -> bool:
        """Record a heartbeat of ``sid``; True if its link was cut and is back."""
        link = self._links.get(sid)
        if link is None:
            self._links[sid] = _Link(now)
            return False
        back = link.state == "cut"
        link.last, link.state = max(link.last, now), "up"
        return back

    def check(self, now: float) -> list[str]:
        """The sources whose links are found cut now (each once per cut)."""
        cut = []
        for sid, link in self._links.items():
            if link.state == "up" and now - link.last > self.timeout_s:
                link.state = "cut"
                self.cuts += 1
                cut.append(sid)
        return cut

    def is_cut(self, sid: str) -> bool:
        """Whether ``sid``'s link is cut; never for a source that has not beaten."""
        link = self._links.get(sid)
        return link is not None and link.state == "cut"

    def due(self, now: float) -> float | None:
        """Seconds until the next link that is up would be found cut, if any."""
        ups = [link.last for link in self._links.values() if link.state == "up"]
        if not ups:
            return None
        return max(0.0, min(ups) + self.timeout_s - now)

    def states(self) -> dict[str, LinkState]:
        """Each source's link state, for the primary's statistics."""
        return {sid: link.state for sid, link in sorted(self._links.items())}
