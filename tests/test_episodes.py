"""tltrack.live.episodes.Episodes, the table of episodes every live service keeps: a sample that
overtakes its episode's start is held and handled once it opens; one of an episode closed here
(declined, retired or evicted) is counted at once, never held; one whose episode never starts is
counted once it has waited too long (tltrack.live.held)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import pytest
from doubles import episode_end, episode_start, received
from tltrack.config import Config, make_config
from tltrack.live.episodes import Episodes, StepQueue, TrackedEpisodes
from tltrack.live.held import Held
from tltrack.live.tracking import SourceEpisode
from tltrack.wire import keys
from tltrack.wire.messages import EpisodeStart, Measurement, RejectCounter

pytestmark = pytest.mark.unit

K = 3


def _episodes(capacity: int = 4) -> tuple[Episodes[str], list[str], RejectCounter]:
    """Episodes whose state is the episode's id; ``ep-declined`` is declined."""
    handled: list[str] = []

    def open_(start: EpisodeStart, _cfg: Config) -> str | None:
        return None if start.episode == "ep-declined" else start.episode

    return Episodes(capacity, open_), handled, RejectCounter()


def _sample(episodes: Episodes[str], handled: list[str], rejects: RejectCounter, e: str) -> None:
    """A sample of episode ``e``: handled now if it is open, else offered to the hold."""
    key = keys.clock(e)
    if episodes.get(e) is not None:
        handled.append(e)
    else:
        episodes.hold(e, key, lambda: handled.append(e), rejects)


def _announce(episodes: Episodes[str], rejects: RejectCounter, e: str, end: bool = False) -> None:
    """sensor_sim's start of episode ``e``, or its end."""
    payload = episode_end(e, K) if end else episode_start(e, K)
    episodes.handle(received(keys.episode(e), payload), rejects, recovery=False)


def test_a_sample_before_its_start_is_handled_once_the_episode_opens() -> None:
    episodes, handled, rejects = _episodes()
    _sample(episodes, handled, rejects, "ep-a")
    assert handled == []
    _announce(episodes, rejects, "ep-a")
    assert handled == ["ep-a"]
    assert rejects.total == 0


def test_samples_of_a_closed_episode_are_counted_at_once_not_held() -> None:
    episodes, handled, rejects = _episodes(capacity=1)
    # declined: what was held for it is counted, and what comes after it too
    _sample(episodes, handled, rejects, "ep-declined")
    _announce(episodes, rejects, "ep-declined")
    _sample(episodes, handled, rejects, "ep-declined")
    # retired: ended, and its last step taken
    _announce(episodes, rejects, "ep-a")
    _announce(episodes, rejects, "ep-a", end=True)
    episodes.retire("ep-a", K + 1)
    _sample(episodes, handled, rejects, "ep-a")
    # evicted: a newer episode took its place (capacity 1)
    _announce(episodes, rejects, "ep-b")
    _announce(episodes, rejects, "ep-c")
    _sample(episodes, handled, rejects, "ep-b")
    assert handled == []
    assert rejects.count(reason="episode_closed") == 4
    assert rejects.total == 4


def test_a_sample_whose_episode_never_starts_is_counted_after_the_ttl() -> None:
    """Held unread for ever, a forged sample of a made-up episode would never show among the
    rejected; after ``ttl_s`` it is counted, and its handling is gone."""
    held, rejects, handled = Held(ttl_s=10.0), RejectCounter(), []
    held.hold("ep-never", keys.clock("ep-never"), lambda: handled.append(1), rejects)
    held.expire(rejects, now=time.monotonic() + 5.0)
    assert rejects.total == 0
    held.expire(rejects, now=time.monotonic() + 11.0)
    assert rejects.count(reason="unknown_episode") == 1
    assert held.release("ep-never") == []
    assert handled == []


@dataclass
class _Tracked:
    tracker: SourceEpisode
    steps: StepQueue[Measurement] = field(default_factory=StepQueue)


