"""The wire format: round trips, every rejection class, fuzzing, reject counting."""

from __future__ import annotations

import math
import re
import threading
from typing import Any

import msgpack
import numpy as np
import pytest
from doubles import RADAR
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tltrack.config import make_config
from tltrack.models.scan import MAX_DETECTIONS
from tltrack.wire import messages
from tltrack.wire.messages import (
    MAX_PAYLOAD_BYTES,
    MESSAGE_TYPES,
    REASONS,
    SCHEMA_VERSION,
    EpisodeEnd,
    EpisodeStart,
    EstimateMsg,
    Measurement,
    Message,
    MessageRejected,
    RejectCounter,
    Schedule,
    Tick,
    Transfer,
    Truth,
    decode,
    decode_stats,
    encode,
)

V = SCHEMA_VERSION

pytestmark = [pytest.mark.unit, pytest.mark.timeout(60)]

T0 = 1_700_000_000.0
COMMON: dict[str, Any] = {"episode": "ep-1", "sender": "s1", "t_sensor": T0}


def _spd(n: int, seed: int = 0) -> np.ndarray:
    a = np.random.default_rng(seed).standard_normal((n, n))
    return a @ a.T + n * np.eye(n)


def samples() -> list[Message]:
    cfg = make_config(scenario="ct")
    return [
        Measurement(**COMMON, k=3, sensor="radar-1", z=np.array([[1500.0, 0.7]])),
        Truth(**COMMON, k=3, x=np.array([1.0, 2.0, 3.0, 4.0, -0.05]), pos=np.array([1.0, 3.0])),
        Truth(**COMMON, k=0, x=[1.0, 2.0, 3.0, 4.0], pos=[1.0, 3.0]),
        Transfer(
            **COMMON, k=3, k_apply=4, sensor=RADAR, eta=np.array([1500.0, 0.7]), P_eta=_spd(2)
        ),
        EstimateMsg(
            **COMMON,
            k=7,
            filter="tl-pf",
            x=np.arange(5.0),
            pos=[0.0, 2.0],
            P=_spd(5),
            transfer_used=True,
            t_sent=T0 + 0.01,
            step_ms=1.6,
        ),
        EstimateMsg(
            **COMMON,
            k=7,
            filter="sir",
            x=np.arange(4.0),
            pos=[0.0, 2.0],
            P=_spd(4),
            transfer_used=False,
            t_sent=T0,
            step_ms=0,
        ),
        EpisodeStart(**COMMON, k=0, run=2, config=cfg.model_dump(), K=cfg.K, steps_per_sec=10.0),
        EpisodeEnd(**COMMON, k=99, steps_sent=100),
        Tick(**COMMON, k=3),
        Schedule(**COMMON, k=0, period_s=1.0, t0_s=0.25),
    ]


def raw(msg: Message) -> dict[str, Any]:
    """The wire dict of a valid message, for tampering."""
    return msgpack.unpackb(encode(msg), raw=False)


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def reject(payload: bytes, typ: type[Message]) -> str:
    with pytest.raises(MessageRejected) as info:
        decode(payload, typ)
    assert info.value.reason in REASONS
    return info.value.reason


VALID_TRANSFER = Transfer(
    **COMMON, k=3, k_apply=4, sensor=RADAR, eta=[1500.0, 0.7], P_eta=[[4.0, 1.0], [1.0, 3.0]]
)


# ---- round trips --------------------------------------------------------------------------------


@pytest.mark.parametrize("msg", samples(), ids=lambda m: type(m).__name__)
def test_round_trip(msg: Message) -> None:
    data = encode(msg)
    assert isinstance(data, bytes) and len(data) < MAX_PAYLOAD_BYTES
    back = decode(data, type(msg))
    assert back == msg
    assert back.schema_version == SCHEMA_VERSION
    assert encode(back) == data  # canonical: encoding is stable


def test_numpy_inputs_become_plain_floats() -> None:
    z = np.array([[1.0, 2.0]], dtype=np.float32)
    m = Measurement(**COMMON, k=np.int64(2), sensor="a", z=z)  # type: ignore[arg-type]
    assert type(m.z) is list and all(type(v) is float for d in m.z for v in d)
    assert decode(encode(m), Measurement) == m


