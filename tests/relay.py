"""A TCP relay on one link, on loopback: it keeps a copy of every byte it forwards (what anyone on
the path between two routers can read), and it can cut the link and restore it."""

from __future__ import annotations

import contextlib
import socket
import threading


class Relay:
    """Relays connections from ``port`` to ``target``; use as ``with Relay(target) as r:``."""

    def __init__(self, target: str) -> None:
        host, port = target.removeprefix("tcp/").rsplit(":", 1)
        self.target = (host, int(port))
        self.seen = bytearray()
        self._lock = threading.Lock()
        self._open: list[socket.socket] = []
        self._cut = threading.Event()
        self._stop = threading.Event()
        self._server = socket.create_server(("127.0.0.1", 0))
        self._server.settimeout(0.1)
        self.endpoint = f"tcp/127.0.0.1:{self._server.getsockname()[1]}"
        self._thread = threading.Thread(target=self._serve, daemon=True)

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
                b.sendall(data)
        for sock in (a, b):
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)

    def _serve(self) -> None:
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
