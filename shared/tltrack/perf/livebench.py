"""``tltrack bench-live``: end-to-end latency of one tracker pair, and its highest sustained rate,
for each topology (single router, a router per operator) and each particle filter kind.

A benchmark, not a test: it prints what it measured on this machine, now. The stack is the demo's
(routers and services on loopback, under the shipped access control); latency is the scorer's,
sensor timestamp to estimate arrival: the TL estimate's, every estimate's pooled, and the TL
estimate's stages (:mod:`tltrack.live.latency`). Beside them, in the same run, the two terms of the
physical limit: the routed Zenoh round trip (:mod:`tltrack.perf.rtt`) and the TL step; and each
filter's step live against the same step in-process (:func:`tltrack.perf.bench.run_bench`).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

from tltrack.config import make_config
from tltrack.live import supervisor, topology
from tltrack.live.topology import Kind
from tltrack.perf import rtt
from tltrack.perf.bench import run_bench

#: the live episode: the demo's scenario, a fixed truth, run 0
PRESET, TRUTH, SEED = "arasaratnam-haykin", "fixed", 0
#: the product's defaults, whose figures go at the top level of the result
DEFAULT_TOPOLOGY: Kind = "federated"
DEFAULT_FILTER = "rpf"


def episode(
    kind: Kind, kind_filter: str, pace: float, steps: int, particles: int, tmp: Path
) -> dict[str, Any]:
    """One episode at ``pace`` steps/s; the scorer's summary (empty if it failed)."""
    run = f"{kind}-{kind_filter}-{pace:g}"
    db = tmp / f"scorer-{run}.sqlite"
    topo = topology.build(kind, ["s1"])
    env = {"TLTRACK_PRIMARY_FILTER": kind_filter, "TLTRACK_SOURCE_FILTER": kind_filter}
    with supervisor.Stack(topo.referee.endpoint, tmp / f"logs-{run}", True, env, topo) as stack:
        stack.start_router()
        stack.start_service(
            "scorer", env={"TLTRACK_SCORER_DB": str(db), "TLTRACK_SCORER_GRACE_S": "2"}
        )
        wait = stack.start_trackers(make_config())
        flags = supervisor.sim_flags(steps, particles, pace, False, PRESET, TRUTH, SEED)
        stack.start_service("sensor_sim", *flags, env=supervisor.sim_env(wait))
        stack.wait("sensor_sim", steps / pace + 120)
        summary = supervisor.wait_for_scored(stack.endpoint, 1, 60, "referee")
    return summary or {}


def sustained(summary: dict[str, Any], steps: int, period_ms: float) -> bool:
    """Nothing lost, and no backlog: every estimate's p99 latency under 5 step periods."""
    filters = summary.get("filters", {})
    if len(filters) < 3 or any(f["steps"] != steps for f in filters.values()):
        return False
    p99 = summary["latency_ms"]["p99"]
    return p99 is not None and p99 < 5 * period_ms


def measure(
    kind: Kind,
    kind_filter: str,
    particles: int,
    pace: float,
    steps: int,
    rates: list[float],
    ladder_steps: int,
) -> dict[str, Any]:
    """Latency at ``pace``, then the rate ladder up to the first rate not sustained."""
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        at_pace = episode(kind, kind_filter, pace, steps, particles, tmp)
        best, ladder = None, []
        for rate in rates:
            summary = episode(kind, kind_filter, rate, ladder_steps, particles, tmp)
            ok = sustained(summary, ladder_steps, 1e3 / rate)
            ladder.append({"rate": rate, "sustained": ok, **rung(summary, ladder_steps)})
            if not ok:
                break
            best = rate
    filters: dict[str, dict[str, Any]] = at_pace.get("filters", {})
    tl = filters.get(f"tl-{kind_filter}", {})
    return {
        "latency_ms": tl.get("latency_ms"),  # the TL estimate's
        "latency_ms_all": at_pace.get("latency_ms"),  # every filter's estimates, pooled
        "stages_ms": tl.get("stages_ms"),  # where the TL estimate's time goes
        "live_step_ms": {n: (f.get("stages_ms") or {}).get("step") for n, f in filters.items()},
        "max_sustained_steps_per_s": best,
        "ladder": ladder,
    }


def rung(summary: dict[str, Any], steps: int) -> dict[str, Any]:
    """Why a rung passed or failed: every estimate's p99 (ms), the estimates missing, and the
    stages (p50, ms) of every estimate: where a backlog builds up."""
    filters = summary.get("filters", {})
    return {
        "p99_ms": (summary.get("latency_ms") or {}).get("p99"),
        "missing": {name: steps - f["steps"] for name, f in filters.items()} or None,
        "stages_ms": summary.get("stages_ms"),
    }


def limit(run: dict[str, Any], rtt_ms: dict[str, float], engine_ms: dict[str, Any]) -> None:
    """Add the physical limit's terms to ``run``: the round trip, the TL step, their ratio to
    the TL estimate's p50 (the target is at most 3), and each step live and in-process."""
    live: dict[str, float | None] = run.pop("live_step_ms")
    tl_step = live.get(f"tl-{run['filter']}")
    p50 = (run["latency_ms"] or {}).get("p50")
    run["zenoh_rtt_ms"] = rtt_ms
    run["tl_step_ms"] = tl_step
    run["ratio"] = None if p50 is None or tl_step is None else p50 / (rtt_ms["p50"] + tl_step)
    run["step_ms"] = {n: {"live": ms, "engine": engine_ms.get(n)} for n, ms in live.items()}


def run(
    particles: int,
    pace: float,
    steps: int,
    rates: list[float],
    kinds: tuple[Kind, ...] = topology.TOPOLOGIES,
    filters: tuple[str, ...] = ("rpf", "pf"),
    ladder_steps: int = 5000,
) -> dict[str, Any]:
    """Every topology in ``kinds`` x filter kind in ``filters``, one after the other; the
    product's defaults, when measured, also at the top level."""
    loadavg_at_start = list(os.getloadavg())
    engine = run_bench(
        particles, cfg=make_config(preset=PRESET, truth=TRUTH, seed=SEED), stonesoup=False
    )["ms_per_step"]
    runs = []
    for kind in kinds:
        rtt_ms = rtt.measure(kind)
        for kind_filter in filters:
            one = {"topology": kind, "filter": kind_filter}
            one |= measure(kind, kind_filter, particles, pace, steps, rates, ladder_steps)
            limit(one, rtt_ms, engine)
            runs.append(one)
    default = next(
        (r for r in runs if (r["topology"], r["filter"]) == (DEFAULT_TOPOLOGY, DEFAULT_FILTER)),
        {},
    )
    top = {k: v for k, v in default.items() if k not in ("topology", "filter")}
    return {
        "particles": particles,
        "pace": pace,
        "rates_tried": rates,
        "ladder_steps": ladder_steps,
        **top,
        "runs": runs,
        "loadavg_at_start": loadavg_at_start,
        "loadavg": list(os.getloadavg()),
    }
