"""Do the product's routers, Zenoh in a Python process (``tltrack router``), cost latency against
a stock Rust ``zenohd``? The routed round trip of ``bench-live`` (:mod:`tltrack.perf.rtt`) through
each, alternated round by round, for one router and for two linked ones.

    make zenohd   # once: a stock zenohd on PATH
    .venv/bin/python benchmarks/router_rtt.py [--rounds 3] [--samples 2000]
"""

from __future__ import annotations

import argparse
import shutil

from tltrack.perf import rtt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--samples", type=int, default=2000)
    args = ap.parse_args()
    if shutil.which("zenohd") is None:
        ap.error("no zenohd on PATH: make zenohd builds one (~7.5 min)")
    for r in range(1, args.rounds + 1):
        for kind in ("single", "federated"):
            for zenohd in (False, True):
                got = rtt.measure(kind, samples=args.samples, zenohd=zenohd)
                router = "zenohd" if zenohd else "tltrack router"
                print(
                    f"round {r} {kind:9s} {router:14s} RTT p50 {got['p50']:.3f} ms"
                    f" p99 {got['p99']:.3f} ms",
                    flush=True,
                )


if __name__ == "__main__":
    main()