def test_episode_start_config_is_canonical_and_parses() -> None:
    msg = decode(encode(samples()[6]), EpisodeStart)
    cfg = msg.parsed_config()
    assert cfg.scenario == "ct" and cfg.K == msg.K
    assert msg.config == cfg.model_dump(mode="json")


def test_every_type_is_registered() -> None:
    assert set(MESSAGE_TYPES) == {type(m).TYPE for m in samples()}


# ---- rejections ---------------------------------------------------------------------------------


def test_too_large_is_refused_before_unpacking(monkeypatch: pytest.MonkeyPatch) -> None:
    # A valid msgpack map far over the limit: refusing it must not cost an unpack (whose
    # time would then grow with the flood; no clock here, the unpacker is simply never called).
    big = pack(
        {"schema_version": SCHEMA_VERSION, "type": "transfer", "pad": "x" * (4 * 1024 * 1024)}
    )
    unpacked: list[int] = []
    real = messages._unpack

    def counted(payload: bytes) -> Any:
        unpacked.append(len(payload))
        return real(payload)

    monkeypatch.setattr(messages, "_unpack", counted)
    assert reject(big, Transfer) == "too_large"
    assert reject(b"\x00" * (MAX_PAYLOAD_BYTES + 1), Transfer) == "too_large"
    assert unpacked == []
    fit = encode(VALID_TRANSFER)
    assert decode(fit, Transfer) == VALID_TRANSFER and unpacked == [len(fit)]


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"\xc1",  # never-used msgpack byte
        b"\x93\x01\x02",  # array of 3 with 2 items
        encode(VALID_TRANSFER)[:-3],  # truncated
        encode(VALID_TRANSFER) + b"\x00",  # trailing data
        b"\xdd\xff\xff\xff\xff",  # array32 claiming 4 G items
        b"\xdf\xff\xff\xff\xff",  # map32 claiming 4 G entries
        b"\xdb\xff\xff\xff\xff" + b"a" * 10,  # str32 claiming 4 GiB
        b"\xc6\x7f\xff\xff\xff",  # bin32 claiming 2 GiB
        b"\xa2\xff\xfe",  # invalid UTF-8
        pack({1: 2}),  # non-string map key
        pack(
            {"schema_version": SCHEMA_VERSION, "type": "transfer", "pad": b"bytes"}
        ),  # bin not allowed
        pack(
            {"schema_version": SCHEMA_VERSION, "type": "transfer", "t": msgpack.Timestamp(1, 0)}
        ),  # ext
        pack(
            {"schema_version": SCHEMA_VERSION, "type": "transfer", "e": msgpack.ExtType(5, b"xyz")}
        ),
    ],
)
def test_garbage_is_not_msgpack(payload: bytes) -> None:
    assert reject(payload, Transfer) == "not_msgpack"


@pytest.mark.parametrize("top", [[1, 2], 3, "transfer", None, 1.5, True])
def test_top_level_must_be_a_map(top: Any) -> None:
    assert reject(pack(top), Transfer) == "bad_structure"


def test_deep_nesting_is_refused() -> None:
    deep: Any = 1.0
    for _ in range(200):
        deep = [deep]
    assert reject(pack({**raw(VALID_TRANSFER), "eta": deep}), Transfer) == "bad_structure"
    # deeper than msgpack's own stack: refused by the unpacker
    assert reject(b"\x91" * 100_000 + b"\x01", Transfer) in ("not_msgpack", "too_large")
    assert reject(b"\x91" * 20_000 + b"\x01", Transfer) in ("not_msgpack", "bad_structure")


@pytest.mark.parametrize("version", [0, 1, 99, -1, "2", 2.0, True, None, [2]])
def test_unknown_schema_version(version: Any) -> None:
    d = raw(VALID_TRANSFER)
    d["schema_version"] = version
    assert reject(pack(d), Transfer) == "unknown_version"
    del d["schema_version"]
    assert reject(pack(d), Transfer) == "unknown_version"


def test_constructing_an_unknown_version_fails() -> None:
    with pytest.raises(ValueError, match=f"schema_version {V + 1} is not supported"):
        Measurement(**COMMON, k=0, sensor="a", z=[[1.0, 2.0]], schema_version=V + 1)


