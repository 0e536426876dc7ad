"""The scorer's summary over a store of many scored episodes: read from scratch (every episode's
rows) against the scorer's way (the scored episodes' scores kept, only the episode under way
read), side by side, median of ``--repeats``.

    .venv/bin/python benchmarks/scorer_summary.py [--episodes 1000] [--repeats 5]

The store is synthetic: ``--episodes`` finished episodes of K = 100 steps and three filters (the
live demo's), and one episode under way, written straight into the scorer's schema.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from tltrack.services.scorer.store import Store
from tltrack.services.scorer.summary import Summarizer

K, FILTERS = 100, ("source-rpf", "rpf", "tl-rpf")


def fill(store: Store, episodes: int, rng: np.random.Generator) -> list[str]:
    """``episodes`` finished episodes and one under way; returns the finished ones' names."""
    P = json.dumps(np.eye(5).tolist())
    names = [f"ep-{e}" for e in range(episodes + 1)]
    for e, ep in enumerate(names):
        ended = (float(e) + 1.0, "complete") if e < episodes else (None, None)
        store.db.execute(
            "INSERT INTO episodes (episode, run, K, config, started, ended, end_reason)"
            " VALUES (?,?,?,?,?,?,?)",
            (ep, e, K, "{}", float(e), *ended),
        )
        pos = rng.normal(size=(K, 2)) * 1000.0
        store.db.executemany(
            "INSERT INTO truth (episode, k, x, t_sensor, pos) VALUES (?,?,?,?,?)",
            [(ep, k + 1, "[]", 0.0, json.dumps(pos[k].tolist())) for k in range(K)],
        )
        store.db.executemany(
            "INSERT INTO estimates (episode, filter, k, x, P, transfer_used, t_sensor, t_sent,"
            " t_recv, step_ms, pos, recovered, t_received, t_step)"
            " VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            [
                (
                    ep,
                    f,
                    k + 1,
                    "[0,0,0,0,0]",
                    P,
                    1,
                    0.0,
                    0.004,
                    0.005,
                    0.3,
                    json.dumps((pos[k] + 10.0).tolist()),
                    0,
                    0.001,
                    0.002,
                )
                for f in FILTERS
                for k in range(K)
            ],
        )
    store.commit()
    return names[:episodes]


def timed(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        store = Store(Path(tmp) / "scorer.sqlite")
        scored = set(fill(store, args.episodes, np.random.default_rng(0)))
        kept = Summarizer(store)
        kept.summary(final=scored)  # the scorer reads each scored episode once
        scratch, kept_s = [], []
        for _ in range(args.repeats):  # alternated, so both see the same machine
            scratch.append(timed(lambda: Summarizer(store).summary()))
            kept_s.append(timed(lambda: kept.summary(final=scored)))
        same = Summarizer(store).summary()["filters"] == kept.summary(final=scored)["filters"]
        store.close()
    rows = (args.episodes + 1) * K * len(FILTERS)
    print(f"{args.episodes} scored episodes + 1 under way, {rows} estimates:")
    a, b = statistics.median(scratch), statistics.median(kept_s)
    print(f"  from scratch  {a * 1e3:9.1f} ms (median of {args.repeats})")
    print(f"  kept          {b * 1e3:9.1f} ms")
    print(f"  ratio         {a / b:9.1f}x; the same figures both ways: {same}")


if __name__ == "__main__":
    main()
