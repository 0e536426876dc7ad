"""Prometheus metrics: what the dashboard sees itself, and the services' own counters.

The dashboard's own observations (messages received, RMSE, latency, transfer use) are ordinary
counters, gauges and histograms updated as messages arrive. The other services' counters
(rejected messages per key and reason, events, dropped samples) live in their processes and reach
the dashboard in their statistics, so a collector mirrors the latest values at scrape time; a
restarted service's counters start again from zero, which Prometheus reads as a counter reset.

Labels stay bounded: a key is the subscription pattern with the episode id as ``*``, a filter is
one of at most ``max_filters`` names per episode, and the mirrored maps are capped in ``state``.
"""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client import (
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    disable_created_metrics,
)
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector
from tltrack.services.dashboard.state import ErrorUpdate, State

#: end-to-end latency on one host is milliseconds; seconds means a stalled service
LATENCY_BUCKETS = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0)
STEP_BUCKETS = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0)


class Metrics:
    """One registry per dashboard (not the global one), so tests can build several."""

    def __init__(self, state: State) -> None:
        disable_created_metrics()  # no *_created series: they double the output for nothing
        self.registry = CollectorRegistry()
        r = self.registry
        self.received = Counter(
            "tltrack_messages_received",
            "Messages received by the dashboard, per key pattern (episode id as *)",
            ["key"],
            registry=r,
        )
        self.rmse = Gauge(
            "tltrack_rmse_meters",
            "Position RMSE of the latest episode so far (mean over k of "
            "RMSE(k), as the scorer computes it)",
            ["filter"],
            registry=r,
        )
        self.rmse_k = Gauge(
            "tltrack_rmse_step_meters",
            "RMSE(k) at the latest step k scored",
            ["filter"],
            registry=r,
        )
        self.step_k = Gauge(
            "tltrack_estimate_step", "Latest step k received", ["filter"], registry=r
        )
        self.latency = Histogram(
            "tltrack_latency_seconds",
            "End-to-end latency: sensor timestamp to the estimate's arrival at the dashboard",
            ["filter"],
            buckets=LATENCY_BUCKETS,
            registry=r,
        )
        self.step_time = Histogram(
            "tltrack_filter_step_seconds",
            "Time a filter took for one step, as it reports it",
            ["filter"],
            buckets=STEP_BUCKETS,
            registry=r,
        )
        self.nis = Gauge(
            "tltrack_nis_window",
            "Mean NIS of the filter's own measurements over its last 20 steps (n_z when its "
            "model fits)",
            ["filter"],
            registry=r,
        )
        self.nis_above = Gauge(
            "tltrack_nis_above_band_ratio",
            "Share of the episode's steps whose windowed NIS was above its 99% band (0.5 and "
            "more: the motion model's noise is too low for the target)",
            ["filter"],
            registry=r,
        )
        self.transfer = Counter(
            "tltrack_transfer_steps",
            "Steps of a transfer-learning filter, by whether a transfer was used",
            ["filter", "used"],
            registry=r,
        )
        r.register(ServiceCollector(state))

    def on_error(self, u: ErrorUpdate) -> None:
        self.rmse.labels(u.filter).set(u.rmse)
        self.rmse_k.labels(u.filter).set(u.error)


class ServiceCollector(Collector):
    """Mirrors every service's liveliness and the counters of its latest statistics."""

    def __init__(self, state: State) -> None:
        self.state = state

    def collect(self) -> Iterator[Metric]:
        rejected = CounterMetricFamily(
            "tltrack_messages_rejected",
            "Messages a service rejected, per key",
            labels=["service", "key"],
        )
        reasons = CounterMetricFamily(
            "tltrack_messages_rejected_by_reason",
            "Messages a service rejected, per reason",
            labels=["service", "reason"],
        )
        events = CounterMetricFamily(
            "tltrack_service_events",
            "A service's own counters (steps, steps_with_transfer...)",
            labels=["service", "event"],
        )
        dropped = CounterMetricFamily(
            "tltrack_service_dropped", "Samples a service's full inbox dropped", labels=["service"]
        )
        up = GaugeMetricFamily(
            "tltrack_service_up",
            "1 while the service's liveliness token is alive",
            labels=["service"],
        )
        links = GaugeMetricFamily(
            "tltrack_source_link_up",
            "1 while a source's heartbeat reaches the service over the direct link, 0 once cut",
            labels=["service", "source"],
        )
        for h in self.state.services():
            up.add_metric([h.name], 1.0 if h.alive else 0.0)
            s = h.stats
            if not s:
                continue
            for key, n in s["rejected_by_key"].items():
                rejected.add_metric([h.name, key], n)
            for reason, n in s["rejected_by_reason"].items():
                reasons.add_metric([h.name, reason], n)
            for event, n in s["counters"].items():
                events.add_metric([h.name, event], n)
            dropped.add_metric([h.name], s["dropped"])
            for sid, state in s.get("links", {}).items():
                links.add_metric([h.name, sid], 1.0 if state == "up" else 0.0)
        yield from (rejected, reasons, events, dropped, up, links)

    def describe(self) -> Iterator[Metric]:
        return iter(())  # names vary with the services seen; nothing to check at registration
