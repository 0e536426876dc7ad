"""A Stone Soup tracker as the primary of a running tltrack deployment: it reads its own
measurements and a live source's transfers over Zenoh, under the primary's identity with the ACL
on, and its TL-UKF gives the engine's TL-UKF of the same episode."""

from __future__ import annotations

import datetime
import threading
from pathlib import Path

import numpy as np
import pytest
from doubles import RADAR
from livestack import logs, sim_flags, stack
from security_helpers import session, start_router, start_service
from stonesoup.predictor.kalman import UnscentedKalmanPredictor
from stonesoup.types.array import CovarianceMatrix, StateVector
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import GaussianState
from stonesoup.updater.kalman import UnscentedKalmanUpdater
from tltrack.engine.montecarlo import trace_run
from tltrack.engine.scenario import initial_estimate
from tltrack.engine.setup import PRIMARY, Setup, sensor_spec
from tltrack.interop.stonesoup import (
    UKF_POINTS,
    Motion,
    Sensor,
    TransferReader,
    TransferWriter,
    stacked,
    timestamp,
)
from tltrack.live import supervisor
from tltrack.wire import keys
from tltrack.wire.messages import MAX_PAYLOAD_BYTES, EpisodeStart, Measurement, Transfer, encode
from tltrack.wire.transport import Subscriber

pytestmark = [pytest.mark.integration, pytest.mark.timeout(150)]

K = 30
CT = {"ndim_state": 5, "mapping": (0, 2), "velocity_mapping": (1, 3)}  # the episode's layout
#: the primary's step grid: step 0 at the epoch, a period of 1 s
GRID = (datetime.datetime(1970, 1, 1), datetime.timedelta(seconds=1.0))
#: a state of position only: no velocity for a Doppler sensor to read
POSITION = {"ndim_state": 2, "mapping": (0, 1)}


def test_a_stone_soup_tracker_takes_a_live_sources_transfers(tmp_path: Path) -> None:
    with stack(tmp_path) as s:
        start_router(s)  # the shipped ACL; every process under its operator's identity
        # a late measurement waits (no predict-through): the source stays the engine's
        src = {"TLTRACK_SOURCE_FILTER": "ukf", "TLTRACK_SOURCE_GAP_TIMEOUT_S": "30"}
        start_service(s, "source_tracker", env=src)
        with (
            session(s.endpoint, "primary") as z,
            Subscriber(z, [keys.EPISODES]) as episodes,
            Subscriber(z, [keys.PRIMARY_MEAS]) as meas,
            TransferReader(session=z, count=K - 1, idle_s=60.0, **CT) as reader,
        ):
            only_the_source = supervisor.sim_env(["source/s1:source_tracker"])
            start_service(s, "sensor_sim", *sim_flags(K, 100, pace=20), env=only_the_source)
            got = episodes.recv_message(EpisodeStart, timeout=90)
            assert got is not None, logs(s)
            start = got[1]
            cfg = start.parsed_config()
            setup = Setup(cfg)
            assert (setup.motion.layout.pos, setup.motion.layout.vel) == (
                CT["mapping"],
                CT["velocity_mapping"],
            )
            own = Sensor(spec=sensor_spec(cfg, PRIMARY), noise_covar=setup.sensors[PRIMARY].R, **CT)
            predictor = UnscentedKalmanPredictor(Motion(model=setup.motion), **UKF_POINTS)
            updater = UnscentedKalmanUpdater(None, **UKF_POINTS)
            T, t0 = datetime.timedelta(seconds=setup.motion.T), timestamp(0.0)
            x0 = initial_estimate(cfg, start.run)
            state = GaussianState(
                StateVector(x0), CovarianceMatrix(np.diag(cfg.P0_diag)), timestamp=t0
            )
            zs: dict[int, np.ndarray] = {}

            def z_at(k: int) -> Detection:
                while k not in zs:
                    m = meas.recv_message(Measurement, timeout=30)
                    assert m is not None, logs(s)
                    zs[m[1].k] = np.asarray(m[1].z[0])
                return Detection(StateVector(zs[k]), timestamp=t0 + k * T, measurement_model=own)

            def step(k: int, d: Detection) -> np.ndarray:
                nonlocal state
                state = updater.update(
                    SingleHypothesis(predictor.predict(state, timestamp=t0 + k * T), d)
                )
                return np.asarray(state.state_vector, dtype=float)[:, 0]

            track = [step(1, z_at(1))]  # step 1 has no transfer: the first is sent after it
            for _, (eta,) in reader:
                assert eta.k_apply == len(track) + 1 and eta.source == "s1"
                k = eta.k_apply
                track.append(step(k, stacked([z_at(k), eta], when=t0 + k * T)))
        assert len(track) == K, logs(s)
        assert reader.rejects.total == 0
    engine = trace_run(cfg, ["tl-ukf"], start.run)["tl-ukf"]
    np.testing.assert_allclose(np.array(track), engine, rtol=1e-6, atol=1e-6)


