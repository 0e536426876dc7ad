"""``tltrack bench-live``: end-to-end latency of one tracker pair, and its highest sustained rate,
in the single-router topology, the federated one (a router per operator), or both in one run.

A benchmark, not a test: it prints what it measured on this machine, now. The stack is the demo's
(routers and services on loopback, under the shipped access control); latency is the scorer's,
sensor timestamp to estimate arrival: the TL estimate's, every estimate's pooled, and the TL
estimate's stages (:mod:`tltrack.latency`).
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from tltrack import demo, topology
from tltrack.config import make_config
from tltrack.topology import Kind


def episode(kind: Kind, pace: float, steps: int, particles: int, tmp: Path) -> dict[str, Any]:
    """One episode at ``pace`` steps/s; the scorer's summary (None values if it failed)."""
    run = f"{kind}-{pace:g}"
    db = tmp / f"scorer-{run}.sqlite"
    topo = topology.build(kind, ["s1"])
    with demo.Stack(topo.referee.endpoint, tmp / f"logs-{run}", True, topology=topo) as stack:
        stack.start_router()
        stack.start_service(
            "scorer", env={"TLTRACK_SCORER_DB": str(db), "TLTRACK_SCORER_GRACE_S": "2"}
        )
        wait = stack.start_trackers(make_config())
        stack.start_service(
            "sensor_sim",
            *demo.sim_flags(steps, particles, pace, False, "arasaratnam-haykin", "fixed", 0),
            env={"TLTRACK_SIM_WAIT_FOR": json.dumps(wait)},
        )
        stack.wait("sensor_sim", steps / pace + 120)
        summary = demo.wait_for_scored(stack.endpoint, 1, 60, "referee")
    return summary or {}


def sustained(summary: dict[str, Any], steps: int, period_ms: float) -> bool:
    """Nothing lost, and no backlog: p99 latency stays under 5 step periods (or 20 ms)."""
    filters = summary.get("filters", {})
    if len(filters) < 3 or any(f["steps"] != steps for f in filters.values()):
        return False
    p99 = summary["latency_ms"]["p99"]
    return p99 is not None and p99 < max(5 * period_ms, 20.0)


def measure(kind: Kind, particles: int, pace: float, steps: int, rates: list[float]) -> Any:
    """Latency at ``pace`` and the highest of ``rates`` sustained, in topology ``kind``."""
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        at_pace = episode(kind, pace, steps, particles, tmp)
        best = None
        for rate in rates:
            if not sustained(episode(kind, rate, steps, particles, tmp), steps, 1e3 / rate):
                break
            best = rate
    filters: dict[str, dict[str, Any]] = at_pace.get("filters", {})
    tl = next((f for name, f in filters.items() if name.startswith("tl-")), {})
    return {
        "latency_ms": tl.get("latency_ms"),  # the TL estimate's
        "latency_ms_all": at_pace.get("latency_ms"),  # every filter's estimates, pooled
        "stages_ms": tl.get("stages_ms"),  # where the TL estimate's time goes
        "max_sustained_steps_per_s": best,
    }


def run(
    particles: int,
    pace: float,
    steps: int,
    rates: list[float],
    kinds: tuple[Kind, ...] = topology.TOPOLOGIES,
) -> dict[str, Any]:
    """One entry per topology in ``kinds``, measured one after the other."""
    return {
        "particles": particles,
        "pace": pace,
        "rates_tried": rates,
        "topologies": {kind: measure(kind, particles, pace, steps, rates) for kind in kinds},
        "loadavg": list(os.getloadavg()),
    }