def test_wrong_type_tag() -> None:
    assert reject(encode(VALID_TRANSFER), Measurement) == "wrong_type"
    d = raw(VALID_TRANSFER)
    d["type"] = "TRANSFER"
    assert reject(pack(d), Transfer) == "wrong_type"
    del d["type"]
    assert reject(pack(d), Transfer) == "wrong_type"


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("eta", [1.0]),
        ("eta", [1.0, 2.0, 3.0]),
        ("eta", []),
        ("P_eta", [[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]),
        ("P_eta", [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        ("P_eta", [[1.0, 0.0], [0.0]]),  # ragged
        ("P_eta", []),
    ],
)
def test_transfer_bad_shapes(field: str, value: Any) -> None:
    d = raw(VALID_TRANSFER)
    d[field] = value
    assert reject(pack(d), Transfer) == "bad_shape"


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("eta", [1e300, 0.7]),  # finite, and it overflows the filters' squares
        ("eta", [-5.0, 0.7]),  # a range that is not positive
        ("eta", [1500.0, 100.0]),  # a bearing outside [-pi, pi]
        ("P_eta", [[1e300, 0.0], [0.0, 1.0]]),
    ],
)
def test_a_transfer_no_sensor_could_state_is_refused(field: str, value: Any) -> None:
    d = raw(VALID_TRANSFER)
    d[field] = value
    assert reject(pack(d), Transfer) == "out_of_range"


def test_a_transfer_describes_its_sensor_and_its_size_follows_the_kind() -> None:
    bearing = {"kind": "bearing", "position": [-3000.0, 5.0], "sigma_bearing": 1e-3}
    d = {**raw(VALID_TRANSFER), "sensor": bearing, "eta": [0.7], "P_eta": [[1e-6]]}
    back = decode(pack(d), Transfer)
    assert back.sensor.kind == "bearing" and back.sensor.position == (-3000.0, 5.0)
    d["eta"] = [1500.0, 0.7]  # two components from a bearing-only sensor
    assert reject(pack(d), Transfer) == "bad_shape"
    d = {**raw(VALID_TRANSFER), "sensor": {**bearing, "kind": "sonar"}}
    assert reject(pack(d), Transfer) == "unknown_kind"
    d = {**raw(VALID_TRANSFER), "sensor": {**bearing, "sigma_pos": 3.0}}  # not a bearing's
    assert reject(pack(d), Transfer) == "invalid"
    d = raw(VALID_TRANSFER)
    del d["sensor"]
    assert reject(pack(d), Transfer) == "invalid"


def test_a_transfer_names_every_parameter_of_its_sensor() -> None:
    """The primary builds the source's sensor from the transfer: one left out crashed it."""
    d = raw(VALID_TRANSFER)
    del d["sensor"]["sigma_r"]
    with pytest.raises(MessageRejected, match="needs sigma_r") as info:
        decode(pack(d), Transfer)
    assert info.value.reason == "invalid"
    position = {"kind": "position", "position": [0.0, 0.0]}  # sigma_pos has a default: taken
    d = {**raw(VALID_TRANSFER), "sensor": position, "eta": [10.0, 20.0], "P_eta": [[4, 0], [0, 4]]}
    assert decode(pack(d), Transfer).sensor.kind == "position"


def test_a_time_past_the_year_5000_is_refused() -> None:
    """A Stone Soup reader dates a message by its t_sensor: 1e12 s overflowed its datetime and
    ended its generator."""
    d = raw(VALID_TRANSFER)
    d["t_sensor"] = 1e11
    assert decode(pack(d), Transfer).t_sensor == 1e11
    d["t_sensor"] = 1.0000001e11
    assert reject(pack(d), Transfer) == "invalid"


@pytest.mark.parametrize(("i", "typ"), [(1, Truth), (4, EstimateMsg)])
@pytest.mark.parametrize("field", ["x", "pos"])
def test_a_state_beyond_1e9_is_refused(i: int, typ: type[Message], field: str) -> None:
    """Finite, and its square overflowed the scorer's error (OverflowError ended it)."""
    d = raw(samples()[i])
    d[field] = [1e155, *d[field][1:]]
    assert reject(pack(d), typ) == "out_of_range"


