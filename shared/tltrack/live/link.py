"""A link that misbehaves on demand: a user-space TCP relay between two routers that delays (with
jitter), caps the bandwidth, stalls and cuts, changed while it runs.

The kernel's ``netem`` is not everywhere (not on the machine this was built on), and a relay needs
no privilege. One router dials the relay's endpoint instead of the other router's
(:attr:`tltrack.live.topology.Topology.via`, or ``--connect`` of ``tltrack router``), and the
relay forwards each connection to the other router, shaping each direction:

- **delay** ``delay_s`` and **jitter** ``jitter_s``: each chunk read waits ``delay_s`` plus a
  uniform draw in ``[-jitter_s, jitter_s]`` (never below zero). A TCP stream keeps its order, so
  no chunk overtakes the one before it: the gap between two arrivals may grow or shrink by up to
  twice the jitter.
- **rate** ``rate_bps``: a chunk leaves no sooner than the previous one's bits have at that rate.
- **stall** ``stalled``: nothing is forwarded, connections stay open (a link that goes silent:
  Zenoh notices only after its lease); what was held goes on once ``stalled`` is false again.
- **cut**: every connection is closed and new ones are refused until
  :meth:`~LinkEmulator.restore` (a link that is gone: Zenoh notices at once and redials).

It never drops bytes: the federation runs TLS over TCP, where a lost byte corrupts a stream rather
than losing a transfer. Transfer loss is studied in the engine (``tltrack study links``).

From Python: ``with LinkEmulator(target) as link: link.shape(delay_s=0.1); link.cut()``. From the
command line: ``tltrack link`` (:mod:`tltrack.app.link`), controlled through a JSON file it
rereads (:func:`read_control`).
"""

from __future__ import annotations

import contextlib
import json
import math
import queue
import random
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Literal

Way = Literal["forward", "back"]  #: forward: from the dialler to the target
Direction = Literal["forward", "back", "both"]
Tap = Callable[[bytes], object]  #: what a direction of a connection passes its bytes to

_CHUNK = 65536
_QUEUED = 1024  #: chunks held per direction before the relay stops reading (TCP pushes back)
_TICK = 0.005  #: how often a held chunk looks again at the clock, a stall or a cut


@dataclass(frozen=True)
class Shape:
    """What one direction of the link does to what it carries."""

    delay_s: float = 0.0
    jitter_s: float = 0.0
    rate_bps: float | None = None  #: None: as fast as loopback
    stalled: bool = False

    def __post_init__(self) -> None:
        if self.delay_s < 0 or self.jitter_s < 0:
            raise ValueError(f"delay and jitter must be >= 0 s: {self}")
        if self.rate_bps is not None and self.rate_bps <= 0:
            raise ValueError(f"rate must be > 0 bit/s or None: {self.rate_bps}")


_SHAPE_FIELDS = {f.name for f in fields(Shape)}


class _Connection:
    """One relayed connection: its two sockets, closed together."""

    def __init__(self, client: socket.socket, upstream: socket.socket) -> None:
        self.socks = (client, upstream)
        self.closed = threading.Event()

    def close(self) -> None:
        self.closed.set()
        for sock in self.socks:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            with contextlib.suppress(OSError):
                sock.close()


