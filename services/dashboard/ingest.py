"""From Zenoh samples to the dashboard's state and metrics: parse the key, validate, record.

Like every service, a bad payload is counted under its key and reason and skipped, never raised.
"""

from __future__ import annotations

import logging

from tltrack.services.dashboard.metrics import Metrics
from tltrack.services.dashboard.state import Role, State
from tltrack.wire import keys
from tltrack.wire.messages import (
    EpisodeEnd,
    EpisodeStart,
    EstimateMsg,
    RejectCounter,
    Truth,
    decode_stats,
)
from tltrack.wire.transport import Received, decode_received

log = logging.getLogger("dashboard")


def pattern(info: keys.KeyInfo, key: str) -> str:
    """The key with its episode id as ``*``: a bounded label for counts per key."""
    if info.episode is None:
        return key
    return key[: -len(info.episode)] + keys.ANY


class Ingest:
    def __init__(self, state: State, metrics: Metrics, rejects: RejectCounter) -> None:
        self.state, self.metrics, self.rejects = state, metrics, rejects

    def handle(self, item: Received) -> None:
        try:
            info = keys.parse(item.key)
        except ValueError:
            self.rejects.add(item.key, "bad_key")
            return
        label = pattern(info, item.key)
        self.metrics.received.labels(label).inc()
        self.state.on_received(label)
        if info.kind == "alive" and info.operator and info.service:
            self.state.on_liveliness(info.operator, info.service, item.is_put)
        elif info.kind == "episode":
            msg = decode_received(item, (EpisodeStart, EpisodeEnd), self.rejects)
            if isinstance(msg, EpisodeStart):
                self.state.on_start(msg)
            elif isinstance(msg, EpisodeEnd):
                self.state.on_end(msg)
        elif info.kind == "truth":
            self._on_truth(item)
        elif info.kind == "source_estimate":
            self._on_estimate(item, "source")
        elif info.kind == "primary_estimate" and info.role in ("tl", "isolated"):
            self._on_estimate(item, "tl" if info.role == "tl" else "isolated")
        elif info.kind == "stats" and info.operator and info.service:
            self._on_stats(item, info.operator, info.service)

    def _on_truth(self, item: Received) -> None:
        truth = decode_received(item, Truth, self.rejects)
        if truth is None:
            return
        verdict, updates = self.state.on_truth(truth)
        if verdict != "new":
            self.rejects.add(item.key, verdict)
        for u in updates:
            self.metrics.on_error(u)

    def _on_estimate(self, item: Received, role: Role) -> None:
        est = decode_received(item, EstimateMsg, self.rejects)
        if est is None:
            return
        verdict, update = self.state.on_estimate(role, est, item.t_recv)
        if verdict != "new":
            self.rejects.add(item.key, verdict)
            return
        m, name = self.metrics, est.filter
        m.latency.labels(name).observe(max(0.0, item.t_recv - est.t_sensor))
        m.step_time.labels(name).observe(est.step_ms / 1e3)
        m.step_k.labels(name).set(est.k)
        if role == "tl":
            m.transfer.labels(name, "true" if est.transfer_used else "false").inc()
        if est.nis_window is not None:
            m.nis.labels(name).set(est.nis_window)
        if (share := self.state.nis_above_band(est.episode, name)) is not None:
            m.nis_above.labels(name).set(share)
        if update is not None:
            m.on_error(update)

    def _on_stats(self, item: Received, operator: str, service: str) -> None:
        try:
            if not item.is_put:
                raise ValueError("not a put")
            raw = decode_stats(item.payload)
        except ValueError:
            self.rejects.add(item.key, "bad_stats")
            return
        self.state.on_stats(operator, service, raw)
