"""A TCP relay on one link: it keeps a copy of every byte it forwards (what anyone on the path
between two routers can read), and it can cut the link and restore it, delay, stall and cap it
(the package's link emulator, :mod:`tltrack.live.link`, which it builds on).

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

import sys
import threading
from pathlib import Path

import msgpack
import numpy as np
from tltrack.live.link import LinkEmulator, Tap, Way


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


class Relay(LinkEmulator):
    """The package's link emulator (:mod:`tltrack.live.link`) keeping a copy of every byte it
    forwards; use as ``with Relay(target) as r:``. ``lag_s``: the link slow towards the dialler."""

    def __init__(
        self,
        target: str,
        listen: tuple[str, int] = ("127.0.0.1", 0),
        out: Path | None = None,
        lag_s: float = 0.0,
    ) -> None:
        self._out = out  #: where to write the streams; None: keep them in memory
        self._streams: list[bytearray] = []
        self._files = 0  #: streams written to ``out``
        self._keep = threading.Lock()
        super().__init__(target, listen, tap=self._stream)
        self.shape("back", delay_s=lag_s)

    def bytes(self) -> bytes:
        with self._keep:
            return SEPARATOR.join(self._streams)

    def _stream(self, _way: Way) -> Tap:
        """Where one direction of one connection keeps what it forwards."""
        with self._keep:
            if self._out is None:
                stream = bytearray()
                self._streams.append(stream)

                def extend(data: bytes) -> None:
                    with self._keep:
                        stream.extend(data)

                return extend
            self._files += 1
            path = self._out / f"{self._files:05d}.bin"

        def append(data: bytes) -> None:
            with path.open("ab") as f:
                f.write(data)

        return append


def main(port: str, target: str, directory: str) -> None:
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    Relay(target, ("0.0.0.0", int(port)), out).serve()  # until the container stops


if __name__ == "__main__":
    main(*sys.argv[1:])
