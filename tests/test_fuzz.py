"""Bad input at every boundary: every key a service subscribes to, flooded with malformed payloads
beside the genuine stream of a lock-step episode.

The payloads come from one generator of malformations (:func:`malformed`), driven by a seeded
``random.Random`` for the live flood and by hypothesis for the handlers in-process, where
failures shrink. A payload is kept only if :func:`tltrack.wire.messages.decode` refuses it, so every
one must be counted exactly once by every service that receives it; messages that decode but
name a past, far-future or already-seen step are added live, where the trackers' step windows
refuse them.
"""

from __future__ import annotations

import contextlib
import json
import math
import random
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
import zenoh
from doubles import RADAR, Offline, received
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from livestack import SIM_DEFAULTS, estimates, logs, stack
from security_helpers import (
    FUZZER,
    fuzz_access,
    rss_kb,
    session,
    start_router,
    start_sensor,
    start_trackers_and_scorer,
    summary,
    wait_alive,
    wait_for_scored,
)
from tltrack.config import make_config
from tltrack.engine.montecarlo import trace_run
from tltrack.services.primary_tracker import tracker as primary_svc
from tltrack.services.scorer import scorer as scorer_svc
from tltrack.services.scorer.store import Store
from tltrack.services.source_tracker import tracker as source_svc
from tltrack.wire import keys
from tltrack.wire.messages import (
    MAX_K,
    MAX_PAYLOAD_BYTES,
    EpisodeEnd,
    EpisodeStart,
    EstimateMsg,
    Measurement,
    Message,
    MessageRejected,
    Transfer,
    Truth,
    decode,
    encode,
)
from tltrack.wire.transport import Subscriber

E = "ep-r0"
T0 = 1.7e9  #: in the past: a stamp from the future is refused as such (from_the_future)
SPD2 = [[4.0, 0.01], [0.01, 1e-4]]
SPD4 = np.diag([25.0, 4.0, 25.0, 4.0]).tolist()


# ---- the generator of malformed payloads ------------------------------------------------------


def _template(kind: str) -> Message:
    common: dict[str, Any] = {"episode": E, "t_sensor": T0, "k": 5}
    if kind == "episode":
        cfg = make_config(**SIM_DEFAULTS, K=10, particles=50).model_dump(mode="json")
        return EpisodeStart(
            **common | {"k": 0}, sender="sensor_sim", run=0, config=cfg, K=10, steps_per_sec=0.0
        )
    if kind == "measurement":
        return Measurement(**common, sender="sensor_sim", sensor="primary", z=[[1500.0, 0.7]])
    if kind == "transfer":
        return Transfer(
            **common, sender="s1", k_apply=6, sensor=RADAR, eta=[1500.0, 0.7], P_eta=SPD2
        )
    if kind == "truth":
        return Truth(**common, sender="sensor_sim", x=[1.0, 2.0, 3.0, 4.0], pos=[1.0, 3.0])
    return EstimateMsg(
        **common,
        sender="primary",
        filter="tl-pf",
        x=[1.0, 2.0, 3.0, 4.0],
        pos=[1.0, 3.0],
        P=SPD4,
        transfer_used=True,
        t_sent=T0,
        step_ms=1.0,
    )


EXPECTED: dict[str, Any] = {
    "episode": (EpisodeStart, EpisodeEnd),
    "measurement": Measurement,
    "transfer": Transfer,
    "truth": Truth,
    "estimate": EstimateMsg,
}
KINDS = [*EXPECTED, "stats"]
TEMPLATES = {kind: _template(kind).model_dump(mode="python") for kind in EXPECTED}

WRONG_VALUES: list[Any] = [
    "x",
    "",
    1.5,
    -1,
    2**63 - 1,
    True,
    None,
    [],
    {},
    {"a": 1},
    [[1.0]],
    b"\x00",
    math.nan,
]
BAD_IDS = ["", "a/b", "x" * 65, "é", "*", "$x", "tltrack/**", " "]
NON_FINITE = [math.nan, math.inf, -math.inf]
#: finite, and beyond anything a sensor measures (tltrack.models.components)
ABSURD = [1e300, -1e300]


