"""A TCP relay on one link: it keeps a copy of every byte it forwards (what anyone on the path
between two routers can read), and it can cut the link and restore it.

In a test it runs on loopback (``with Relay(target) as r``). Run as a program, it is a relay in a
container (tests/compose.relay.yaml): ``python relay.py PORT HOST:PORT FILE`` relays port PORT
of every interface to HOST:PORT and appends every byte it forwards to FILE.

:func:`sentinels` are what the tests look for in those bytes: msgpack encodes each float of a
message as the 9 bytes 0xcb + its big-endian float64, random enough to be unique to one value.
"""

from __future__ import annotations

import contextlib
import socket
import sys
import threading
from typing import BinaryIO

import msgpack
import numpy as np


def sentinels(values: np.ndarray) -> set[bytes]:
    """How each value travels inside a message."""
    return {msgpack.packb(float(v)) for v in np.ravel(values)}


def found(patterns: set[bytes], wire: bytes) -> int:
    """How many of ``patterns`` occur in ``wire``."""
    return sum(p in wire for p in patterns)


class Relay:
    """Relays connections from ``port`` to ``target``; use as ``with Relay(target) as r:``."""

    def __init__(
        self,
        target: str,
        listen: tuple[str, int] = ("127.0.0.1", 0),
        sink: BinaryIO | None = None,
    ) -> None:
        host, port = target.removeprefix("tcp/").rsplit(":", 1)
        self.target = (host, int(port))
        self.seen = bytearray()
        self._sink = sink
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
            return bytes(self.seen)

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

    def _pipe(self, a: socket.socket, b: socket.socket) -> None:
        with contextlib.suppress(OSError):  # the other direction, or cut(), closed both
            while data := a.recv(65536):
                with self._lock:
                    self.seen.extend(data)
                    if self._sink is not None:
                        self._sink.write(data)
                        self._sink.flush()
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
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pipe, args=(a, b), daemon=True).start()

    def __enter__(self) -> Relay:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self.cut()
        self._thread.join(5)
        self._server.close()


def main(port: str, target: str, path: str) -> None:
    with open(path, "ab") as sink:
        Relay(target, ("0.0.0.0", int(port)), sink).serve()  # until the container stops


if __name__ == "__main__":
    main(*sys.argv[1:])
