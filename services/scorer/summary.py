"""RMSE, latency, transfer use, gaps and rejected messages, computed from the store alone.

RMSE follows the paper: RMSE(k) = sqrt(mean over episodes of the squared position error at k),
overall = mean over k. Latency is end to end: sensor timestamp to the estimate's arrival here
(meaningful on one host; across hosts it needs synchronised clocks). ``stages_ms`` splits it into
the p50 of each stage of :mod:`tltrack.latency`.
"""

from __future__ import annotations

import json
from collections import defaultdict
from typing import Any

import numpy as np
from tltrack import latency
from tltrack.services.scorer.store import Store


def _percentiles(ms: list[float]) -> dict[str, float | None]:
    if not ms:
        return {"p50": None, "p95": None, "p99": None}
    p = np.percentile(ms, [50, 95, 99])
    return {"p50": float(p[0]), "p95": float(p[1]), "p99": float(p[2])}


def summarize(store: Store, episodes: list[str] | None = None) -> dict[str, Any]:
    """The summary over ``episodes`` (default: all in the store)."""
    eps = store.rows("SELECT episode, run, K, ended, end_reason FROM episodes ORDER BY started")
    if episodes is not None:
        eps = [e for e in eps if e[0] in episodes]
    names = [e[0] for e in eps]
    K_of = {e[0]: e[2] for e in eps}
    truth = {
        (ep, k): np.array(json.loads(pos))
        for ep, k, pos in store.rows("SELECT episode, k, pos FROM truth WHERE pos IS NOT NULL")
    }
    sq: dict[str, dict[int, list[float]]] = defaultdict(lambda: defaultdict(list))
    end_to_end: dict[str, list[float]] = defaultdict(list)
    split: dict[str, list[tuple[float, ...]]] = defaultdict(list)
    used: dict[str, int] = defaultdict(int)
    recoveries: dict[str, int] = defaultdict(int)
    seen: dict[str, set[tuple[str, int]]] = defaultdict(set)
    for (
        ep,
        name,
        k,
        pos,
        tu,
        rec,
        t_sensor,
        t_recv,
        t_sent,
        step_ms,
        t_received,
        t_step,
    ) in store.rows(
        "SELECT episode, filter, k, pos, transfer_used, recovered, t_sensor, t_recv, t_sent,"
        " step_ms, t_received, t_step FROM estimates"
    ):
        if ep not in K_of:
            continue
        seen[name].add((ep, k))
        end_to_end[name].append((t_recv - t_sensor) * 1e3)
        if t_received is not None and t_step is not None:
            split[name].append(
                latency.stages(t_sensor, t_received, t_step, step_ms, t_sent, t_recv)
            )
        used[name] += tu
        recoveries[name] += rec or 0
        if (ep, k) in truth and pos is not None:
            d = np.array(json.loads(pos)) - truth[ep, k]
            sq[name][k].append(float(d[0] ** 2 + d[1] ** 2))
    filters = {}
    for name in sorted(seen):
        steps = sorted(sq[name])
        per_step = [float(np.sqrt(np.mean(sq[name][k]))) for k in steps]
        expected = sum(K_of[e] for e in names)
        filters[name] = {
            "rmse_overall": float(np.mean(per_step)) if per_step else None,
            "rmse_per_step": per_step,
            "steps": len(seen[name]),
            "gaps": expected - len(seen[name]),
            "steps_with_transfer": used[name],
            "recoveries": recoveries[name],
            "latency_ms": _percentiles(end_to_end[name]),
            "stages_ms": latency.p50(split[name]),
        }
    everything = [v for lst in end_to_end.values() for v in lst]
    rejected: dict[str, dict[str, int]] = {}
    dropped = 0
    for operator, service, _t, stats in store.rows("SELECT * FROM service_stats"):
        s = json.loads(stats)
        rejected[f"{operator}/{service}"] = s.get("rejected", {}).get("by_reason", {})
        dropped += int(s.get("dropped", 0))
    return {
        "episodes": [
            {"episode": e, "run": r, "K": K, "complete": reason == "complete"}
            for e, r, K, _ended, reason in eps
        ],
        "filters": filters,
        "latency_ms": _percentiles(everything),
        "stages_ms": latency.p50([v for rows in split.values() for v in rows]),
        "messages": {
            "rejected": rejected,
            "rejected_total": sum(sum(v.values()) for v in rejected.values()),
            "dropped": dropped,
            "missing_estimates": sum(f["gaps"] for f in filters.values()),
        },
    }
