"""Links that misbehave, live: the federated stack with the link emulator (tltrack.live.link) on
the source-primary link between routers (tests/test_federation.py builds the stack).

- Cut: the source stays up and its token still reaches the primary through the referee's router;
  its heartbeat does not (the routers' ACLs), so the primary reports the cut within two of its
  periods, steps on alone without waiting out its deadline, and takes transfers again once the
  link is back.
- Delayed by one primary period with jitter: transfers that come after their step are refused and
  counted as late, the others used, and the primary's estimates keep coming.
"""

from __future__ import annotations

import contextlib
import datetime
import sqlite3
import statistics
import time
from pathlib import Path

import pytest
import test_federation as fed
from livestack import (
    end_episode_once,
    estimates,
    logs,
    mostly_used,
    primary_stats,
    wait_until,
)
from tltrack.live import supervisor

pytestmark = [
    pytest.mark.integration,
    pytest.mark.timeout(240),
    pytest.mark.xdist_group("live"),  # timing: never beside another stack
]

PACE = 5.0  #: steps a second: the primary's period is 0.2 s, twice the default heartbeat's
PERIOD_S = 1 / PACE
LINK = ("source/s1", "primary")


def lateness(db: Path, ks: range) -> list[float]:
    """Seconds from each step's tick to the TL estimate's going out."""
    with contextlib.closing(sqlite3.connect(db)) as con:
        rows = con.execute(
            "SELECT k, t_sent - t_sensor FROM estimates WHERE filter = 'tl-rpf'"
        ).fetchall()
    return [late for k, late in rows if k in ks]


def logged_at(log: Path, what: str, since: float) -> float | None:
    """When the primary first logged the link to s1 ``what`` (cut, back) after ``since``
    (time.time()), if it did."""
    for line in log.read_text().splitlines():
        if f"link to source s1 {what}" in line:
            t = datetime.datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S,%f").timestamp()
            if t >= since - 0.002:  # the log's clock has milliseconds
                return t
    return None


def cuts_in_episode(log: Path) -> int:
    """The cuts the primary logged once its episode began (the start of every process at once
    on a small machine can hold a heartbeat back beyond its timeout: a blip before any step)."""
    lines = log.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if "episode ep-" in line)
    return sum("link to source s1 cut" in line for line in lines[start:])


def used(db: Path) -> dict[int, bool]:
    return {k: u for k, (_x, u) in estimates(db).get("tl-rpf", {}).items()}


def test_a_cut_link_is_noticed_within_two_periods_and_transfers_resume(tmp_path):
    """The default heartbeat (0.1 s), a deadline (0.5 s) longer than the period: were the primary
    to wait it out on every step, as it did before heartbeats, it would fall ever further behind."""
    db = tmp_path / "scorer.sqlite"
    with fed.federation(tmp_path) as (s, relays):
        s.start_router()
        fed.run_episode(
            s,
            db,
            1000,  # ended once the test has seen what it asserts on
            PACE,
            primary_env={"TLTRACK_PRIMARY_DEADLINE_MS": "500"},
        )
        primary_log = s.logs / "primary_tracker.log"
        assert wait_until(lambda: max(used(db), default=0) >= 15, 90), logs(s)
        cuts_before = primary_stats(db).get("counters", {}).get("link_cuts", 0)
        t_cut = time.time()
        relays[LINK].cut()
        assert wait_until(lambda: logged_at(primary_log, "cut", t_cut), 5), logs(s)
        noticed = logged_at(primary_log, "cut", t_cut)
        assert noticed is not None
        hit = max(used(db))
        assert wait_until(lambda: max(used(db)) >= hit + 15, 30), logs(s)
        stats_cut = primary_stats(db)
        t_restore = time.time()
        relays[LINK].restore()
        assert wait_until(lambda: logged_at(primary_log, "back", t_restore), 30), logs(s)
        back = logged_at(primary_log, "back", t_restore)
        assert back is not None
        resumed = max(used(db))
        seen = end_episode_once(s, lambda: max(used(db)) >= resumed + 15, 30)
        assert seen, logs(s)
        assert s.wait("sensor_sim", 60) == 0, logs(s)
        assert wait_until(lambda: primary_stats(db).get("counters", {}).get("link_cuts"), 10)
        stats = primary_stats(db)
        late_during = lateness(db, range(hit + 2, hit + 13))
        text = primary_log.read_text()
        in_episode = cuts_in_episode(primary_log)
    after_cut = noticed - t_cut
    print(f"cut noticed after {after_cut * 1e3:.0f} ms; back {back - t_restore:.2f} s after")
    print(f"lateness during the cut: median {statistics.median(late_during) * 1e3:.0f} ms")
    assert after_cut <= 2 * PERIOD_S, f"the cut took {after_cut:.3f} s to notice"
    assert "source s1 gone" not in text, "the source's token should outlive the cut"
    assert stats_cut.get("links") == {"s1": "cut"}, stats_cut
    assert stats_cut["counters"]["link_cuts"] == cuts_before + 1, (cuts_before, stats_cut)
    print(f"link cuts: {stats['counters']['link_cuts']}, {in_episode} in the episode (1 made)")
    assert stats["links"] == {"s1": "up"}, stats
    u = used(db)
    during = [u[k] for k in range(hit + 2, hit + 13)]
    assert not any(during), f"transfer used while the link was cut: {during}"
    # going on alone: no step waits out the 0.5 s deadline
    assert statistics.median(late_during) < 0.1 and max(late_during) < 0.5, late_during
    tail = [u[k] for k in range(max(u) - 12, max(u) + 1)]
    assert mostly_used(tail), f"transfer did not resume: {tail}"


