"""The link emulator (tltrack.live.link) on loopback sockets, and the primary's view of a link from
heartbeats (tltrack.live.heartbeat), given the time."""

from __future__ import annotations

import contextlib
import json
import socket
import time
from collections.abc import Iterator

import pytest
from tltrack.live.heartbeat import LinkWatch
from tltrack.live.link import LinkEmulator, Shape, apply_control, read_control
from tltrack.wire import keys

pytestmark = pytest.mark.unit


@contextlib.contextmanager
def target() -> Iterator[tuple[socket.socket, str]]:
    """A listening socket: the router at the far end of the link."""
    with socket.create_server(("127.0.0.1", 0)) as server:
        server.settimeout(5)
        yield server, f"tcp/127.0.0.1:{server.getsockname()[1]}"


def dial(link: LinkEmulator) -> socket.socket:
    host, port = link.endpoint.removeprefix("tcp/").rsplit(":", 1)
    sock = socket.create_connection((host, int(port)), timeout=5)
    return sock


def receive(sock: socket.socket, n: int) -> bytes:
    out = b""
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        if not chunk:
            break
        out += chunk
    return out


def test_each_chunk_waits_the_delay_in_order_and_the_other_way_too():
    with target() as (server, to), LinkEmulator(to, shape=Shape(0.15, 0.05), seed=1) as link:
        client = dial(link)
        far, _ = server.accept()
        t0 = time.monotonic()
        for i in range(5):
            client.sendall(bytes([i]) * 10)
            time.sleep(0.01)
        got = receive(far, 50)
        forward = time.monotonic() - t0
        assert got == b"".join(bytes([i]) * 10 for i in range(5)), "order kept"
        assert 0.1 <= forward < 0.5, forward
        link.shape("back", delay_s=0.0, jitter_s=0.0)
        t0 = time.monotonic()
        far.sendall(b"back")
        assert receive(client, 4) == b"back"
        assert time.monotonic() - t0 < 0.1
        client.close()
        far.close()


def test_a_cut_closes_the_link_and_refuses_it_until_restored():
    with target() as (server, to), LinkEmulator(to) as link:
        client = dial(link)
        far, _ = server.accept()
        client.sendall(b"up")
        assert receive(far, 2) == b"up"
        link.cut()
        assert receive(client, 1) == b"", "the dialler sees the link close"
        again = dial(link)  # accepted by the relay's socket, then closed at once
        assert receive(again, 1) == b""
        link.restore()
        client = dial(link)
        far2, _ = server.accept()
        client.sendall(b"back")
        assert receive(far2, 4) == b"back"
        for s in (client, far, far2, again):
            s.close()


def test_a_stall_holds_the_bytes_and_the_rate_spaces_them():
    with target() as (server, to), LinkEmulator(to) as link:
        client = dial(link)
        far, _ = server.accept()
        far.settimeout(0.3)
        link.shape(stalled=True)  # every byte held, both ways; connections stay open
        client.sendall(b"held")
        with pytest.raises(TimeoutError):
            far.recv(4)
        link.shape(stalled=False)
        far.settimeout(5)
        assert receive(far, 4) == b"held"
        link.shape(rate_bps=400e3)  # 20 kB: 0.4 s
        t0 = time.monotonic()
        for _ in range(20):
            client.sendall(b"x" * 1000)
            time.sleep(0.002)
        assert len(receive(far, 20_000)) == 20_000
        assert time.monotonic() - t0 >= 0.3
        client.close()
        far.close()


def test_a_rate_set_down_holds_only_the_chunks_after_it():
    """A chunk that went at 8 Mbit/s is not timed again at the 1 kbit/s set after it."""
    with target() as (server, to), LinkEmulator(to) as link:
        client = dial(link)
        far, _ = server.accept()
        link.shape(rate_bps=8e6)
        client.sendall(b"x" * 1000)
        assert len(receive(far, 1000)) == 1000
        time.sleep(0.3)
        link.shape(rate_bps=1000.0)
        t0 = time.monotonic()
        client.sendall(b"y" * 10)
        assert receive(far, 10) == b"y" * 10
        assert time.monotonic() - t0 < 1.0  # not the 1000 B chunk's 8 s at the new rate
        client.close()
        far.close()


