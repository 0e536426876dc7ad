"""An operator's sensor (services/sensor) driven in-process: zenoh orders samples per key, not
across keys, so a tick may come before its episode's start, and the episode's end before its
last ticks. Every tick must still be measured, once."""

from __future__ import annotations

import time

import numpy as np
import pytest
from doubles import Offline, episode_end, episode_start, received
from livestack import SIM_DEFAULTS
from tltrack.config import make_config
from tltrack.engine.scenario import measurements, truth
from tltrack.engine.setup import Setup
from tltrack.services.sensor import sensor as sensor_svc
from tltrack.wire import keys
from tltrack.wire.messages import Measurement, Tick, encode

pytestmark = pytest.mark.unit

E, K = "ep-r0", 6


def _tick(k: int) -> bytes:
    return encode(Tick(episode=E, sender="sensor_sim", k=k, t_sensor=time.time()))


ORDERS = {
    "in order": ["start", *range(1, K + 1), "end"],
    "ticks before the start": [1, 2, "start", *range(3, K + 1), "end"],
    "the end before the last ticks": ["start", 1, 2, "end", *range(3, K + 1)],
}


@pytest.mark.parametrize("order", list(ORDERS))
def test_every_tick_is_measured_once_whatever_the_order_across_keys(order: str) -> None:
    svc = Offline(sensor_svc.NAME)
    sensor = sensor_svc.Sensor(sensor_svc.Settings.model_validate({}), svc)
    for what in ORDERS[order]:
        if what == "start":
            sensor.handle(received(keys.episode(E), episode_start(E, K)))
        elif what == "end":
            sensor.handle(received(keys.episode(E), episode_end(E, K)))
        else:
            sensor.handle(received(keys.clock(E), _tick(int(what))))
    assert svc.rejects.total == 0
    sent = [msg for key, msg in svc.published if key == keys.primary_meas(E)]
    assert all(isinstance(m, Measurement) for m in sent)
    assert [m.k for m in sent] == list(range(1, K + 1))
    cfg = make_config(**SIM_DEFAULTS, K=K, particles=50)
    want = measurements(Setup(cfg), 0, truth(Setup(cfg), 0), "primary")
    np.testing.assert_array_equal(np.array([m.z for m in sent]), want[:, None, :])  # one each
    # an end that came early lets the episode go with its last tick (one that comes last
    # leaves it to the bound of max_episodes)
    if order == "the end before the last ticks":
        assert sensor.episodes.get(E) is None