def _pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def _numeric_paths(d: dict[str, Any]) -> list[tuple[str, ...]]:
    paths: list[tuple[str, ...]] = []
    for key, v in d.items():
        if isinstance(v, float):
            paths.append((key,))
        elif isinstance(v, list):
            for i, item in enumerate(v):
                if isinstance(item, list):
                    paths += [(key, str(i), str(j)) for j in range(len(item))]
                else:
                    paths.append((key, str(i)))
    return paths


def _set(d: dict[str, Any], path: tuple[str, ...], value: Any) -> None:
    target: Any = d
    for p in path[:-1]:
        target = target[p] if isinstance(target, dict) else target[int(p)]
    if isinstance(target, dict):
        target[path[-1]] = value
    else:
        target[int(path[-1])] = value


def _structured(rnd: random.Random, kind: str) -> bytes:
    """A template with one field broken: version, tag, type, shape, NaN/Inf or an absurd value,
    covariance, ids, a field missing or extra."""
    d = json.loads(json.dumps(TEMPLATES[kind]))  # deep copy
    field = rnd.choice(sorted(d))
    how = rnd.randrange(9)
    if how == 0:
        d["schema_version"] = rnd.choice([0, 1, 99, -1, "2", 2.0, None, True, [2]])
    elif how == 1:
        d["type"] = rnd.choice(
            ["measurement", "transfer", "truth", "estimate", "episode_end", "", None, 7]
        )
    elif how == 2:
        d[field] = rnd.choice(WRONG_VALUES)
    elif how == 3:
        vectors = [f for f in ("z", "x", "eta", "P", "P_eta") if f in d]
        f = rnd.choice(vectors or [field])
        d[f] = rnd.choice(
            [
                [],
                [1.0],
                [1.0] * 3,
                [1.0] * 7,
                [[1.0, 0.0]],
                [[1.0], [0.0, 1.0]],
                [[1.0] * 3] * 3,
                [1.0] * 300,
            ]
        )
    elif how == 4 and (paths := _numeric_paths(d)):
        _set(d, rnd.choice(paths), rnd.choice(NON_FINITE + ABSURD))
    elif how == 5 and ("P" in d or "P_eta" in d):
        f = "P" if "P" in d else "P_eta"
        n = len(d[f])
        m = np.eye(n)
        choice = rnd.randrange(4)
        if choice == 0:
            m[0, n - 1] = 0.5  # not symmetric
        elif choice == 1:
            m[0, 0] = -1.0  # not positive-definite
        elif choice == 2:
            m = np.ones((n, n))  # singular
        else:
            m = np.zeros((n, n))
        d[f] = m.tolist()
    elif how == 6:
        d[rnd.choice(["episode", "sender"])] = rnd.choice(BAD_IDS)
    elif how == 7:
        del d[field]
    else:
        d[rnd.choice(["extra", "K", "zz", "__class__"])] = 1
    return _pack(d)


def _bytes_level(rnd: random.Random, kind: str) -> bytes:
    """Random bytes, truncated or bit-flipped msgpack, not a map, msgpack bombs, ext types."""
    good = _pack(TEMPLATES[kind]) if kind != "stats" else json.dumps({"a": 1}).encode()
    how = rnd.randrange(6)
    if how == 0:
        return rnd.randbytes(rnd.randrange(0, 300))
    if how == 1:
        return good[: rnd.randrange(1, len(good))]
    if how == 2:
        b = bytearray(good)
        for _ in range(rnd.randrange(1, 8)):
            b[rnd.randrange(len(b))] ^= 1 << rnd.randrange(8)
        return bytes(b)
    if how == 3:
        return _pack(rnd.choice([[1, 2], 3, "measurement", None, 1.5, True, [TEMPLATES.get(kind)]]))
    if how == 4:  # headers announcing 4 G entries, nesting 100 000 deep (msgpack, or JSON)
        return rnd.choice(
            [
                b"\xdd\xff\xff\xff\xff",
                b"\xdf\xff\xff\xff\xff",
                b"\xdb\xff\xff\xff\xff",
                b"\x91" * 100_000 + b"\x00",
                b"\x81\xa1a" * 5000 + b"\x00",
                b"[" * 100_000,
            ]
        )
    return _pack({**TEMPLATES.get(kind, {}), "x": msgpack.ExtType(5, b"ext")})


