"""An estimate's end-to-end latency, stage by stage, so that a user can see where the time goes.

Every estimate carries the sensor's timestamp ``t_sensor``, when its tracker received z_k
(``t_received``), when the step began (``t_step``), the step's duration (``step_ms``) and when it
was published (``t_sent``); its receiver adds its own arrival time ``t_recv``.

``t_sensor`` is when the sensor published z_k. A federated sensor measures when sensor_sim's
clock ticks, but that tick's hop to the sensor is the simulation's world clock, not a stage of
the product (a real sensor is its own clock), so it is not counted. The stages (ms):

- ``to_tracker``: the sensor's publication to the tracker's receipt of z_k (a routed hop);
- ``wait``: receipt to the step's start (the queue, and a primary's wait for the transfer);
- ``step``: the filter's step (the primary's isolated twin steps after the TL estimate is out,
  so its ``wait`` holds the TL step and the twin's delay);
- ``publish``: the step's end to the estimate's publication;
- ``to_receiver``: publication to arrival at the scorer or the dashboard (a routed hop).

They add up to ``t_recv - t_sensor``. Across hosts the hops need synchronised clocks.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from tltrack.wire.messages import EstimateMsg

#: the stages of an estimate's latency, in order (the module's docstring says what each covers)
STAGES = ("to_tracker", "wait", "step", "publish", "to_receiver")


def end_to_end_ms(t_sensor: float, t_recv: float) -> float:
    """An estimate's latency as the scorer reports it: from the sensor's publication of z_k to
    the estimate's arrival at the scorer (the sum of the :data:`STAGES`), in ms."""
    return (t_recv - t_sensor) * 1e3


def stages(
    t_sensor: float, t_received: float, t_step: float, step_ms: float, t_sent: float, t_recv: float
) -> tuple[float, float, float, float, float]:
    """One estimate's latency in :data:`STAGES` order, in ms."""
    to_tracker = (t_received - t_sensor) * 1e3
    wait = (t_step - t_received) * 1e3
    publish = (t_sent - t_step) * 1e3 - step_ms
    return to_tracker, wait, step_ms, publish, (t_recv - t_sent) * 1e3


def of(m: EstimateMsg, t_recv: float) -> tuple[float, float, float, float, float] | None:
    """The stages of estimate ``m`` received at ``t_recv``; None if its tracker did not say."""
    if m.t_received is None or m.t_step is None:
        return None
    return stages(m.t_sensor, m.t_received, m.t_step, m.step_ms, m.t_sent, t_recv)


def p50(rows: Sequence[tuple[float, ...]] | NDArray[np.float64]) -> dict[str, float | None]:
    """Each stage's median over ``rows`` of :func:`stages` (or an array of them, one per row)."""
    if len(rows) == 0:
        return {s: None for s in STAGES}
    return dict(zip(STAGES, (float(v) for v in np.median(np.array(rows), axis=0)), strict=True))


def percentiles(ms: Sequence[float] | NDArray[np.float64]) -> dict[str, float | None]:
    """p50, p95 and p99 of latencies ``ms`` (None each when there are none): what the scorer's
    summary and the dashboard report."""
    if len(ms) == 0:
        return {"p50": None, "p95": None, "p99": None}
    p = np.percentile(ms, [50, 95, 99])
    return {"p50": float(p[0]), "p95": float(p[1]), "p99": float(p[2])}
