"""A TCP relay on one link: it keeps a copy of every byte it forwards (what anyone on the path
between two routers can read), and it can cut the link and restore it.

In a test it runs on loopback (``with Relay(target) as r``); ``lag_s`` makes the link slow
towards the dialler. Run as a program, it is a relay in a
container (tests/compose.relay.yaml): ``python relay.py PORT HOST:PORT DIR`` relays port PORT
of every interface to HOST:PORT and writes every byte it forwards to a file in DIR.

Each direction of each connection keeps its bytes apart (a list in memory, or a file of its own),
so that no value is split by the other direction's bytes; :meth:`Relay.bytes` and
:func:`captured` join them with a separator no sentinel spans.

:func:`sentinels` are what the tests look for in those bytes: msgpack encodes each float of a
message as the 9 bytes 0xcb + its big-endian float64, random enough to be unique to one value.
"""

from __future__ import annotations

import contextlib
import socket
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import msgpack
import numpy as np


def sentinels(values: np.ndarray) -> set[bytes]:
    """How each value travels inside a message."""
    return {msgpack.packb(float(v)) for v in np.ravel(values)}


def found(patterns: set[bytes], wire: bytes) -> int:
    """How many of ``patterns`` occur in ``wire``."""
    return sum(p in wire for p in patterns)


SEPARATOR = b"\n" * 9  #: between two streams: no 9-byte sentinel spans it


def captured(directory: Path) -> bytes:
    """The streams a relay run as a program wrote into ``directory``."""
    return SEPARATOR.join(p.read_bytes() for p in sorted(directory.glob("*.bin")))


class Relay:
    """Relays connections from ``port`` to ``target``; use as ``with Relay(target) as r:``."""

    def __init__(
        self,
        target: str,
        listen: tuple[str, int] = ("127.0.0.1", 0),
        out: Path | None = None,
        lag_s: float = 0.0,
    ) -> None:
        host, port = target.removeprefix("tcp/").rsplit(":", 1)
        self.target = (host, int(port))
        self._out = out  #: where to write the streams; None: keep them in memory
        self.lag_s = lag_s  #: how long each chunk from the target waits before going on
        self._streams: list[bytearray] = []
        self._files = 0  #: streams written to ``out``
        self._lock = threading.Lock()
        self._open: list[socket.socket] = []
        self._cut = threading.Event()
        self._stop = threading.Event()
        self._server = socket.create_server(listen)
        self._server.settimeout(0.1)
        self.endpoint = f"tcp/127.0.0.1:{self._server.getsockname()[1]}"
        self._thread = threading.Thread(target=self.serve, daemon=True)

    def bytes(self) -> bytes:
        with self._lock:
            return SEPARATOR.join(self._streams)

    def cut(self) -> None:
        """Drop every connection, and refuse new ones until :meth:`restore`."""
        self._cut.set()
        with self._lock:
            socks, self._open = self._open, []
        for sock in socks:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            sock.close()

    def restore(self) -> None:
        self._cut.clear()

    def _stream(self) -> Callable[[bytes], object]:
        """Where one direction of one connection keeps what it forwards."""
        with self._lock:
            if self._out is None:
                self._streams.append(bytearray())
                return self._streams[-1].extend
            self._files += 1
            path = self._out / f"{self._files:05d}.bin"

        def append(data: bytes) -> None:
            with path.open("ab") as f:
                f.write(data)

        return append

    def _pipe(self, a: socket.socket, b: socket.socket, lag_s: float = 0.0) -> None:
        keep = self._stream()
        with contextlib.suppress(OSError):  # the other direction, or cut(), closed both
            while data := a.recv(65536):
                with self._lock:
                    keep(data)
                time.sleep(lag_s)
                b.sendall(data)
        for sock in (a, b):
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)

    def serve(self) -> None:
        """Accept and relay connections, in this thread, until the relay is closed."""
        while not self._stop.is_set():
            try:
                client, _ = self._server.accept()
            except TimeoutError:
                continue
            if self._cut.is_set():
                client.close()
                continue
            try:
                upstream = socket.create_connection(self.target, timeout=2)
            except OSError:
                client.close()
                continue
            upstream.settimeout(None)
            with self._lock:
                self._open += [client, upstream]
            for a, b, lag in ((client, upstream, 0.0), (upstream, client, self.lag_s)):
                threading.Thread(target=self._pipe, args=(a, b, lag), daemon=True).start()

    def __enter__(self) -> Relay:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self.cut()
        self._thread.join(5)
        self._server.close()


def main(port: str, target: str, directory: str) -> None:
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    Relay(target, ("0.0.0.0", int(port)), out).serve()  # until the container stops


if __name__ == "__main__":
    main(*sys.argv[1:])
