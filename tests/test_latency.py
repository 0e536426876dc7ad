"""The latency's stages (tltrack.live.latency): they add up to the end-to-end latency, and an
estimate whose tracker did not time its stages has none."""

from __future__ import annotations

import pytest
from tltrack.live import latency
from tltrack.wire.messages import EstimateMsg

pytestmark = pytest.mark.unit

T0 = 1_700_000_000.0
P = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


def estimate(**times: float | None) -> EstimateMsg:
    return EstimateMsg(
        episode="e",
        sender="primary",
        k=3,
        filter="tl-rpf",
        x=[0.0, 1.0, 0.0, 1.0],
        pos=[0.0, 0.0],
        P=P,
        transfer_used=True,
        step_ms=0.3,
        **{"t_sensor": T0, "t_sent": T0 + 0.0012, **times},
    )


def test_the_stages_add_up_to_the_end_to_end_latency() -> None:
    m = estimate(t_received=T0 + 0.0002, t_step=T0 + 0.0005)
    split = latency.of(m, t_recv=T0 + 0.0015)
    assert split is not None
    assert dict(zip(latency.STAGES, split, strict=True)) == pytest.approx(
        {"to_tracker": 0.2, "wait": 0.3, "step": 0.3, "publish": 0.4, "to_receiver": 0.3},
        abs=1e-3,  # epoch seconds in a double resolve about 0.2 us
    )
    assert sum(split) == pytest.approx(1.5, abs=1e-3)  # t_recv - t_sensor, in ms


def test_an_estimate_without_its_trackers_times_has_no_stages() -> None:
    assert latency.of(estimate(), t_recv=T0 + 0.002) is None
    assert latency.of(estimate(t_received=T0), t_recv=T0 + 0.002) is None
    assert latency.p50([]) == dict.fromkeys(latency.STAGES)


def test_each_stages_p50_is_over_its_own_column() -> None:
    rows = [(1.0, 0.0, 0.3, 0.1, 1.0), (3.0, 2.0, 0.5, 0.1, 2.0), (2.0, 1.0, 0.4, 0.1, 9.0)]
    assert latency.p50(rows) == pytest.approx(
        {"to_tracker": 2.0, "wait": 1.0, "step": 0.4, "publish": 0.1, "to_receiver": 2.0}
    )


def test_the_times_are_validated_at_the_boundary() -> None:
    with pytest.raises(ValueError, match="t_step"):
        estimate(t_received=T0, t_step=float("nan"))
    with pytest.raises(ValueError, match="t_received"):
        estimate(t_received=-1.0, t_step=T0)


def test_when_a_message_arrived_is_not_part_of_it() -> None:
    """The transport stamps each decoded message with its arrival time; two copies of one
    message, received at different times, are still equal (and the stamp is never sent)."""
    a, b = estimate().received(T0 + 1.0), estimate().received(T0 + 2.0)
    assert (a.received_at, b.received_at) == (T0 + 1.0, T0 + 2.0)
    assert a == b and a != estimate(t_received=T0)
    assert "received_at" not in a.model_dump()
