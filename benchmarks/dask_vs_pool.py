"""`tltrack reproduce --table2-pf-only` on a 2-worker Dask cluster against the local process pool.

    .venv/bin/python benchmarks/dask_vs_pool.py [--runs 1000] [--repeats 3] [--batch-size B]
        [--json FILE]

Starts a Dask scheduler and `dask worker --nworkers 2 --nthreads 1 --preload
tltrack.engine.dask_preload` on loopback, as docs/howto/dask.md does by hand, then runs the same
`tltrack reproduce --runs R --table2-pf-only` alternately on the local pool (2 processes) and with
`--scheduler`, `--repeats` times each, back to back, and compares the median walls (whole commands,
start-up included). The Table 2 rows must be the same, wall times aside.

It also measures the per-batch scheduling overhead: the round trip of an empty batch through each
executor, one at a time (latency) and 200 at once (throughput, per batch). The 1-minute load
average is sampled every 5 s during the whole run, since the figures mean little on a busy machine.
Every process it starts is stopped by its id at the end.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import Executor, ProcessPoolExecutor
from pathlib import Path

BIN = Path(sys.executable).parent


def noop(i: int) -> int:
    return i


def overhead(ex: Executor, n: int = 200) -> dict[str, float]:
    """ms per empty batch: one at a time (latency), and n at once (per batch)."""
    for f in [ex.submit(noop, i) for i in range(20)]:  # warm: processes and connections up
        f.result()
    t0 = time.perf_counter()
    for i in range(50):
        ex.submit(noop, i).result()
    latency = (time.perf_counter() - t0) / 50
    t0 = time.perf_counter()
    for f in [ex.submit(noop, i) for i in range(n)]:
        f.result()
    bulk = (time.perf_counter() - t0) / n
    return {"latency_ms": round(latency * 1e3, 2), "bulk_ms_per_batch": round(bulk * 1e3, 2)}


#: Table 2's timing columns, which differ from run to run
TIMINGS = ("ms iso / TL", "wall [min]")


def rows(table: Path) -> list[list[str]]:
    """Table 2's rows without its timing columns, and without the total wall line."""
    cells = [
        [c.strip() for c in line.strip().strip("|").split("|")]
        for line in table.read_text().splitlines()
        if line.startswith("| ") and "---" not in line
    ]
    keep = [i for i, name in enumerate(cells[0]) if name not in TIMINGS]
    return [[row[i] for i in keep] for row in cells]


def reproduce(runs: int, out: Path, extra: list[str]) -> float:
    cmd = [str(BIN / "tltrack"), "reproduce", "--runs", str(runs), "--table2-pf-only"]
    t0 = time.perf_counter()
    subprocess.run([*cmd, "--out", str(out), *extra], check=True, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--batch-size", type=int, default=None)
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "shared"))
    from tltrack.engine import cluster

    work = Path(tempfile.mkdtemp(prefix="dask-vs-pool-"))
    loads: list[float] = []
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(5.0):
            loads.append(os.getloadavg()[0])

    threading.Thread(target=sample, daemon=True).start()
    procs: list[subprocess.Popen[bytes]] = []
    worker_pids: list[int] = []
    try:
        file = work / "scheduler.json"
        procs.append(
            subprocess.Popen(
                [
                    *[str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0"],
                    *["--scheduler-file", str(file), "--no-dashboard"],
                ],
                stdout=(work / "scheduler.log").open("wb"),
                stderr=subprocess.STDOUT,
            )
        )
        while not file.exists():
            time.sleep(0.2)
        address = json.loads(file.read_text())["address"]
        procs.append(
            subprocess.Popen(
                [
                    *[str(BIN / "dask"), "worker", "--scheduler-file", str(file)],
                    *["--nworkers", "2", "--nthreads", "1", "--no-dashboard"],
                    *["--preload", "tltrack.engine.dask_preload"],
                ],
                stdout=(work / "worker.log").open("wb"),
                stderr=subprocess.STDOUT,
            )
        )
        with cluster.pool(address, worker_wait=300) as ex:
            assert ex is not None
            ex.client.wait_for_workers(2, timeout=300)
            worker_pids = list(ex.client.run(os.getpid).values())
            dask_overhead = overhead(ex)
        with ProcessPoolExecutor(2) as pool:
            pool_overhead = overhead(pool)

        extra = ["--batch-size", str(a.batch_size)] if a.batch_size else []
        walls: dict[str, list[float]] = {"pool": [], "dask": []}
        tables: dict[str, list[list[str]]] = {}
        for i in range(a.repeats):
            for how, more in (("pool", []), ("dask", ["--scheduler", address])):
                out = work / f"{how}-{i}"
                walls[how].append(round(reproduce(a.runs, out, [*extra, *more]), 1))
                tables.setdefault(how, rows(out / "table2_pf.md"))
                print(f"{how} #{i + 1}: {walls[how][-1]:.1f} s", file=sys.stderr)
        med = {k: statistics.median(v) for k, v in walls.items()}
        result = {
            "runs": a.runs,
            "batch_size": a.batch_size or "default",
            "walls_s": walls,
            "median_s": med,
            "dask_over_pool": round(med["dask"] / med["pool"], 3),
            "same_table2_rows": tables["pool"] == tables["dask"],
            "per_batch_overhead": {"dask": dask_overhead, "pool": pool_overhead},
            "loadavg_1min": {
                "mean": round(statistics.fmean(loads), 2) if loads else None,
                "min": min(loads, default=None),
                "max": max(loads, default=None),
            },
            "cpus": os.cpu_count(),
        }
    finally:
        stop.set()
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
        for pid in worker_pids:  # a worker process that outlived its nanny
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, 9)
    print(json.dumps(result, indent=2))
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
