"""``tltrack bench-live``: end-to-end latency of one tracker pair, and its highest sustained rate.

A benchmark, not a test: it prints what it measured on this machine, now. The stack is the demo's
(router and four services on loopback); latency is the scorer's, sensor timestamp to estimate
arrival: the TL estimate's, every estimate's pooled, and the TL estimate's stages.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

from tltrack import demo


def episode(pace: float, steps: int, particles: int, tmp: Path) -> dict[str, Any]:
    """One episode at ``pace`` steps/s; the scorer's summary (None values if it failed)."""
    db = tmp / f"scorer-{pace:g}.sqlite"
    endpoint = f"tcp/127.0.0.1:{demo.free_port()}"
    with demo.Stack(endpoint, tmp / f"logs-{pace:g}") as stack:
        stack.start_router()
        stack.start_service(
            "scorer", env={"TLTRACK_SCORER_DB": str(db), "TLTRACK_SCORER_GRACE_S": "2"}
        )
        stack.start_service("primary_tracker")
        stack.start_service("source_tracker")
        stack.start_service(
            "sensor_sim",
            *demo.sim_flags(steps, particles, pace, False, "arasaratnam-haykin", "fixed", 0),
        )
        stack.wait("sensor_sim", steps / pace + 120)
        summary = demo.wait_for_scored(endpoint, 1, 60)
    return summary or {}


def sustained(summary: dict[str, Any], steps: int, period_ms: float) -> bool:
    """Nothing lost, and no backlog: p99 latency stays under 5 step periods (or 20 ms)."""
    filters = summary.get("filters", {})
    if len(filters) < 3 or any(f["steps"] != steps for f in filters.values()):
        return False
    p99 = summary["latency_ms"]["p99"]
    return p99 is not None and p99 < max(5 * period_ms, 20.0)


def run(particles: int, pace: float, steps: int, rates: list[float]) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        at_pace = episode(pace, steps, particles, tmp)
        best = None
        for rate in rates:
            ok = sustained(episode(rate, steps, particles, tmp), steps, 1e3 / rate)
            if not ok:
                break
            best = rate
    filters: dict[str, dict[str, Any]] = at_pace.get("filters", {})
    tl = next((f for name, f in filters.items() if name.startswith("tl-")), {})
    return {
        "particles": particles,
        "pace": pace,
        "latency_ms": tl.get("latency_ms"),  # the TL estimate's
        "latency_ms_all": at_pace.get("latency_ms"),  # every filter's estimates, pooled
        "stages_ms": tl.get("stages_ms"),  # where the TL estimate's time goes (tltrack.latency)
        "max_sustained_steps_per_s": best,
        "rates_tried": rates,
        "loadavg": list(os.getloadavg()),
    }