def test_a_link_delayed_by_a_period_with_jitter_refuses_late_transfers_and_steps_on(tmp_path):
    """200 ms ± 40 ms each way, a deadline of 10 ms: the transfer for step k+1 leaves the source
    right after its step k, and comes from 40 ms before to 40 ms after z_{k+1} (and the source's
    step): some in time, some late. A slow link is not a cut: the heartbeat's arrivals spread by
    up to twice the jitter (80 ms) beyond its period, so it beats every 0.3 s here (a 0.6 s
    timeout): the 0.1 s default left 20 ms to spare and 0.2 s left 120 ms, and on a loaded
    machine (a container image building on both cores beside it) both took a beat for a cut."""
    db = tmp_path / "scorer.sqlite"
    K = 50
    with fed.federation(tmp_path) as (s, relays):
        # from the start: a delay that sets in while heartbeats flow is a silence of its length
        relays[LINK].shape(delay_s=PERIOD_S, jitter_s=0.04)
        s.start_router()
        beat = "0.3"
        primary = {"TLTRACK_PRIMARY_DEADLINE_MS": "10", "TLTRACK_PRIMARY_HEARTBEAT_S": beat}
        source = {"TLTRACK_SOURCE_HEARTBEAT_S": beat}
        fed.run_episode(s, db, K, PACE, primary_env=primary, source_env=source)
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        assert supervisor.wait_for_scored(s.endpoint, 1, 120, "referee") is not None, logs(s)
        done = lambda: primary_stats(db).get("counters", {}).get("steps") == K  # noqa: E731
        assert wait_until(done, 10), primary_stats(db)
        stats = primary_stats(db)
        false_cuts = cuts_in_episode(s.logs / "primary_tracker.log")
    live = estimates(db)
    assert sorted(live["tl-rpf"]) == list(range(1, K + 1)), "the primary missed steps"
    assert sorted(live["rpf"]) == list(range(1, K + 1))
    late = stats["rejected"]["by_reason"].get("late_transfer", 0)
    u = used(db)
    delayed = [u[k] for k in range(2, K)]
    print(f"late transfers refused: {late}; steps with a transfer: {sum(delayed)}/{len(delayed)}")
    print(f"link cuts: {stats['counters'].get('link_cuts', 0)}, {false_cuts} in the episode")
    assert late > 0, stats
    assert any(delayed), "no transfer came in time"
    # with no cut, each step that went on without its transfer waited out the deadline
    assert stats["counters"].get("deadlines_passed", 0) >= delayed.count(False), stats
    assert false_cuts == 0, "a slow link taken for a cut"