class LinkEmulator:
    """Relays connections from ``listen`` to ``target``, shaped; use as ``with`` (or
    :meth:`serve` in the calling thread). ``tap``: given the direction, returns where that
    direction of a new connection passes every byte it forwards (a capture), or None."""

    def __init__(
        self,
        target: str,
        listen: tuple[str, int] = ("127.0.0.1", 0),
        *,
        shape: Shape | None = None,
        seed: int | None = None,
        tap: Callable[[Way], Tap | None] | None = None,
    ) -> None:
        self.target = host_port(target, "target")
        self._shapes: dict[Way, Shape] = {"forward": shape or Shape(), "back": shape or Shape()}
        self._rng = random.Random(seed)
        self._tap = tap
        self._lock = threading.Lock()
        self._open: list[_Connection] = []
        self._cut = threading.Event()
        self._stop = threading.Event()
        self._server = socket.create_server(listen)
        self._server.settimeout(0.1)
        self.endpoint = f"tcp/{listen[0]}:{self._server.getsockname()[1]}"
        self._thread = threading.Thread(target=self.serve, name="link", daemon=True)

    # ---- control ----------------------------------------------------------------------------

    def shape(self, direction: Direction = "both", **changes: Any) -> None:
        """Change ``delay_s``, ``jitter_s``, ``rate_bps`` or ``stalled`` of one direction or both;
        it applies to every chunk read from now on (a higher rate also to the chunk still going)."""
        unknown = set(changes) - _SHAPE_FIELDS
        if unknown:
            raise ValueError(f"no such link setting: {', '.join(sorted(unknown))}")
        ways: tuple[Way, ...] = ("forward", "back") if direction == "both" else (direction,)
        with self._lock:
            for d in ways:
                self._shapes[d] = replace(self._shapes[d], **changes)

    def shapes(self) -> dict[Way, Shape]:
        with self._lock:
            return dict(self._shapes)

    @property
    def is_cut(self) -> bool:
        return self._cut.is_set()

    def cut(self) -> None:
        """Close every connection, and refuse new ones until :meth:`restore`."""
        self._cut.set()
        with self._lock:
            conns, self._open = self._open, []
        for conn in conns:
            conn.close()

    def restore(self) -> None:
        self._cut.clear()

    # ---- relaying ---------------------------------------------------------------------------

    def _read(self, conn: _Connection, a: socket.socket, held: queue.Queue[Any], d: Way) -> None:
        """Read what ``a`` sends and stamp each chunk with when it may leave."""
        tap = self._tap(d) if self._tap else None
        last = 0.0
        with contextlib.suppress(OSError):
            while data := a.recv(_CHUNK):
                if tap is not None:
                    tap(data)
                with self._lock:
                    s = self._shapes[d]
                    lag = max(0.0, s.delay_s + self._rng.uniform(-s.jitter_s, s.jitter_s))
                last = max(last, time.monotonic() + lag)  # a stream keeps its order
                if not _put(conn, held, (last, data)):
                    return
        _put(conn, held, None)  # the end: the writer closes the connection once all is sent

    def _write(self, conn: _Connection, b: socket.socket, held: queue.Queue[Any], d: Way) -> None:
        """Send each chunk to ``b`` once due, not stalled, and within the rate."""
        #: the previous chunk: when it began to go, its bits, and when they had gone at its rate;
        #: a higher rate since lets them go sooner (a chunk at 1 bit/s held the link for hours)
        last: tuple[float, int, float] | None = None
        with contextlib.suppress(OSError):
            while (item := held.get()) is not None:
                due, data = item
                while not conn.closed.is_set():
                    with self._lock:
                        s = self._shapes[d]
                    now = time.monotonic()
                    free = (
                        0.0
                        if last is None or s.rate_bps is None
                        else min(last[2], last[0] + last[1] / s.rate_bps)
                    )
                    if not s.stalled and now >= max(due, free):
                        break
                    time.sleep(_TICK if s.stalled else min(_TICK, max(due, free) - now))
                if conn.closed.is_set():
                    return
                if s.rate_bps is not None:
                    start, bits = max(free, time.monotonic()), len(data) * 8
                    last = (start, bits, start + bits / s.rate_bps)
                b.sendall(data)
        conn.close()
        with self._lock, contextlib.suppress(ValueError):
            self._open.remove(conn)

    def serve(self) -> None:
        """Accept and relay connections, in this thread, until :meth:`close`."""
        while not self._stop.is_set():
            try:
                client, _ = self._server.accept()
            except TimeoutError:
                continue
            except OSError:  # closed
                return
            if self._cut.is_set():
                client.close()
                continue
            try:
                upstream = socket.create_connection(self.target, timeout=2)
            except OSError:
                client.close()
                continue
            upstream.settimeout(None)
            conn = _Connection(client, upstream)
            with self._lock:
                self._open.append(conn)
            ways: tuple[tuple[socket.socket, socket.socket, Way], ...] = (
                (client, upstream, "forward"),
                (upstream, client, "back"),
            )
            for a, b, d in ways:
                held: queue.Queue[Any] = queue.Queue(_QUEUED)
                for job, sock in ((self._read, a), (self._write, b)):
                    threading.Thread(
                        target=job, args=(conn, sock, held, d), name=f"link-{d}", daemon=True
                    ).start()

    def close(self) -> None:
        self._stop.set()
        self.cut()
        if self._thread.is_alive():
            self._thread.join(5)
        self._server.close()

    def __enter__(self) -> LinkEmulator:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