def _oversized(rnd: random.Random, kind: str) -> bytes:
    """Just over the limit up to 4x it: refused before unpacking."""
    size = rnd.randrange(MAX_PAYLOAD_BYTES + 1, 4 * MAX_PAYLOAD_BYTES)
    if kind == "stats":
        return json.dumps({"pad": "x" * size}).encode()
    return _pack({**TEMPLATES[kind], "pad": "x" * size})


def _rejected(payload: bytes, kind: str) -> bool:
    """Whether the service receiving ``payload`` on a ``kind`` key must refuse it."""
    if kind == "stats":  # the scorer keeps any JSON object up to the size limit
        try:
            return len(payload) > MAX_PAYLOAD_BYTES or not isinstance(json.loads(payload), dict)
        except (ValueError, RecursionError):
            return True
    try:
        decode(payload, EXPECTED[kind])
    except MessageRejected:
        return True
    return False


def malformed(rnd: random.Random, kind: str) -> bytes:
    """One payload that a service subscribed to a ``kind`` key must reject."""
    while True:
        r = rnd.random()
        if kind == "stats":
            payload = _oversized(rnd, kind) if r < 0.05 else _bytes_level(rnd, kind)
        elif r < 0.03:
            payload = _oversized(rnd, kind)
        elif r < 0.35:
            payload = _bytes_level(rnd, kind)
        else:
            payload = _structured(rnd, kind)
        if _rejected(payload, kind):
            return payload


# ---- the handlers in-process, driven by hypothesis --------------------------------------------


KIND_KEYS = {
    "episode": [keys.episode(E)],
    "measurement": [keys.primary_meas(E), keys.source_meas("s1", E)],
    "transfer": [keys.transfer("s1", E), keys.transfer("s9", E)],
    "truth": [keys.truth(E)],
    "estimate": [keys.primary_estimate("tl", E), keys.source_estimate("s1", E)],
    "stats": [keys.stats("primary", "primary_tracker"), keys.stats("referee", "evil")],
}


def _handlers(tmp: Path) -> dict[str, tuple[Any, Offline]]:
    """The three subscribing services' handlers, each in the middle of episode E."""
    start = received(keys.episode(E), encode(_template("episode")))
    out: dict[str, tuple[Any, Offline]] = {}
    for name, make in (
        (
            "primary_tracker",
            lambda svc: primary_svc.PrimaryTracker(primary_svc.Settings.model_validate({}), svc),
        ),
        (
            "source_tracker",
            lambda svc: source_svc.SourceTracker(source_svc.Settings.model_validate({}), svc),
        ),
        (
            "scorer",
            lambda svc: scorer_svc.Scorer(
                scorer_svc.Settings.model_validate({}), svc, Store(tmp / "scorer.sqlite")
            ),
        ),
    ):
        svc = Offline(name)
        handler = make(svc)
        handler.handle(start)
        out[name] = (handler, svc)
    return out


SUBSCRIBES: dict[str, set[str]] = {
    "primary_tracker": {
        keys.episode(E),
        keys.primary_meas(E),
        keys.transfer("s1", E),
        keys.transfer("s9", E),
    },
    "source_tracker": {keys.episode(E), keys.source_meas("s1", E)},
    "scorer": {
        keys.episode(E),
        keys.truth(E),
        keys.primary_estimate("tl", E),
        keys.source_estimate("s1", E),
        *KIND_KEYS["stats"],
    },
}


@pytest.fixture(scope="module")
def handlers(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Any, Offline]]:
    return _handlers(tmp_path_factory.mktemp("handlers"))


