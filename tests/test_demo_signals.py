"""Whatever stops ``tltrack demo`` or ``tltrack bench-live``, no process it started survives it.

Each test starts the command as a shell would start a background job (its own session, SIGINT
ignored), waits until the scorer has committed some rows, sends one signal to that process alone,
and then checks every process that was its descendant: all gone (or zombies awaiting a reaper)
within 10 s, 5 s for SIGKILL, and the scorer's committed rows still there and intact. A service
whose router is not there stops on a signal too, though it is blocked waiting for it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from livestack import connecting, wait_until

pytestmark = pytest.mark.integration

#: an episode long enough to be cut short
DEMO = ["demo", "--steps", "2000", "--pace", "20", "--particles", "300", "--out", "out"]


def children(pid: int) -> set[int]:
    """The direct children of ``pid`` (every thread's), from /proc."""
    out: set[int] = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        with contextlib.suppress(OSError):
            out |= {int(c) for c in (task / "children").read_text().split()}
    return out


def descendants(pid: int) -> set[int]:
    found, todo = set(), [pid]
    while todo:
        new = children(todo.pop()) - found
        found |= new
        todo += new
    return found


def alive(pid: int) -> bool:
    """Running (a zombie has exited: it only waits for its reaper)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def committed_rows(db: Path) -> int:
    if not db.exists():
        return 0
    with contextlib.closing(sqlite3.connect(db, timeout=5)) as con:
        try:
            return int(con.execute("SELECT COUNT(*) FROM estimates").fetchone()[0])
        except sqlite3.OperationalError:  # no schema yet
            return 0


def as_background_job() -> None:
    """What a non-interactive shell does for ``cmd &``: SIGINT (and SIGQUIT) ignored."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGQUIT, signal.SIG_IGN)


def start(argv: list[str], tmp: Path) -> subprocess.Popen[bytes]:
    log = open(tmp / "command.log", "wb")  # noqa: SIM115 (the child holds it)
    return subprocess.Popen(
        [sys.executable, "-m", "tltrack", *argv],
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,  # the signal reaches this process alone, not its group
        preexec_fn=as_background_job,
        cwd=tmp,
    )


def stop_and_check(
    proc: subprocess.Popen[bytes], sig: int, db: Path, tmp: Path, *, check_rows: bool = True
) -> None:
    """Wait for committed rows, send ``sig``, and check that every descendant goes."""
    assert wait_until(lambda: committed_rows(db) >= 6, 120), (tmp / "command.log").read_text()
    kids = descendants(proc.pid)
    assert len(kids) >= 5, f"router + 4 services expected, found {kids}"
    rows = committed_rows(db)
    os.kill(proc.pid, sig)
    limit = 10.0  # each child stops on its own SIGTERM, in well under 1 s when not loaded
    t0 = time.monotonic()
    survivors = kids
    while survivors and time.monotonic() - t0 < limit:
        time.sleep(0.05)
        survivors = {p for p in kids if alive(p)}
    for p in survivors:  # do not leak them into the other tests
        with contextlib.suppress(OSError):
            os.kill(p, signal.SIGKILL)
    assert not survivors, f"{signal.Signals(sig).name}: still running after {limit} s: {survivors}"
    rc = proc.wait(15)
    assert rc == (-sig if sig == signal.SIGKILL else 128 + sig), rc
    if check_rows:
        with contextlib.closing(sqlite3.connect(db)) as con:
            assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert committed_rows(db) >= rows


#: the tests that stop a whole demo stack, each within a time limit: never beside another stack
LIVE = pytest.mark.xdist_group("live")


@LIVE
@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGINT, signal.SIGKILL])
def test_a_signal_to_the_demo_stops_every_process_it_started(sig: int, tmp_path: Path) -> None:
    """SIGTERM is the next test's: the same demo, with its dashboard too."""
    proc = start(DEMO, tmp_path)
    stop_and_check(proc, sig, tmp_path / "out" / "scorer.sqlite", tmp_path)


@LIVE
def test_sigterm_to_the_demo_with_its_dashboard_stops_everything(tmp_path: Path) -> None:
    port = str(_free_port())
    proc = start(
        [*DEMO, "--serve", "--port", port],
        tmp_path,
    )
    stop_and_check(proc, signal.SIGTERM, tmp_path / "out" / "scorer.sqlite", tmp_path)


@LIVE
def test_sigterm_to_bench_live_stops_every_process_it_started(tmp_path: Path) -> None:
    """bench-live scores into a temporary directory (here under ``tmp_path``, via TMPDIR) that it
    removes on the way out, so only the processes are checked."""
    os.environ["TMPDIR"] = str(tmp_path)
    try:
        proc = start(
            ["bench-live", "--particles", "300", "--steps", "2000", "--pace", "20", "--rates=50"],
            tmp_path,
        )
    finally:
        del os.environ["TMPDIR"]
    dbs = lambda: list(tmp_path.glob("tmp*/scorer-*-20.sqlite"))  # noqa: E731
    assert wait_until(lambda: any(committed_rows(d) >= 6 for d in dbs()), 120), (
        tmp_path / "command.log"
    ).read_text()
    stop_and_check(proc, signal.SIGTERM, dbs()[0], tmp_path, check_rows=False)


def _free_port() -> int:
    from tltrack.live.supervisor import free_port

    return free_port()


@pytest.mark.parametrize(
    ("service", "sig"),
    [
        ("scorer", signal.SIGTERM),
        ("scorer", signal.SIGINT),
        ("primary_tracker", signal.SIGTERM),
        ("sensor", signal.SIGTERM),
    ],
)
def test_a_service_waiting_for_a_router_that_is_not_there_stops_on_a_signal(
    service: str, sig: int, tmp_path: Path
) -> None:
    """A service blocks in zenoh.open until its router answers (connect timeout -1); a stop
    signal must still end it, as the router may be gone for good (found as orphans in a futex)."""
    from tltrack.live.topology import free_port

    env = {
        **os.environ,
        "TLTRACK_ZENOH_ENDPOINTS": f'["tcp/127.0.0.1:{free_port()}"]',  # nobody listens
        "TLTRACK_SCORER_DB": str(tmp_path / "scorer.sqlite"),
    }
    with (tmp_path / "service.log").open("wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", f"tltrack.services.{service}"],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,
        )
    try:
        assert wait_until(lambda: connecting(proc.pid), 60), (tmp_path / "service.log").read_text()
        os.kill(proc.pid, sig)
        rc = proc.wait(timeout=5)
        log = (tmp_path / "service.log").read_text()
        # the signal's own default action (Service.__enter__): nothing is open to close yet
        assert rc == -sig, (rc, log)
        assert "Traceback" not in log, log
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize(
    ("close", "rc"),
    [
        ("import time; time.sleep(30)", 128 + signal.SIGTERM),  # the timer ends it
        # libc's sleep through ctypes.PyDLL keeps the GIL, so the timer (a Python thread)
        # cannot run: the kernel's alarm ends it
        ("import ctypes; ctypes.PyDLL(None).sleep(30)", -signal.SIGALRM),
    ],
    ids=["close-hangs", "wedged-holding-the-gil"],
)
def test_a_process_whose_close_never_ends_still_ends_soon_after_a_stop_signal(
    close: str, rc: int
) -> None:
    """The bound behind the 10 s above: a close stuck past the grace period ends the process."""
    code = f"from tltrack.live.supervisor import exit_unless_stopped as x\nx(15, 0.5)\n{close}"
    t0 = time.monotonic()
    assert subprocess.run([sys.executable, "-c", code], timeout=20).returncode == rc
    assert time.monotonic() - t0 < 15