def test_estimate_bad_shapes() -> None:
    est = samples()[4]
    d = raw(est)
    d["P"] = _spd(4).tolist()  # x has 5 entries
    assert reject(pack(d), EstimateMsg) == "bad_shape"
    d = raw(est)
    d["x"] = [0.0] * 7  # no scenario has 7 states
    assert reject(pack(d), EstimateMsg) == "bad_shape"
    d = raw(samples()[0])
    d["z"] = [[1.0, 2.0, 3.0, 4.0]]  # no sensor measures 4 components
    assert reject(pack(d), Measurement) == "bad_shape"
    d["z"] = [[1.0, 2.0], [1.0, 2.0, 3.0]]  # one sensor's detections share its size
    assert reject(pack(d), Measurement) == "bad_shape"
    d = raw(samples()[1])
    d["x"] = [1.0, 2.0, 3.0]
    assert reject(pack(d), Truth) == "bad_shape"


def _float_paths(obj: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    if isinstance(obj, float):
        return [path]
    if isinstance(obj, list):
        return [p for i, v in enumerate(obj) for p in _float_paths(v, (*path, i))]
    if isinstance(obj, dict):
        return [p for k, v in obj.items() if k != "config" for p in _float_paths(v, (*path, k))]
    return []


def _set(d: Any, path: tuple[Any, ...], value: Any) -> None:
    for p in path[:-1]:
        d = d[p]
    d[path[-1]] = value


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("msg", samples(), ids=lambda m: type(m).__name__)
def test_non_finite_anywhere(msg: Message, bad: float) -> None:
    d = raw(msg)
    paths = _float_paths(d)
    assert paths
    for path in paths:
        tampered = raw(msg)
        _set(tampered, path, bad)
        assert reject(pack(tampered), type(msg)) == "non_finite", path


def test_nan_is_non_finite() -> None:
    d = raw(VALID_TRANSFER)
    d["eta"] = [math.nan, 0.0]
    assert reject(pack(d), Transfer) == "non_finite"
    d = raw(VALID_TRANSFER)
    d["P_eta"] = [[1.0, math.nan], [math.nan, 1.0]]
    assert reject(pack(d), Transfer) == "non_finite"


@pytest.mark.parametrize(
    "P",
    [
        [[1.0, 2.0], [2.0, 1.0]],  # indefinite
        [[1.0, 1.0], [1.0, 1.0]],  # singular
        [[0.0, 0.0], [0.0, 0.0]],
        [[-1.0, 0.0], [0.0, -1.0]],
        [[1e308, 1e308], [1e308, 1e308]],  # overflow inside Cholesky
        [[1e-300, 0.0], [0.0, -1e-300]],
    ],
)
def test_non_spd_covariance(P: list[list[float]]) -> None:
    d = raw(VALID_TRANSFER)
    d["P_eta"] = P
    assert reject(pack(d), Transfer) == "not_spd"


def test_non_spd_estimate_covariance() -> None:
    d = raw(samples()[4])
    P = np.array(d["P"])
    w, V = np.linalg.eigh(P)
    w[0] = -1e-3
    d["P"] = ((V * w) @ V.T).tolist()
    d["P"] = [
        [(a + b) / 2 for a, b in zip(r, c, strict=True)]
        for r, c in zip(d["P"], zip(*d["P"], strict=True), strict=True)
    ]
    assert reject(pack(d), EstimateMsg) == "not_spd"


def test_asymmetric_covariance() -> None:
    d = raw(VALID_TRANSFER)
    d["P_eta"] = [[4.0, 1.0], [1.001, 3.0]]
    assert reject(pack(d), Transfer) == "not_symmetric"
    # round-off asymmetry well inside the 1e-9 relative tolerance is accepted
    d["P_eta"] = [[4.0e6, 1.0], [1.0 + 1e-6, 3.0e6]]
    assert decode(pack(d), Transfer).P_eta[1][0] == 1.0 + 1e-6


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("k", True),  # bool is not an int on the wire
        ("k", 3.0),
        ("k", "3"),
        ("k", -1),
        ("k", 2**40),
        ("k_apply", 5),  # k != k_apply - 1
        ("t_sensor", "1700000000"),
        ("t_sensor", -5.0),
        ("eta", ["1.0", 2.0]),
        ("eta", [True, 2.0]),
        ("eta", {"0": 1.0}),
        ("episode", "a/b"),  # would break key expressions
        ("episode", "*"),
        ("episode", ""),
        ("sender", "x" * 65),
        ("sender", 7),
    ],
)
def test_invalid_fields(field: str, value: Any) -> None:
    d = raw(VALID_TRANSFER)
    d[field] = value
    assert reject(pack(d), Transfer) in ("invalid", "bad_shape")