@settings(
    max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(kind=st.sampled_from(KINDS), rnd=st.randoms(use_true_random=False), data=st.data())
@pytest.mark.unit
def test_each_handler_counts_every_malformed_payload_once(
    handlers: dict[str, tuple[Any, Offline]], kind: str, rnd: random.Random, data: st.DataObject
) -> None:
    """The service code behind every subscription: no exception, one rejection, no effect."""
    payload = malformed(rnd, kind)
    key = data.draw(st.sampled_from(KIND_KEYS[kind]))
    for name, (handler, svc) in handlers.items():
        if key not in SUBSCRIBES[name]:
            continue
        before, published = svc.rejects.total, len(svc.published)
        handler.handle(received(key, payload))
        assert svc.rejects.total == before + 1, (name, key, payload[:80])
        assert len(svc.published) == published


# Gaps this file found in the services, now closed: each test pins its fix.


@pytest.mark.unit
def test_the_scorer_counts_statistics_nested_too_deeply(
    handlers: dict[str, tuple[Any, Offline]],
) -> None:
    """JSON nested 100 000 deep makes json.loads recurse out of the stack: a RecursionError,
    which the scorer let through its loop (the dashboard caught it)."""
    scorer, svc = handlers["scorer"]
    before = svc.rejects.total
    scorer.handle(received(keys.stats("primary", "primary_tracker"), b"[" * 100_000))
    assert svc.rejects.total == before + 1


@pytest.mark.unit
def test_a_replayed_episode_start_is_counted_as_a_duplicate(tmp_path: Path) -> None:
    start = received(keys.episode(E), encode(_template("episode")))
    for name, (handler, svc) in _handlers(tmp_path).items():
        handler.handle(start)
        assert svc.rejects.count(reason="duplicate") == 1, name


@pytest.mark.unit
def test_a_sample_held_for_its_episode_is_checked_first(tmp_path: Path) -> None:
    """Held unread, 64 samples of 4 unknown episodes may be anything up to zenoh's 1 GiB limit
    (measured: 20 x 50 MB kept 1 GB in the primary); refused at once, they cost nothing."""
    handlers = _handlers(tmp_path)
    for name, key in (
        ("primary_tracker", keys.primary_meas("ep-later")),
        ("source_tracker", keys.source_meas("s1", "ep-later")),
    ):
        handler, svc = handlers[name]
        handler.handle(received(key, b"\x00" * (MAX_PAYLOAD_BYTES + 1)))
        handler.handle(received(key, b"\xc1 not msgpack"))
        assert svc.rejects.count(reason="too_large") == 1, name
        assert svc.rejects.count(reason="not_msgpack") == 1, name


@pytest.mark.unit
def test_the_scorer_refuses_replays_steps_beyond_k_wrong_keys_and_senders(tmp_path: Path) -> None:
    scorer, svc = _handlers(tmp_path)["scorer"]
    truth, est = _template("truth"), _template("estimate")
    for msg, key in ((truth, keys.truth(E)), (est, keys.primary_estimate("tl", E))):
        scorer.handle(received(key, encode(msg)))  # kept
        scorer.handle(received(key, encode(msg)))  # a replay
    scorer.handle(
        received(keys.primary_estimate("tl", E), encode(est.model_copy(update={"k": 10**6})))
    )  # K is 10
    scorer.handle(
        received(
            keys.primary_estimate("tl", "ep-zz"),
            encode(est.model_copy(update={"k": 7})),
        )
    )  # not its episode's key
    scorer.handle(
        received(
            keys.primary_estimate("tl", E), encode(est.model_copy(update={"k": 6, "sender": "s1"}))
        )
    )  # not its key
    assert svc.rejects.count(reason="duplicate") == 2
    assert svc.rejects.count(reason="bad_step") == 1
    assert svc.rejects.count(reason="unknown_episode") == 1  # on another episode's key
    assert svc.rejects.count(reason="wrong_sender") == 1
    assert svc.rejects.total == 5
    assert scorer.store.rows("SELECT count(*) FROM estimates") == [(1,)]


@pytest.mark.unit
def test_the_scorer_holds_what_overtakes_its_episode_start(tmp_path: Path) -> None:
    """Zenoh orders samples per key only: the truth and an estimate of an episode can arrive
    before its start. They are kept, and stored once it starts; none is counted as refused."""
    scorer, svc = _handlers(tmp_path)["scorer"]
    later = {"episode": "ep-later"}
    scorer.handle(
        received(keys.truth("ep-later"), encode(_template("truth").model_copy(update=later)))
    )
    scorer.handle(
        received(
            keys.primary_estimate("tl", "ep-later"),
            encode(_template("estimate").model_copy(update=later)),
        )
    )
    count = "SELECT count(*) FROM {} WHERE episode = 'ep-later'"
    assert scorer.store.rows(count.format("estimates")) == [(0,)]
    scorer.handle(
        received(keys.episode("ep-later"), encode(_template("episode").model_copy(update=later)))
    )
    assert scorer.store.rows(count.format("truth")) == [(1,)]
    assert scorer.store.rows(count.format("estimates")) == [(1,)]
    assert svc.rejects.total == 0


@pytest.mark.unit
def test_the_scorer_counts_what_waits_for_an_episode_that_never_starts(tmp_path: Path) -> None:
    """The hold is bounded: 64 samples an episode, 4 episodes. A 65th sample, and the samples of
    the oldest episode once a 5th waits, are counted as unknown_episode, and none is stored."""
    scorer, svc = _handlers(tmp_path)["scorer"]
    est = _template("estimate")
    for k in range(1, 66):
        update = {"episode": "ep-never", "k": k}
        scorer.handle(
            received(keys.primary_estimate("tl", "ep-never"), encode(est.model_copy(update=update)))
        )
    assert svc.rejects.count(reason="unknown_episode") == 1
    for e in ("ep-a", "ep-b", "ep-c", "ep-d"):
        update = {"episode": e}
        scorer.handle(
            received(keys.primary_estimate("tl", e), encode(est.model_copy(update=update)))
        )
    assert svc.rejects.count(reason="unknown_episode") == 65
    assert scorer.store.rows("SELECT count(*) FROM estimates") == [(0,)]


# ---- the live flood ---------------------------------------------------------------------------

#: decode-level payloads per key: >= 10 000 for each service's key set (episode key: all three)
PLAN = {
    keys.episode(E): ("episode", 3300),
    keys.primary_meas(E): ("measurement", 3300),
    keys.source_meas("s1", E): ("measurement", 6700),
    keys.transfer("s1", E): ("transfer", 3300),
    keys.truth(E): ("truth", 2000),
    keys.source_estimate("s1", E): ("estimate", 1700),
    keys.primary_estimate("tl", E): ("estimate", 1000),
    keys.primary_estimate("isolated", E): ("estimate", 1000),
    keys.stats("source/s1", "source_tracker"): ("stats", 700),
    keys.stats("referee", "fuzzer"): ("stats", 600),
}
SERVICES = {
    "primary_tracker": "primary/primary_tracker",
    "source_tracker": "source/s1/source_tracker",
    "scorer": "referee/scorer",
}
BIG = 100_000_000


def _serves(name: str, key: str) -> bool:
    """Whether service ``name`` subscribes to the concrete ``key`` (its real patterns)."""
    patterns = {
        "primary_tracker": [keys.EPISODES, keys.PRIMARY_MEAS, keys.TRANSFERS],
        "source_tracker": [keys.EPISODES, keys.source_meas("s1", keys.ANY)],
        "scorer": [
            keys.EPISODES,
            keys.TRUTHS,
            keys.SOURCE_ESTIMATES,
            keys.PRIMARY_ESTIMATES,
            f"{keys.ROOT}/**/stats/*",
        ],
    }[name]
    return any(zenoh.KeyExpr(p).intersects(key) for p in patterns)


class StepFuzzer:
    """Messages that decode but name a step the trackers must refuse: k = 0, far in the future,
    replays of genuine ones, a transfer whose sender is not the source its key names. Only while
    the episode is alive in the trackers (a replay after its end is not a rejection, just too
    late)."""

    def __init__(self, z: zenoh.Session, listen: zenoh.Session, K: int) -> None:
        self.z, self.K = z, K
        self.sent: dict[str, int] = {}
        self.genuine = Subscriber(
            listen,
            [
                keys.primary_meas(E),
                keys.source_meas("s1", E),
                keys.transfer("s1", E),
                keys.primary_estimate("tl", E),
            ],
        )
        self.primary_k = 0
        self.latest = 0
        self.replayed: set[bytes] = set()

    def put(self, key: str, payload: bytes) -> None:
        """With BLOCK, as the services publish: a payload the network drops is never counted."""
        self.z.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)
        self.sent[key] = self.sent.get(key, 0) + 1

    def tick(self) -> None:
        for item in self.genuine.drain():
            if item.payload in self.replayed:
                continue
            try:
                msg = decode(item.payload, (Measurement, Transfer, EstimateMsg))
            except MessageRejected:
                continue  # our own flood
            if msg.t_sensor == T0:
                continue  # our own step messages
            if isinstance(msg, EstimateMsg):
                self.primary_k = max(self.primary_k, msg.k)
                continue
            self.latest = max(self.latest, msg.k_apply if isinstance(msg, Transfer) else msg.k)
            if self.latest < self.K - 4:
                self.replayed.add(item.payload)
                for _ in range(2):
                    self.put(item.key, item.payload)  # a duplicate, then stale
        if self.latest >= self.K - 4:
            return
        m = _template("measurement")
        t = _template("transfer")
        for key, sensor in ((keys.primary_meas(E), "primary"), (keys.source_meas("s1", E), "s1")):
            for k in (0, MAX_K, 10**6):
                self.put(key, encode(m.model_copy(update={"k": k, "sensor": sensor})))
        self.put(
            keys.transfer("s1", E), encode(t.model_copy(update={"k": 10**6, "k_apply": 10**6 + 1}))
        )
        self.put(keys.transfer("s9", E), encode(t))
        if self.primary_k >= 2:
            self.put(keys.transfer("s1", E), encode(t.model_copy(update={"k": 0, "k_apply": 1})))


