"""bench-live's arithmetic, and its round trip through real routers and a real second process.
What it measures is a figure, not a test: nothing here is timed."""

from __future__ import annotations

import shutil
from typing import Any

import pytest
from tltrack.perf import livebench, rtt


def _summary(steps: int, p99: float, filters: int = 3) -> dict[str, Any]:
    names = ["tl-rpf", "rpf", "source-rpf"][:filters]
    return {
        "filters": {n: {"steps": steps} for n in names},
        "latency_ms": {"p50": p99 / 2, "p99": p99},
    }


@pytest.mark.parametrize(
    ("summary", "sustained"),
    [
        (_summary(5000, 4.9), True),  # under 5 periods of 1 ms
        (_summary(5000, 5.1), False),
        (_summary(5000, 10.0), False),  # no 20 ms floor any more
        (_summary(4999, 1.0), False),  # an estimate lost
        (_summary(5000, 1.0, filters=2), False),  # a filter silent
        ({}, False),  # the episode failed
    ],
)
@pytest.mark.unit
def test_a_rate_is_sustained_only_with_every_estimate_and_p99_under_five_periods(
    summary: dict[str, Any], sustained: bool
) -> None:
    assert livebench.sustained(summary, 5000, period_ms=1.0) is sustained


@pytest.mark.unit
def test_the_limit_is_the_round_trip_plus_the_tl_step() -> None:
    run: dict[str, Any] = {
        "filter": "rpf",
        "latency_ms": {"p50": 6.0, "p95": 8.0, "p99": 9.0},
        "live_step_ms": {"tl-rpf": 1.5, "rpf": 1.2, "source-rpf": 1.4},
    }
    livebench.limit(run, {"p50": 0.5, "p99": 0.9}, {"tl-rpf": 0.5, "rpf": 0.4})
    assert run["ratio"] == pytest.approx(6.0 / (0.5 + 1.5))
    assert run["tl_step_ms"] == 1.5
    assert run["zenoh_rtt_ms"] == {"p50": 0.5, "p99": 0.9}
    assert run["step_ms"] == {
        "tl-rpf": {"live": 1.5, "engine": 0.5},
        "rpf": {"live": 1.2, "engine": 0.4},
        "source-rpf": {"live": 1.4, "engine": None},
    }
    assert "live_step_ms" not in run


@pytest.mark.unit
def test_a_failed_episode_has_no_ratio() -> None:
    run: dict[str, Any] = {"filter": "pf", "latency_ms": None, "live_step_ms": {}}
    livebench.limit(run, {"p50": 0.5, "p99": 0.9}, {})
    assert run["ratio"] is None and run["tl_step_ms"] is None and run["step_ms"] == {}


@pytest.mark.parametrize("kind", ["single", "federated"])
@pytest.mark.integration
def test_the_round_trip_goes_through_real_routers_to_another_process(kind: str) -> None:
    got = rtt.measure(kind, samples=200, warmup=20)
    assert got["n"] == 200 and 0 < got["p50"] < 2000, got  # every ping had its pong


@pytest.mark.skipif(
    shutil.which("zenohd") is None,
    reason="no zenohd on PATH (make zenohd builds it with cargo, ~7.5 min)",
)
@pytest.mark.unit
def test_the_round_trip_goes_through_stock_zenohd_routers_too() -> None:
    got = rtt.measure("federated", samples=200, warmup=20, zenohd=True)
    assert got["n"] == 200 and 0 < got["p50"] < 2000, got


@pytest.mark.unit
def test_a_rung_says_why_it_failed() -> None:
    got = livebench.rung(_summary(4990, 61.0), 5000)
    missing = {"tl-rpf": 10, "rpf": 10, "source-rpf": 10}
    assert got == {"p99_ms": 61.0, "missing": missing, "stages_ms": None}
    assert livebench.rung({}, 5000) == {"p99_ms": None, "missing": None, "stages_ms": None}