def test_a_rate_set_back_up_frees_the_link_at_once():
    """A chunk sent at 1 bit/s held the link for its bits' time at that rate (8 kB: over two
    hours), whatever the rate became after it; now they are timed at the rate in force."""
    with target() as (server, to), LinkEmulator(to) as link:
        client = dial(link)
        far, _ = server.accept()
        link.shape(rate_bps=1.0)
        client.sendall(b"x" * 1000)
        assert len(receive(far, 1000)) == 1000  # the first chunk goes at once
        client.sendall(b"y" * 1000)
        far.settimeout(0.3)
        with pytest.raises(TimeoutError):
            far.recv(1000)  # waits for the first one's 8000 bits
        link.shape(rate_bps=None)
        far.settimeout(5)
        t0 = time.monotonic()
        assert receive(far, 1000) == b"y" * 1000
        assert time.monotonic() - t0 < 1.0
        client.close()
        far.close()


def test_the_control_file_sets_the_link_and_names_what_is_wrong(tmp_path):
    path = tmp_path / "link.json"
    with target() as (_server, to), LinkEmulator(to) as link:
        path.write_text(json.dumps({"delay_ms": 100, "jitter_ms": 20, "rate_kbps": 64}))
        apply_control(link, read_control(path))
        assert link.shapes()["forward"] == Shape(0.1, 0.02, 64e3)
        path.write_text(json.dumps({"cut": True, "rate_kbps": None}))
        apply_control(link, read_control(path))
        assert link.is_cut and link.shapes()["back"].rate_bps is None
        path.write_text(json.dumps({"cut": False}))
        apply_control(link, read_control(path))
        assert not link.is_cut
    nan, inf = float("nan"), float("inf")  # json.dumps writes NaN and Infinity, json reads them
    for bad, named in (
        ({"loss": 0.1}, "loss"),
        ({"cut": 1}, "cut"),
        ([], "object"),
        ({"delay_ms": nan}, r"delay_ms must be in \[0, 3600000\]"),
        ({"jitter_ms": -1}, r"jitter_ms must be in \[0, 3600000\]"),
        ({"delay_ms": inf}, "delay_ms must be in"),
        ({"rate_kbps": 0}, "rate_kbps must be finite and > 0"),
        ({"delay_ms": 1e300}, r"delay_ms must be in \[0, 3600000\]"),  # finite, and forever
    ):
        path.write_text(json.dumps(bad))
        with pytest.raises(ValueError, match=named):
            read_control(path)
    path.write_text("[" * 100_000 + "]" * 100_000)  # RecursionError ended the emulator's loop
    with pytest.raises(ValueError, match="nested too deeply"):
        read_control(path)
    path.write_text('{"jitter_ms": ' + "9" * 400 + "}")  # overflows a float: still a ValueError
    with pytest.raises(ValueError, match="jitter_ms must be in"):
        read_control(path)


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--to", "tcp/127.0.0.1:1", "--listen", ":99999"], "--listen ':99999'"),
        (["--to", "tcp/127.0.0.1:1", "--listen", "bogus"], "--listen 'bogus'"),
        (["--to", "bogus"], "--to 'bogus'"),
        (["--to", "tcp/127.0.0.1:99999"], "--to 'tcp/127.0.0.1:99999'"),
        (["--to", "udp/127.0.0.1:7447"], "the link relays TCP only"),  # was relayed as TCP
        # were taken, leaving a link that never delivers; the control file refused them
        (["--to", "tcp/127.0.0.1:1", "--delay-ms", "inf"], "--delay-ms must be in [0, 3600000]"),
        (["--to", "tcp/127.0.0.1:1", "--delay-ms", "1e12"], "--delay-ms must be in"),
        (["--to", "tcp/127.0.0.1:1", "--jitter-ms", "nan"], "--jitter-ms must be in"),
        (["--to", "tcp/127.0.0.1:1", "--rate-kbps", "inf"], "--rate-kbps must be finite and > 0"),
        (["--to", "tcp/127.0.0.1:1", "--rate-kbps", "0"], "--rate-kbps must be finite and > 0"),
    ],
)
def test_link_refuses_an_endpoint_or_a_shape_naming_the_option(args, says):
    from tltrack.app import app
    from typer.testing import CliRunner

    r = CliRunner().invoke(app, ["link", *args])
    assert r.exit_code == 2 and says in r.output, r.output