def _put(conn: _Connection, held: queue.Queue[Any], item: Any) -> bool:
    """Queue ``item`` for the writer, waiting while the queue is full; False once closed."""
    while not conn.closed.is_set():
        with contextlib.suppress(queue.Full):
            held.put(item, timeout=0.1)
            return True
    return False


# ---- control from the command line ---------------------------------------------------------

#: the longest delay or jitter a control file may set [ms]: an hour (more stalls the link for good)
MOST_DELAY_MS = 3_600_000.0


def read_control(path: Path) -> dict[str, Any]:
    """A control file's settings: a JSON object with any of ``delay_ms``, ``jitter_ms``,
    ``rate_kbps`` (null: no cap), ``stalled`` and ``cut``; ``ValueError`` names what is wrong."""
    try:
        raw = json.loads(path.read_text())
    except (OSError, ValueError, RecursionError) as err:
        why = "nested too deeply" if isinstance(err, RecursionError) else err
        raise ValueError(f"{path}: {why}") from None
    if not isinstance(raw, dict):
        raise ValueError(f"{path}: a JSON object, please")
    allowed = {"delay_ms", "jitter_ms", "rate_kbps", "stalled", "cut"}
    if unknown := set(raw) - allowed:
        raise ValueError(f"{path}: unknown {', '.join(sorted(unknown))}; use {sorted(allowed)}")
    for name in ("stalled", "cut"):
        if name in raw and not isinstance(raw[name], bool):
            raise ValueError(f"{path}: {name} must be true or false")
    for name in ("delay_ms", "jitter_ms", "rate_kbps"):
        if name not in raw or (raw[name] is None and name == "rate_kbps"):
            continue
        try:
            check_setting(name, raw[name])
        except ValueError as err:
            raise ValueError(f"{path}: {err}") from None
    return raw


def check_setting(name: str, value: Any, label: str | None = None) -> None:
    """``ValueError`` (naming ``label``, else ``name``) unless ``value`` is one that ``delay_ms``,
    ``jitter_ms`` or ``rate_kbps`` may take: the control file's and the command line's limits."""
    label = label or name
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{label} must be a number")
    rate = name == "rate_kbps"  # a cap of 0 would stall the link for good
    try:
        ok = math.isfinite(value) and (value > 0 if rate else 0 <= value <= MOST_DELAY_MS)
    except OverflowError:  # an integer of hundreds of digits
        ok = False
    if not ok:
        want = "finite and > 0" if rate else f"in [0, {MOST_DELAY_MS:.0f}]"
        raise ValueError(f"{label} must be {want}, not {value}")


def host_port(text: str, option: str, *, listen: bool = False) -> tuple[str, int]:
    """``[tcp/]HOST:PORT`` as (host, port), or ``ValueError`` naming ``option``. Where to
    ``listen``, the host may be left out (127.0.0.1) and the port may be 0 (any free one)."""
    protocol, slash, address = text.rpartition("/")
    if slash and protocol != "tcp":
        raise ValueError(f"{option} {text!r}: the link relays TCP only (tcp/HOST:PORT)")
    host, sep, port = address.rpartition(":")
    low = 0 if listen else 1
    if not (sep and (host or listen) and port.isdigit() and low <= int(port) <= 65535):
        raise ValueError(f"{option} {text!r}: HOST:PORT with a port in {low}..65535")
    return host or "127.0.0.1", int(port)


def apply_control(link: LinkEmulator, control: dict[str, Any]) -> None:
    """Set ``link`` as a control file says (:func:`read_control`); what it omits stays."""
    changes: dict[str, Any] = {}
    if "delay_ms" in control:
        changes["delay_s"] = control["delay_ms"] / 1e3
    if "jitter_ms" in control:
        changes["jitter_s"] = control["jitter_ms"] / 1e3
    if "rate_kbps" in control:
        rate = control["rate_kbps"]
        changes["rate_bps"] = None if rate is None else rate * 1e3
    if "stalled" in control:
        changes["stalled"] = control["stalled"]
    link.shape(**changes)
    if control.get("cut") is True and not link.is_cut:
        link.cut()
    elif control.get("cut") is False and link.is_cut:
        link.restore()