def test_the_reader_refuses_what_the_primary_refuses(tmp_path: Path) -> None:
    """A transfer on s1's key sent as s2, a payload that is no transfer, one over the size limit
    (dropped uncounted before), a Doppler one the reader's position-only state cannot express,
    the good one again and one for an earlier step (a second update, a prediction backwards)
    are counted and skipped; the good ones are read, dated at their steps, one stamped for the
    primary's own schedule (t_apply) too (it was refused: k_apply numbers the primary's samples
    on any clock). Closed, the reader ends at once (it spun on the closed subscriber)."""
    good = Transfer(
        episode="e", sender="s1", k=3, t_sensor=3.0, k_apply=4, sensor=RADAR,
        eta=[1000.0, 0.5], P_eta=[[25.0, 0.0], [0.0, 1e-4]],
    )  # fmt: skip
    doppler = Transfer.model_validate({
        **good.model_dump(), "sensor": {**RADAR, "kind": "range-bearing-doppler"},
        "eta": [1000.0, 0.5, 3.0], "P_eta": np.diag([25.0, 1e-4, 1.0]).tolist(),
    })  # fmt: skip
    with stack(tmp_path) as s:
        s.start_router()
        with (
            supervisor.client(s.endpoint) as z,
            TransferReader(session=z, count=2, idle_s=20.0, steps=GRID, **POSITION) as reader,
        ):
            key = keys.transfer("s1", "e")
            z.put(key, encode(good.model_copy(update={"sender": "s2"})))
            z.put(key, b"\x93not a transfer")
            z.put(key, b"\x00" * (MAX_PAYLOAD_BYTES + 1))
            z.put(key, encode(doppler))
            z.put(key, encode(good.model_copy(update={"k": 1, "t_apply": 4.0})))
            z.put(key, encode(good))
            z.put(key, encode(good.model_copy(update={"k": 1, "k_apply": 2})))
            z.put(key, encode(good.model_copy(update={"k": 4, "k_apply": 5})))
            got = [d for _, dets in reader for d in dets]
    assert [(d.source, d.k_apply, d.timestamp) for d in got] == [
        ("s1", 4, GRID[0] + 4 * GRID[1]),
        ("s1", 5, GRID[0] + 5 * GRID[1]),
    ]
    assert reader.rejects.count(key, "invalid") == 1
    assert reader.rejects.count(key, "wrong_sender") == 1
    assert reader.rejects.count(key, "too_large") == 1
    assert reader.rejects.count(key, "duplicate") == 1
    assert reader.rejects.count(key, "late_transfer") == 1
    assert reader.rejects.count(key) == 6
    reader.idle_s = None  # closed by the with: nothing will come, and it must not wait for it
    after: list[object] = []
    drain = threading.Thread(target=lambda: after.extend(reader), daemon=True)
    drain.start()
    drain.join(5.0)
    assert not drain.is_alive() and after == []


def test_a_stone_soup_source_writes_under_its_identity(tmp_path: Path) -> None:
    """TransferWriter on source s1's session reaches the primary's reader through the ACL; the
    same writer on source s2's session, speaking for s1, is stopped by the router."""
    sensor = Sensor(spec=RADAR, **CT)
    ahead = GaussianState(StateVector([1000.0, 5.0, 800.0, -2.0, 0.0]), np.eye(5) * 25.0)
    with stack(tmp_path) as s:
        start_router(s)
        with (
            session(s.endpoint, "primary") as z,
            session(s.endpoint, "source-s1") as s1,
            session(s.endpoint, "source-s2") as s2,
            TransferReader(session=z, count=2, idle_s=3.0, **CT) as reader,
        ):
            with TransferWriter(s2, source="s1", episode="e") as forger:
                forger.write(ahead, sensor, k=1, t_sensor=1.0)
            with TransferWriter(s1, source="s1", episode="e") as writer:
                sent = writer.write(ahead, sensor, k=2, t_sensor=2.0)
            got = [d for _, dets in reader for d in dets]  # stops 3 s after the last
    assert [(d.source, d.k_apply) for d in got] == [("s1", 3)]
    np.testing.assert_array_equal(np.asarray(got[0].state_vector, dtype=float)[:, 0], sent.eta)
    assert reader.rejects.total == 0