def _rss_sampler(
    pids: dict[str, int], stop: threading.Event
) -> tuple[dict[str, int], Callable[[], None]]:
    peak = {name: 0 for name in pids}

    def run() -> None:
        while not stop.wait(0.05):
            for name, pid in pids.items():
                with contextlib.suppress(OSError, ValueError):  # gone: the liveness check says so
                    peak[name] = max(peak[name], rss_kb(pid))

    return peak, run


@pytest.mark.timeout(180)
@pytest.mark.integration
def test_services_survive_a_flood_of_bad_input_beside_a_lockstep_episode(tmp_path: Path) -> None:
    """Over 10 000 bad payloads per service and one of 100 MB, through the router as deployed
    (BLOCK, so none is lost on the way): every service lives, counts each one in the scorer's
    summary, keeps its memory, and computes exactly what it computes without them."""
    K, N, pace = 60, 500, 3.0
    rnd = random.Random(20261121)
    flood = [(key, malformed(rnd, kind)) for key, (kind, n) in PLAN.items() for _ in range(n)]
    rnd.shuffle(flood)
    acl, users = fuzz_access(tmp_path)
    db = tmp_path / "scorer.sqlite"
    with stack(tmp_path) as s:
        start_router(s, acl, users)
        start_trackers_and_scorer(s, db, users, primary_env={"TLTRACK_PRIMARY_LOCKSTEP": "true"})
        with session(s.endpoint, "referee", users) as ref:
            assert wait_alive(ref, ["scorer", "primary_tracker", "source_tracker"], 90), logs(s)
        pids = {name: s.procs[name].pid for name in SERVICES}
        baseline = {name: rss_kb(pid) for name, pid in pids.items()}
        stop = threading.Event()
        peak, sample = _rss_sampler(pids, stop)
        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        with session(s.endpoint, FUZZER, users) as z, session(s.endpoint, FUZZER, users) as listen:
            steps = StepFuzzer(z, listen, K)
            with Subscriber(listen, keys.EPISODES) as episodes:
                start_sensor(s, K, N, pace=pace, users=users)
                assert episodes.recv_message(EpisodeStart, timeout=60) is not None, logs(s)
            period = (K - 6) / pace / len(flood)
            t_next = time.monotonic()
            for i, (key, payload) in enumerate(flood):
                steps.put(key, payload)
                if i % 50 == 0:
                    steps.tick()
                if i == len(flood) // 2:
                    half = dict(peak)  # the small half of the flood, before the 100 MB payload
                    z.put(
                        keys.episode(E),
                        b"\x00" * BIG,
                        congestion_control=zenoh.CongestionControl.BLOCK,
                    )
                    steps.sent[keys.episode(E)] += 1
                t_next += period
                if (pause := t_next - time.monotonic()) > 0:
                    time.sleep(pause)
            while steps.latest < K - 4 and s.procs["sensor_sim"].poll() is None:
                steps.tick()
                time.sleep(0.05)
            steps.genuine.close()
            sent = dict(steps.sent)
        assert s.wait("sensor_sim", 90) == 0, logs(s)
        scored = wait_for_scored(s.endpoint, 1, 60, users)
        assert scored is not None, logs(s)
        expected = {
            name: sum(n for key, n in sent.items() if _serves(name, key)) for name in SERVICES
        }
        deadline = time.monotonic() + 90  # a loaded machine works through its backlog slowly
        with session(s.endpoint, "referee", users) as ref:
            while True:
                result = summary(ref)
                assert result is not None
                counted = {
                    name: sum(result["messages"]["rejected"].get(op, {}).values())
                    for name, op in SERVICES.items()
                }
                if counted == expected or time.monotonic() > deadline:
                    break
                time.sleep(0.5)
        stop.set()
        sampler.join(5)
        alive = {name: s.procs[name].poll() is None for name in SERVICES}
        assert all(alive.values()), (alive, logs(s))
        final = {name: rss_kb(pid) for name, pid in pids.items()}
        print(
            f"\nsent {sum(sent.values())} payloads; rejected {counted}; RSS kB baseline "
            f"{baseline}, half {half}, peak {peak}, final {final}; "
            f"by reason {result['messages']['rejected']}"
        )

    assert all(n >= 10_000 for n in expected.values()), expected
    assert counted == expected, (counted, expected)
    assert result["messages"]["dropped"] == 0
    MB = 1024
    first_half = flood[: len(flood) // 2]
    for name in SERVICES:
        # The small bad payloads cost at most what is still queued (on a loaded machine, up to
        # all of the first half's bytes for that service) beyond 40 MB; the 100 MB one is copied
        # about twice on receipt (zenoh's reassembly, then bytes) and the allocator keeps part.
        queued_kb = sum(len(p) for key, p in first_half if _serves(name, key)) / 1024
        assert half[name] - baseline[name] < 40 * MB + queued_kb, (name, baseline, half)
        assert peak[name] - baseline[name] < 3 * BIG / 1e6 * MB, (name, baseline, peak)
        assert final[name] - baseline[name] < 2 * BIG / 1e6 * MB, (name, baseline, final)
    cfg = make_config(**SIM_DEFAULTS, K=K, particles=N, recovery=True)
    offline = trace_run(cfg, ["tl-rpf", "rpf", "source-rpf"], run=0)
    live = estimates(db)
    for name in ("tl-rpf", "rpf", "source-rpf"):
        x = np.array([live[name][k][0] for k in range(1, K + 1)])
        np.testing.assert_allclose(x, offline[name], rtol=0, atol=1e-9, err_msg=name)
