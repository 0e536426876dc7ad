"""The routed Zenoh round trip between two Python processes: the floor under any live latency.

``bench-live`` compares its end-to-end latency with this figure, measured in the same run on
the same shape of network: one router (``single``), or two routers linked as the primary's is
to the referee's (``federated``). The pinger sits on the first router, the ponger (a child
process, :func:`pong`) on the last; the ponger answers from Zenoh's callback thread, with
express publishers, as directly as Zenoh allows. The routers here enforce no access control:
the keys are the benchmark's own (``tltrack-bench/``), never the product's.
"""

from __future__ import annotations

import json
import signal
import socket
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import zenoh
from tltrack.live import supervisor, topology
from tltrack.live.topology import Kind
from tltrack.wire.transport import ZenohSettings, open_session

PING, PONG, READY = "tltrack-bench/ping", "tltrack-bench/pong", "tltrack-bench/ready"


def pong() -> None:
    """Echo every ping until SIGTERM (the endpoint from ``TLTRACK_ZENOH_ENDPOINTS``)."""
    stop = threading.Event()
    with open_session(ZenohSettings()) as session:  # SIGTERM ends it while it connects
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        pub = session.declare_publisher(PONG, express=True)
        sub = session.declare_subscriber(PING, lambda s: pub.put(s.payload))
        token = session.liveliness().declare_token(READY)
        stop.wait()
        token.undeclare()
        sub.undeclare()
        pub.undeclare()


def _router_argv(listen: str, connect: str | None, zenohd: bool) -> list[str]:
    """The Python arguments that run a router: ``tltrack router``, or a stock ``zenohd``."""
    if zenohd:
        dial = ["-e", connect] if connect else []
        run = "import os, sys; os.execvp('zenohd', sys.argv[1:])"
        return ["-c", run, "zenohd", "--no-multicast-scouting", "-l", listen, *dial]
    dial = ["--connect", connect] if connect else []
    return ["-m", "tltrack", "router", "--listen", listen, *dial]


def _wait_listening(stack: supervisor.Stack, name: str, endpoint: str, zenohd: bool) -> None:
    """Our router says when it listens; a zenohd is asked by connecting to its port."""
    if not zenohd:
        stack.wait_listening(name)
        return
    host, port = endpoint.removeprefix("tcp/").rsplit(":", 1)
    deadline = time.monotonic() + 60
    while True:
        try:
            socket.create_connection((host, int(port)), timeout=1).close()
            return
        except OSError:
            if stack.procs[name].poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{name} (zenohd) is not listening on {endpoint}") from None
            time.sleep(0.05)


def measure(
    kind: Kind, samples: int = 2000, warmup: int = 200, zenohd: bool = False
) -> dict[str, float]:
    """p50 and p99 of ``samples`` round trips (ms), after ``warmup`` unrecorded ones, and ``n``
    the round trips timed (a pong missing for 2 s raises); with ``zenohd``, through stock Rust
    routers (on PATH, ``make zenohd``) instead of the product's."""
    ports = topology.free_ports(2)
    first, last = (f"tcp/127.0.0.1:{p}" for p in ports)
    with (
        tempfile.TemporaryDirectory() as tmp,
        supervisor.Stack(first, Path(tmp) / "logs") as stack,
    ):
        stack.start("router_a", _router_argv(first, None, zenohd))
        _wait_listening(stack, "router_a", first, zenohd)
        if kind == "federated":
            stack.start("router_b", _router_argv(last, first, zenohd))
            _wait_listening(stack, "router_b", last, zenohd)
        there = last if kind == "federated" else first
        code = "from tltrack.perf.rtt import pong; pong()"
        stack.start("pong", ["-c", code], {"TLTRACK_ZENOH_ENDPOINTS": json.dumps([there])})
        return _ping(first, samples, warmup)


def _ping(endpoint: str, samples: int, warmup: int) -> dict[str, float]:
    back = threading.Event()
    with open_session(ZenohSettings(endpoints=[endpoint])) as session:
        ready = threading.Event()
        watch = session.liveliness().declare_subscriber(READY, lambda s: ready.set(), history=True)
        sub = session.declare_subscriber(PONG, lambda _s: back.set())
        pub = session.declare_publisher(
            PING, express=True, congestion_control=zenoh.CongestionControl.BLOCK
        )
        if not ready.wait(60):
            raise RuntimeError("the ponger did not come up within 60 s")
        rtts: list[float] = []
        for i in range(warmup + samples):
            back.clear()
            t0 = time.perf_counter()
            pub.put(b"ping")
            if not back.wait(2.0):
                raise RuntimeError(f"no pong within 2 s (round trip {i})")
            if i >= warmup:
                rtts.append((time.perf_counter() - t0) * 1e3)
        for entity in (pub, sub, watch):
            entity.undeclare()
    p50, p99 = np.percentile(rtts, [50, 99])
    return {"p50": float(p50), "p99": float(p99), "n": len(rtts)}