def test_missing_and_extra_fields() -> None:
    d = raw(VALID_TRANSFER)
    del d["P_eta"]
    assert reject(pack(d), Transfer) == "invalid"
    d = raw(VALID_TRANSFER)
    d["surprise"] = 1
    assert reject(pack(d), Transfer) == "invalid"


def test_episode_start_with_bad_config() -> None:
    d = raw(samples()[6])
    d["config"]["particles"] = -5
    assert reject(pack(d), EpisodeStart) == "invalid"
    d = raw(samples()[6])
    d["config"]["no_such_field"] = 1
    assert reject(pack(d), EpisodeStart) == "invalid"
    d = raw(samples()[6])  # K follows from it: 200000 steps, over the 100000 receivers take
    d["config"] = {**d["config"], "duration_s": 200_000.0}
    del d["config"]["K"]
    with pytest.raises(MessageRejected, match="K") as info:
        decode(pack(d), EpisodeStart)
    assert info.value.reason == "invalid"
    for field, value in (("kappa", math.nan), ("primary_position", [math.inf, 0.0])):
        d = raw(samples()[6])
        d["config"][field] = value
        assert reject(pack(d), EpisodeStart) == "non_finite"


def test_non_bytes_payload() -> None:
    for payload in ("text", None, 5, [1, 2]):
        with pytest.raises(MessageRejected):
            decode(payload, Transfer)  # type: ignore[arg-type]


def test_encode_refuses_oversized_message() -> None:
    cfg = make_config().model_dump()
    msg = EpisodeStart(**COMMON, k=0, run=0, config=cfg, K=1, steps_per_sec=0)
    huge = msg.model_copy(update={"config": {**cfg, "pad": "x" * MAX_PAYLOAD_BYTES}})
    with pytest.raises(ValueError, match="encodes to"):
        encode(huge)


# ---- fuzzing: nothing but MessageRejected ever escapes ------------------------------------------

json_like = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**64 - 1)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=20)
    | st.binary(max_size=20),
    lambda children: (
        st.lists(children, max_size=6) | st.dictionaries(st.text(max_size=10), children, max_size=6)
    ),
    max_leaves=40,
)

TYPES = list(MESSAGE_TYPES.values())


def _decode_or_reject(payload: bytes, typ: type[Message]) -> None:
    try:
        msg = decode(payload, typ)
    except MessageRejected as err:
        assert err.reason in REASONS
        assert err.reason != "internal", err.detail
    else:
        assert isinstance(msg, typ)


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(payload=st.binary(max_size=512), typ=st.sampled_from(TYPES))
def test_fuzz_random_bytes(payload: bytes, typ: type[Message]) -> None:
    _decode_or_reject(payload, typ)


@settings(max_examples=500, deadline=None)
@given(obj=json_like, typ=st.sampled_from(TYPES))
def test_fuzz_random_structures(obj: Any, typ: type[Message]) -> None:
    _decode_or_reject(pack(obj), typ)


@settings(max_examples=1000, deadline=None)
@given(
    idx=st.integers(0, len(samples()) - 1),
    field=st.text(max_size=12) | st.sampled_from(["k", "z", "x", "P", "eta", "P_eta", "config"]),
    value=json_like,
)
def test_fuzz_tampered_fields(idx: int, field: str, value: Any) -> None:
    msg = samples()[idx]
    d = raw(msg)
    d[field] = value
    _decode_or_reject(pack(d), type(msg))


@settings(max_examples=1000, deadline=None)
@given(idx=st.integers(0, len(samples()) - 1), data=st.data())
def test_fuzz_byte_flips(idx: int, data: st.DataObject) -> None:
    msg = samples()[idx]
    buf = bytearray(encode(msg))
    for _ in range(data.draw(st.integers(1, 4))):
        pos = data.draw(st.integers(0, len(buf) - 1))
        buf[pos] = data.draw(st.integers(0, 255))
    _decode_or_reject(bytes(buf), type(msg))


# ---- reject counter ----------------------------------------------------------------------------


