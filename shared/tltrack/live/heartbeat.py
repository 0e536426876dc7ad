"""The source-primary link's heartbeat: a cut link noticed within two periods, three at most.

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

How long a silence makes a cut adapts to each link, as TCP's retransmission timeout does
(Jacobson and Karels; RFC 6298, https://www.rfc-editor.org/rfc/rfc6298): the gaps between a
link's heartbeats are smoothed into a mean ``gap`` and a mean deviation ``dev``, and the link is cut
after ``gap + 4 dev`` without a beat, never sooner than :data:`MISSED` periods nor later than
:data:`MOST_MISSED`. A steady link is cut after two periods, as before; a link whose beats arrive
unevenly (a loaded host, a jittered route) waits up to three before taking a late beat for a cut.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Literal

import zenoh
from tltrack.wire.transport import Publisher

LinkState = Literal["up", "cut"]

#: heartbeat periods without a beat that make a cut on a steady link
MISSED = 2
#: ... and on the most uneven one: the longest a cut goes unnoticed
MOST_MISSED = 3
#: the gains of the smoothed gap and its deviation (RFC 6298's alpha and beta)
ALPHA, BETA = 1 / 8, 1 / 4


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
    gap: float  #: the smoothed gap between its heartbeats [s]
    dev: float = 0.0  #: the smoothed deviation of that gap [s]
    state: LinkState = "up"

    def arrived(self, now: float) -> None:
        """RFC 6298's update (section 2.3) of the gap and its deviation, by the gap ending now."""
        sample = now - self.last
        self.dev += BETA * (abs(self.gap - sample) - self.dev)
        self.gap += ALPHA * (sample - self.gap)
        self.last = now


@dataclass
class LinkWatch:
    """Each source's direct link from its heartbeats: ``up`` while they arrive, ``cut`` after
    :meth:`timeout_s` without one, ``up`` again at the next."""

    period_s: float
    cuts: int = 0  #: how many times a link went from up to cut
    _links: dict[str, _Link] = field(default_factory=dict)

    def timeout_s(self, sid: str) -> float:
        """The silence that cuts ``sid``'s link: ``gap + 4 dev``, from :data:`MISSED` to
        :data:`MOST_MISSED` periods (the shortest, for a source not heard yet)."""
        low, high = MISSED * self.period_s, MOST_MISSED * self.period_s
        link = self._links.get(sid)
        return low if link is None else min(high, max(low, link.gap + 4 * link.dev))

    def beat(self, sid: str, now: float) -> bool:
        """Record a heartbeat of ``sid``; True if its link was cut and is back."""
        link = self._links.get(sid)
        if link is None:
            self._links[sid] = _Link(now, gap=self.period_s)
            return False
        back = link.state == "cut"
        if back:  # the silence of a cut is not a gap between beats
            link.last, link.state = max(link.last, now), "up"
        elif now > link.last:  # one that overtook another is no gap either
            link.arrived(now)
        return back

    def check(self, now: float) -> list[str]:
        """The sources whose links are found cut now (each once per cut)."""
        cut = []
        for sid, link in self._links.items():
            if link.state == "up" and now - link.last > self.timeout_s(sid):
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
        ups = [
            link.last + self.timeout_s(sid)
            for sid, link in self._links.items()
            if link.state == "up"
        ]
        if not ups:
            return None
        return max(0.0, min(ups) - now)

    def states(self) -> dict[str, LinkState]:
        """Each source's link state, for the primary's statistics."""
        return {sid: link.state for sid, link in sorted(self._links.items())}
