"""Real processes over loopback Zenoh for integration tests: a router, the services, a client."""

from __future__ import annotations

import contextlib
import json
import signal
import sqlite3
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from tltrack.live import supervisor
from tltrack.services.dashboard import launch
from tltrack.services.sensor_sim.simulator import WAIT_FOR

SIM_DEFAULTS = {"preset": "arasaratnam-haykin", "truth": "fixed", "seed": 7}
#: what sensor_sim awaits beside a dashboard: the default stack's services and the page, so that
#: no step is missed
WAIT_WITH_DASHBOARD = [*WAIT_FOR, launch.TOKEN]


@contextlib.contextmanager
def stack(tmp: Path) -> Iterator[supervisor.Stack]:
    s = supervisor.Stack(f"tcp/127.0.0.1:{supervisor.free_port()}", tmp / "logs")
    try:
        yield s
    finally:
        codes = s.stop()
        assert all(c is not None for c in codes.values()), f"processes left running: {codes}"


def start_all(
    s: supervisor.Stack, db: Path, *, primary_env: dict[str, str] | None = None, sim: list[str]
) -> None:
    s.start_router()
    s.start_service("scorer", env={"TLTRACK_SCORER_DB": str(db), "TLTRACK_SCORER_GRACE_S": "3"})
    s.start_service("primary_tracker", env=primary_env)
    s.start_service("source_tracker")
    s.start_service("sensor_sim", *sim)


def sim_flags(steps: int, particles: int, pace: float = 0.0, **kw: Any) -> list[str]:
    o = {**SIM_DEFAULTS, **kw}
    return supervisor.sim_flags(
        steps, particles, pace, False, o["preset"], o["truth"], o["seed"], o.get("episodes", 1)
    )


def estimates(db: Path) -> dict[str, dict[int, tuple[list[float], bool]]]:
    """filter -> k -> (x, transfer_used), as the scorer committed them."""
    out: dict[str, dict[int, tuple[list[float], bool]]] = {}
    if not db.exists():
        return out
    with contextlib.closing(sqlite3.connect(db)) as con:
        try:
            rows = con.execute("SELECT filter, k, x, transfer_used FROM estimates").fetchall()
        except sqlite3.OperationalError:  # the scorer has not created its schema yet
            return out
    for name, k, x, used in rows:
        out.setdefault(name, {})[k] = (json.loads(x), bool(used))
    return out


def logs(s: supervisor.Stack) -> str:
    return "\n".join(f"--- {p.name}\n{p.read_text()[-3000:]}" for p in s.logs.glob("*.log"))


def connecting(pid: int) -> bool:
    """Whether zenoh's runtime has started in process ``pid`` (its thread net-0): a service is
    then inside zenoh.open, waiting for its router."""
    names = set()
    for comm in Path(f"/proc/{pid}/task").glob("*/comm"):
        with contextlib.suppress(OSError):
            names.add(comm.read_text().strip())
    return "net-0" in names


def wait_until(pred: Any, timeout: float, every: float = 0.2) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(every)
    return False


def end_episode_once(s: supervisor.Stack, seen: Any, timeout: float) -> bool:
    """Stop sensor_sim (SIGTERM: it ends its episode as ``aborted``, with the steps it sent) once
    ``seen()`` holds, or after ``timeout``; whether ``seen()`` held.

    A fault test's episode is long enough for the slowest machine's recovery, and ends as soon as
    the test has seen the steps after it that it asserts on: the recovery's time, not the episode's
    length, decides what is left to judge."""
    held = wait_until(seen, timeout)
    if s.procs["sensor_sim"].poll() is None:
        s.kill("sensor_sim", signal.SIGTERM)
    return held


#: the share of due steps that must use the transfer: a transfer later than the primary's
#: deadline leaves its step isolated, as it should, and a loaded machine makes one late in a few
#: dozen steps (one of 21 beside a CPU-bound job, one of about 40 with three test processes)
MOSTLY = 0.9


def mostly_used(used: Sequence[bool]) -> bool:
    """Whether at least :data:`MOSTLY` of these steps used their transfer."""
    return sum(used) >= MOSTLY * len(used)


def primary_stats(db: Path) -> dict[str, Any]:
    """The primary tracker's latest statistics, as the scorer stored them."""
    if not db.exists():
        return {}
    query = "SELECT stats FROM service_stats WHERE service = 'primary_tracker'"
    with contextlib.closing(sqlite3.connect(db)) as con, contextlib.suppress(sqlite3.Error):
        row = con.execute(query).fetchone()
        return json.loads(row[0]) if row else {}
    return {}