def test_reject_counter_counts_per_key_and_reason() -> None:
    rc = RejectCounter()
    for payload in (b"\xc1", pack([1]), pack({"schema_version": 9})):
        try:
            decode(payload, Transfer)
        except MessageRejected as err:
            rc.record("tltrack/source/s1/transfer/e1", err)
    rc.add("tltrack/primary/meas/e1", "non_finite")
    assert rc.total == 4
    assert rc.by_reason() == {
        "not_msgpack": 1,
        "bad_structure": 1,
        "unknown_version": 1,
        "non_finite": 1,
    }
    assert rc.count(key="tltrack/source/s1/transfer/e1") == 3
    assert rc.count(key="tltrack/primary/meas/e1", reason="non_finite") == 1
    assert rc.count(reason="not_msgpack") == 1
    snap = rc.snapshot()
    assert snap["total"] == 4 and set(snap) == {"total", "by_reason", "by_key"}


def test_reject_counter_is_thread_safe_and_bounded() -> None:
    rc = RejectCounter(max_keys=10)

    def work(t: int) -> None:
        for i in range(2000):
            rc.add(f"key/{t}/{i % 20}", REASONS[i % 3])

    threads = [threading.Thread(target=work, args=(t,)) for t in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert rc.total == 16_000
    assert sum(rc.by_key().values()) == 16_000
    assert sum(rc.by_reason().values()) == 16_000
    assert len(rc.by_key()) <= 11 and RejectCounter.OTHER in rc.by_key()


def test_the_wire_imports_no_statistics_library() -> None:
    """Every service and every container's health check imports the wire; scipy.stats alone
    costs seconds on a loaded machine, past the health check's timeout (compose.yaml)."""
    import subprocess
    import sys

    code = "import sys, tltrack.wire.transport; print('scipy.stats' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_a_measurement_carries_a_scan_of_up_to_4096_detections() -> None:
    """None is an empty scan, not an error; the largest scan of the widest built-in sensor fits
    the payload bound; one more detection is refused with its own reason."""
    empty = Measurement(**COMMON, k=1, sensor="a", z=[])
    assert decode(encode(empty), Measurement).z == []
    rng = np.random.default_rng(0)
    full = Measurement(**COMMON, k=1, sensor="a", z=rng.normal(size=(MAX_DETECTIONS, 3)))
    assert decode(encode(full), Measurement) == full
    d = raw(full)
    d["z"] = d["z"] + [[1.0, 2.0, 3.0]]
    assert reject(pack(d), Measurement) == "scan_too_large"


def test_a_truth_carries_the_simulated_scan_one_flag_per_detection() -> None:
    """The referee's picture of the primary's scan: positions and which are false alarms, bounded
    like a scan; a flag too few, a detection that is no position, or one too many is refused."""
    rng = np.random.default_rng(0)
    xy = rng.normal(size=(MAX_DETECTIONS, 2))
    full = Truth(**COMMON, k=2, x=[1.0, 2.0, 3.0, 4.0], pos=[1.0, 3.0], scan=xy,
                 scan_clutter=[True] * MAX_DETECTIONS)  # fmt: skip
    assert decode(encode(full), Truth) == full
    d = raw(full)
    for change, reason in [
        ({"scan_clutter": [True] * (MAX_DETECTIONS - 1)}, "bad_shape"),
        ({"scan": [[1.0, 2.0, 3.0]] * MAX_DETECTIONS}, "bad_shape"),
        ({"scan": d["scan"] + [[0.0, 0.0]], "scan_clutter": d["scan_clutter"] + [False]},
         "scan_too_large"),
    ]:  # fmt: skip
        assert reject(pack({**d, **change}), Truth) == reason, change


@pytest.mark.parametrize(
    ("payload", "said"),
    [
        (b"[1, 2]", "a JSON list, not an object"),
        (b"[" * 100_000, "nested too deeply"),  # json.loads recurses: a RecursionError
        (b'{"a": "' + b"x" * MAX_PAYLOAD_BYTES + b'"}', f"> {MAX_PAYLOAD_BYTES} B"),
        (b"\xff", "can't decode byte 0xff"),
        (b"{", "Expecting property name"),
    ],
)
def test_service_statistics_are_a_json_object_of_bounded_size(payload: bytes, said: str) -> None:
    with pytest.raises(ValueError, match=re.escape(said)):
        decode_stats(payload)
    assert decode_stats(b'{"steps": 3}') == {"steps": 3}