def test_two_missed_heartbeats_cut_a_link_and_the_next_restores_it():
    watch = LinkWatch(period_s=0.1)
    assert watch.check(0.0) == [] and not watch.is_cut("s1") and watch.due(0.0) is None
    watch.beat("s1", 0.0)
    watch.beat("s1", 0.1)
    assert watch.due(0.15) == pytest.approx(0.15)
    assert watch.check(0.3) == [], "exactly two periods: not yet"
    assert watch.check(0.31) == ["s1"] and watch.is_cut("s1") and watch.cuts == 1
    assert watch.check(0.5) == [], "a cut is reported once"
    assert watch.states() == {"s1": "cut"} and watch.due(0.5) is None
    assert watch.beat("s1", 0.6) is True, "back"
    assert watch.states() == {"s1": "up"} and not watch.is_cut("s1")
    assert watch.beat("s1", 0.7) is False


def beats(watch: LinkWatch, times: list[float], sid: str = "s1") -> None:
    for t in times:
        watch.beat(sid, t)


def test_uneven_heartbeats_lengthen_the_silence_that_cuts_up_to_three_periods():
    steady, uneven = LinkWatch(period_s=0.1), LinkWatch(period_s=0.1)
    beats(steady, [0.1 * i for i in range(20)])
    # the same mean period, each beat 20 ms early or late in turn: gaps of 60 and 140 ms
    beats(uneven, [0.1 * i + (0.02 if i % 2 else -0.02) for i in range(20)])
    assert steady.timeout_s("s1") == pytest.approx(0.2)
    timeout = uneven.timeout_s("s1")
    assert 0.24 < timeout < 0.3, timeout
    # a silence between the two: the steady link is cut, the uneven one not yet
    silence = (0.2 + timeout) / 2
    assert steady.check(1.9 + silence) == ["s1"]
    assert uneven.check(1.92 + silence) == []
    assert uneven.due(1.92 + silence) == pytest.approx(timeout - silence)
    assert uneven.check(1.92 + timeout + 0.01) == ["s1"]
    wild = LinkWatch(period_s=0.1)
    beats(wild, [0.0, 0.5, 0.55, 1.2, 1.25, 2.0])
    assert wild.timeout_s("s1") == pytest.approx(0.3), "capped at three periods"
    assert LinkWatch(period_s=0.1).timeout_s("unheard") == pytest.approx(0.2)


def test_the_silence_of_a_cut_is_not_taken_for_a_gap_between_beats():
    watch = LinkWatch(period_s=0.1)
    beats(watch, [0.1 * i for i in range(10)])
    before = watch.timeout_s("s1")
    assert watch.check(5.0) == ["s1"]
    assert watch.beat("s1", 5.0) is True
    beats(watch, [5.1, 5.2])
    assert watch.timeout_s("s1") == pytest.approx(before)
    watch.beat("s1", 5.15)  # overtaken by the one at 5.2: no gap, and last stays 5.2
    assert watch.due(5.2) == pytest.approx(before)


def test_a_source_that_never_beat_is_never_cut():
    watch = LinkWatch(period_s=0.1)
    watch.beat("s2", 0.0)
    assert watch.check(10.0) == ["s2"]
    assert not watch.is_cut("s1") and "s1" not in watch.states()


def test_the_heartbeat_key_parses_back():
    key = keys.heartbeat("s1")
    assert key == "tltrack/source/s1/heartbeat"
    info = keys.parse(key)
    assert (info.kind, info.source, info.operator) == ("heartbeat", "s1", "source/s1")
    assert keys.HEARTBEATS == "tltrack/source/*/heartbeat"