@pytest.mark.parametrize("clutter", [False, True])
def test_a_tracker_takes_only_scans_its_sensor_could_have_made(clutter: bool) -> None:
    """The paper's sensor reports exactly one detection of its two components; a sensor with
    false alarms, any number of them."""
    detection = {"pd": 0.9, "clutter_rate": 5.0} if clutter else None
    cfg = make_config(K=K, particles=50, sources=[{"id": "s1", "detection": detection}])
    opened: list[_Tracked] = []

    def open_(start: EpisodeStart, _cfg: Config) -> _Tracked:
        opened.append(_Tracked(SourceEpisode(cfg, 0, "ukf", "s1")))
        return opened[-1]

    episodes: TrackedEpisodes[_Tracked] = TrackedEpisodes(4, open_)
    rejects = RejectCounter()
    episodes.handle(received(keys.episode("ep-a"), episode_start("ep-a", K)), rejects, False)
    key = keys.source_meas("s1", "ep-a")

    def offer(k: int, z: list[list[float]]) -> None:
        msg = Measurement(episode="ep-a", sender="s1", k=k, t_sensor=0.0, sensor="s1", z=z)
        episodes.offer("ep-a", key, msg, rejects)

    offer(1, [[1000.0, 0.1, 5.0]])  # three components from a range-bearing sensor
    offer(1, [[1000.0, 0.1]])
    offer(2, [[1000.0, 0.1], [2000.0, 0.2]])  # two detections
    offer(3, [])  # none
    queued = opened[0].steps
    taken = []
    while queued.ready() is not None:
        taken.append(queued.release().z)
    both = [[[1000.0, 0.1], [2000.0, 0.2]], []]
    assert taken == [[[1000.0, 0.1]], *(both if clutter else [])]
    assert rejects.count(reason="bad_shape") == (1 if clutter else 3), rejects.snapshot()
    assert rejects.total == rejects.count(reason="bad_shape")
    # finite values no sensor measures: they would overflow the filters, or stop a UKF's service
    for k, z in enumerate([[[1e300, 0.1]], [[-5.0, 0.1]], [[1000.0, 100.0]]], start=4):
        offer(k, z)
    assert rejects.count(reason="out_of_range") == 3, rejects.snapshot()


def test_a_missing_step_is_given_up_on_only_after_the_gap_timeout() -> None:
    """Step 2 never comes while 4 waits: released in order up to 1, then steps 2 and 3 are
    overdue once the gap has lasted longer than the timeout, and never before."""
    q: StepQueue[str] = StepQueue()
    for k in (1, 4):
        assert q.offer(k, f"z{k}") == "accepted"
    assert q.ready() == "z1" and q.release() == "z1" and q.ready() is None
    assert q.overdue(2.0, now=100.0) == []  # the gap starts here
    assert q.overdue(2.0, now=101.9) == []
    assert q.overdue(2.0, now=102.1) == [2, 3]
    assert q.ready() == "z4" and q.offer(3, "late") == "stale"
    assert q.overdue(2.0, now=200.0) == []  # nothing missing: no gap


@pytest.mark.parametrize("role", ["primary", "source"])
def test_a_tracker_refuses_an_episode_whose_filter_it_cannot_make(role: str) -> None:
    """A filter that raises as it is made (a UKF with n + kappa <= 0, which the config now
    refuses as well) ended the source tracker: the episode is refused and counted instead."""
    from doubles import Offline
    from tltrack.services.primary_tracker import tracker as primary_svc
    from tltrack.services.source_tracker import tracker as source_svc
    from tltrack.wire.messages import decode

    svc = Offline(f"{role}_tracker")
    made: primary_svc.PrimaryTracker | source_svc.SourceTracker
    if role == "primary":
        made = primary_svc.PrimaryTracker(primary_svc.Settings(filter="ukf"), svc)
    else:
        made = source_svc.SourceTracker(source_svc.Settings(filter="ukf"), svc)
    start = decode(episode_start("ep-a", K), EpisodeStart)
    cfg = start.parsed_config().model_copy(update={"kappa": -5.0})  # as no config validates
    assert made._open(start, cfg) is None
    assert svc.counters == {"episodes_refused": 1}
