"""The wire format: pydantic v2 models sent as msgpack maps, validated on receipt.

Every message carries ``schema_version``, a ``type`` tag, ``episode``, ``sender``, the step ``k``
and the sensor timestamp ``t_sensor``. :func:`encode` packs a model; :func:`decode` is the only way
in and raises exactly one exception type, :class:`MessageRejected`, for *any* bad payload: too
large (checked before unpacking), not msgpack, trailing bytes, nested too deep, wrong type tag,
unknown schema version, wrong shapes, non-finite numbers, asymmetric or non-positive-definite
covariances. Its ``reason`` is a short code from :data:`REASONS`, suitable as a counter label.

On receipt validation is *strict* (no ``"1.5"`` -> 1.5, no ``True`` -> 1); constructing a model
in code is lax, so a sender may pass NumPy arrays and scalars.

:func:`decode_stats` takes a service's statistics, JSON rather than msgpack (the dashboard and
``zenoh-cli`` show them as they are). :class:`RejectCounter` counts rejections per key and
reason. Replays are refused where the state lives: a tracker's step queue, the scorer's SQLite
keys.
"""

from __future__ import annotations

import json
import math
import threading
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Literal, TypeVar

import msgpack
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError
from tltrack.config import SensorSpec
from tltrack.models import components
from tltrack.models.kinds import MOTIONS, SENSORS
from tltrack.models.scan import MAX_DETECTIONS

#: 2: Truth and EstimateMsg carry ``pos``, the position in ``x`` (the referee needs no state
#: layout), EstimateMsg whether the filter was reinitialised (``recovered``), a Transfer the
#: sensor it is expressed in (``sensor``); sizes follow n_x and n_z.
#: 3: EstimateMsg carries the NIS of the filter's own measurement, its window's mean and band
#: 4: a Measurement carries a scan: ``z`` is a list of detections (the paper's sensor: one)
#: 5: a Truth carries the primary's scan as the simulation drew it (``scan``, ``scan_clutter``)
SCHEMA_VERSION = 5
SUPPORTED_VERSIONS = frozenset({5})

#: refused before unpacking: room for a scan of MAX_DETECTIONS detections of 3 components
#: (9 B per float64 in msgpack: 4096 * 3 * 9 = 110.6 kB)
MAX_PAYLOAD_BYTES = 192 * 1024
MAX_DEPTH = 12  #: nesting of maps/arrays (the config dict is the deepest: 3)
SYMMETRY_RTOL = 1e-9
MAX_K = 2**31 - 1  #: the largest step index a message may carry


def state_sizes() -> tuple[int, ...]:
    """n_x of every registered motion model."""
    return tuple(sorted({len(MOTIONS.get(k).components) for k in MOTIONS.names()}))


def measurement_sizes() -> tuple[int, ...]:
    """n_z of every registered sensor kind."""
    return tuple(sorted({len(SENSORS.get(k).components) for k in SENSORS.names()}))


#: Every ``MessageRejected.reason``.
REASONS = (
    "too_large",  # payload over MAX_PAYLOAD_BYTES
    "not_msgpack",  # not decodable msgpack, trailing bytes, over the unpacker's limits
    "bad_structure",  # not a map, nested too deep, or a value of a type msgpack maps we never send
    "unknown_version",  # schema_version missing or not supported
    "wrong_type",  # type tag is not the expected message type
    "bad_shape",  # wrong vector/matrix dimensions
    "scan_too_large",  # a scan of more than MAX_DETECTIONS detections
    "non_finite",  # NaN or infinity
    "out_of_range",  # a value no sensor measures: a range <= 0, 1e300 m (tltrack.models.components)
    "not_symmetric",  # covariance asymmetric beyond SYMMETRY_RTOL
    "not_spd",  # covariance not positive-definite (Cholesky failed)
    "unknown_kind",  # names a sensor, motion or filter kind the receiver has not registered
    "invalid",  # any other schema violation (missing field, wrong type, out of range...)
    "internal",  # the validator itself failed: a bug, still reported as a rejection
)


class MessageRejected(Exception):  # noqa: N818 (the name the services use)
    """A payload was refused. ``reason`` is one of :data:`REASONS`; ``detail`` is for logs."""

    def __init__(self, reason: str, detail: str = "") -> None:
        self.reason = reason
        self.detail = detail
        super().__init__(f"{reason}: {detail}" if detail else reason)


# ---- field types and checks -------------------------------------------------------------------

Finite = Annotated[float, Field(allow_inf_nan=False)]
Id = Annotated[str, Field(pattern=r"^[A-Za-z0-9_-]{1,64}$")]
Step = Annotated[int, Field(ge=0, le=MAX_K)]
#: seconds since the epoch (time.time()), before the year 5000: a later one overflows a datetime
Timestamp = Annotated[float, Field(ge=0, le=1e11, allow_inf_nan=False)]


def _as_list(v: Any) -> Any:
    """Let senders pass NumPy arrays; on receipt values are already lists."""
    tolist = getattr(v, "tolist", None)
    return tolist() if callable(tolist) and not isinstance(v, list) else v


if TYPE_CHECKING:  # senders may pass NumPy arrays; at run time pydantic turns them into lists
    Vector = Any
    Matrix = Any
    Vectors = Any
else:
    Vector = Annotated[list[Finite], BeforeValidator(_as_list)]  #: list[float] on the wire
    Matrix = Annotated[list[list[Finite]], BeforeValidator(_as_list)]  #: list[list[float]]
    Vectors = Annotated[list[Vector], BeforeValidator(_as_list)]  #: rows of any length


def _check_vector(v: list[float], sizes: tuple[int, ...], name: str) -> list[float]:
    if len(v) not in sizes:
        want = " or ".join(map(str, sizes))
        raise PydanticCustomError("bad_shape", f"{name} has {len(v)} entries, expected {want}")
    return v


def _check_position(v: list[float], sizes: tuple[int, ...], name: str) -> list[float]:
    """A state or position: of one of ``sizes``, each entry within 1e9 (a metre, a metre per
    second: a farther one is no target's, and its square would overflow a float)."""
    _check_vector(v, sizes, name)
    if any(abs(c) > components.MAX_MAGNITUDE for c in v):
        raise PydanticCustomError("out_of_range", f"{name} has an entry beyond 1e9")
    return v


def _check_scan(v: list[list[float]], sizes: tuple[int, ...], name: str) -> list[list[float]]:
    """At most MAX_DETECTIONS detections, each of one of ``sizes``."""
    if len(v) > MAX_DETECTIONS:
        raise PydanticCustomError(
            "scan_too_large", f"{name} has {len(v)} detections, at most {MAX_DETECTIONS}"
        )
    for i, d in enumerate(v):
        _check_vector(d, sizes, f"{name}[{i}]")
    return v


def _check_covariance(P: list[list[float]], n: int, name: str) -> list[list[float]]:
    """Shape n x n, symmetric to SYMMETRY_RTOL of its largest entry, Cholesky succeeds."""
    if len(P) != n or any(len(row) != n for row in P):
        shape = f"{len(P)}x{'/'.join(str(len(r)) for r in P) or 0}"
        raise PydanticCustomError("bad_shape", f"{name} is {shape}, expected {n}x{n}")
    scale = max(abs(x) for row in P for x in row)
    asym = max(abs(P[i][j] - P[j][i]) for i in range(n) for j in range(i + 1, n)) if n > 1 else 0.0
    if asym > SYMMETRY_RTOL * scale:
        raise PydanticCustomError(
            "not_symmetric", f"{name} is not symmetric (max |P-P'| = {asym:.3g})"
        )
    # Plain Cholesky on the lower triangle: every pivot must be finite and > 0.
    L = [[0.0] * n for _ in range(n)]
    for j in range(n):
        s = P[j][j] - sum(L[j][m] * L[j][m] for m in range(j))
        if not (s > 0.0 and math.isfinite(s)):
            raise PydanticCustomError("not_spd", f"{name} is not positive-definite")
        L[j][j] = math.sqrt(s)
        for i in range(j + 1, n):
            L[i][j] = (P[i][j] - sum(L[i][m] * L[j][m] for m in range(j))) / L[j][j]
            if not math.isfinite(L[i][j]):
                raise PydanticCustomError("not_spd", f"{name} is not positive-definite")
    return P


def _sensor_spec(v: Any) -> Any:
    """A sensor description from its plain map (as msgpack gives it: lists, not tuples)."""
    if isinstance(v, SensorSpec):
        return v
    try:
        return SensorSpec.model_validate(v)
    except ValidationError as err:
        first = err.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "its parameters"
        detail = {"where": where, "msg": first["msg"]}
        reason = {"finite_number": "non_finite", "unknown_kind": "unknown_kind"}.get(
            first["type"], "invalid"
        )
        raise PydanticCustomError(reason, "{where}: {msg}", detail) from None


def _all_finite(obj: Any) -> bool:
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, list | tuple):
        return all(_all_finite(v) for v in obj)
    if isinstance(obj, dict):
        return all(_all_finite(v) for v in obj.values())
    return True


# ---- models -----------------------------------------------------------------------------------


class Message(BaseModel):
    """Fields every message carries."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    TYPE: ClassVar[str] = ""

    schema_version: int = SCHEMA_VERSION
    episode: Id
    sender: Id
    k: Step
    t_sensor: Timestamp
    #: time.time() when this process received the message; set on receipt, never on the wire
    _received_at: float | None = PrivateAttr(default=None)

    @property
    def received_at(self) -> float | None:
        return self._received_at

    def received(self, t: float) -> Message:
        """This message, stamped with the local time it arrived (the latency's stages)."""
        self._received_at = t
        return self

    def __eq__(self, other: object) -> bool:
        """Equal fields make equal messages: when each copy arrived is not part of it."""
        if not isinstance(other, Message):
            return NotImplemented
        return type(self) is type(other) and self.__dict__ == other.__dict__

    @field_validator("schema_version")
    @classmethod
    def _known_version(cls, v: int) -> int:
        if v not in SUPPORTED_VERSIONS:
            raise PydanticCustomError("unknown_version", f"schema_version {v} is not supported")
        return v


class Measurement(Message):
    """One sensor's scan at step k: every detection it reported (none, one, or up to
    :data:`~tltrack.models.scan.MAX_DETECTIONS`), each in that sensor's components (its tracker
    checks that the size is its sensor's, and that a sensor which always detects the target and
    nothing else, the paper's, sent exactly one)."""

    TYPE: ClassVar[str] = "measurement"
    type: Literal["measurement"] = "measurement"
    sensor: Id
    z: Vectors

    @field_validator("z")
    @classmethod
    def _shape(cls, v: list[list[float]]) -> list[list[float]]:
        _check_scan(v, measurement_sizes(), "z")
        if len({len(d) for d in v}) > 1:
            raise PydanticCustomError("bad_shape", "z's detections differ in size")
        return v


class Truth(Message):
    """The true state x_k and its position (referee data). In a simulated episode it also
    carries the primary's scan at k as the referee's simulation drew it, as positions, with
    which are false alarms (``scan_clutter``): the dashboard draws it. The referee made those
    detections; no operator's measurement is read for it (in the federated topology each operator
    draws its own, from the same seeds). Empty in a replay, or when the primary's sensor fixes no
    position."""

    TYPE: ClassVar[str] = "truth"
    type: Literal["truth"] = "truth"
    x: Vector
    pos: Vector
    scan: Vectors = Field(default_factory=list)
    scan_clutter: list[bool] = Field(default_factory=list)

    @field_validator("x")
    @classmethod
    def _shape(cls, v: list[float]) -> list[float]:
        return _check_position(v, state_sizes(), "x")

    @field_validator("pos")
    @classmethod
    def _pos_shape(cls, v: list[float]) -> list[float]:
        return _check_position(v, (2,), "pos")

    @field_validator("scan")
    @classmethod
    def _scan_shape(cls, v: list[list[float]]) -> list[list[float]]:
        return _check_scan(v, (2,), "scan")

    @model_validator(mode="after")
    def _one_flag_per_detection(self) -> Truth:
        if len(self.scan_clutter) != len(self.scan):
            raise PydanticCustomError(
                "bad_shape",
                f"scan_clutter has {len(self.scan_clutter)} flags for {len(self.scan)} detections",
            )
        return self


class Transfer(Message):
    """The source's predicted-observation density N(eta, P_eta) for step ``k_apply``, in the
    coordinates of the source's sensor, which ``sensor`` describes (kind, position, noise
    parameters): a primary needs nothing else to use it.

    ``k`` is the source step that produced it. On the paper's shared clock ``k == k_apply - 1``
    and ``t_apply`` is absent. Operators with their own periods or clocks
    (:mod:`tltrack.config.timeline`) stamp it with ``t_apply``: the time of the primary's
    sample ``k_apply`` on the primary's clock, from the episode's start, as its public schedule
    gives it; the primary refuses one that does not name its own sample's time.
    """

    TYPE: ClassVar[str] = "transfer"
    type: Literal["transfer"] = "transfer"
    k_apply: Annotated[int, Field(ge=1, le=MAX_K)]
    t_apply: Annotated[float, Field(allow_inf_nan=False)] | None = None
    sensor: Annotated[SensorSpec, BeforeValidator(_sensor_spec)]
    eta: Vector
    P_eta: Matrix

    @model_validator(mode="after")
    def _consistent(self) -> Transfer:
        if self.t_apply is None and self.k != self.k_apply - 1:
            raise PydanticCustomError(
                "invalid",
                f"k ({self.k}) must be k_apply - 1 ({self.k_apply - 1}), or give t_apply",
            )
        missing = [
            p.name
            for p in self.sensor.declared
            if p.name not in self.sensor.params and p.default is None
        ]
        if missing:  # the primary builds the source's sensor from it: one it cannot default
            raise PydanticCustomError(
                "invalid", f"sensor: a {self.sensor.kind} sensor needs {', '.join(missing)}"
            )
        n_z = self.sensor.n_z
        _check_vector(self.eta, (n_z,), "eta")
        bad = components.first_problem(SENSORS.get(self.sensor.kind).components, self.eta)
        if bad is not None:
            raise PydanticCustomError("out_of_range", f"eta: {bad}")
        _check_covariance(self.P_eta, n_z, "P_eta")
        if any(abs(p) > components.MAX_MAGNITUDE**2 for row in self.P_eta for p in row):
            raise PydanticCustomError("out_of_range", "P_eta has an entry beyond 1e18")
        return self


class EstimateMsg(Message):
    """A filter's posterior mean and covariance at step k, and the position it estimates."""

    TYPE: ClassVar[str] = "estimate"
    type: Literal["estimate"] = "estimate"
    filter: Annotated[str, Field(min_length=1, max_length=64)]
    x: Vector
    pos: Vector
    P: Matrix
    transfer_used: bool
    recovered: bool = False  #: the filter had lost the track and was reinitialised at this step
    t_sent: Timestamp
    step_ms: Annotated[float, Field(ge=0, allow_inf_nan=False)]
    t_received: Timestamp | None = None  #: when the tracker received z_k (the latency's stages)
    t_step: Timestamp | None = None  #: when the step began
    #: the NIS of the filter's own z_k before its update (None: no z_k), the mean over its last
    #: 20 steps (None until 20), and that mean's 99% band (tltrack.filters.consistency)
    nis: Annotated[float, Field(ge=0, allow_inf_nan=False)] | None = None
    nis_window: Annotated[float, Field(ge=0, allow_inf_nan=False)] | None = None
    nis_band: Vector | None = None

    @field_validator("x")
    @classmethod
    def _x_shape(cls, v: list[float]) -> list[float]:
        return _check_position(v, state_sizes(), "x")

    @field_validator("pos")
    @classmethod
    def _pos_shape(cls, v: list[float]) -> list[float]:
        return _check_position(v, (2,), "pos")

    @model_validator(mode="after")
    def _P_ok(self) -> EstimateMsg:
        _check_covariance(self.P, len(self.x), "P")
        if self.nis_band is not None:
            lo, hi = _check_vector(self.nis_band, (2,), "nis_band")
            if not 0 <= lo <= hi:
                raise PydanticCustomError("invalid", "nis_band must be 0 <= low <= high")
        return self


class EpisodeStart(Message):
    """sensor_sim announces an episode: its config (a :class:`tltrack.config.Config` dump),
    run index, number of steps and pace. ``k`` is 0.
    """

    TYPE: ClassVar[str] = "episode_start"
    type: Literal["episode_start"] = "episode_start"
    run: Annotated[int, Field(ge=0, le=MAX_K)]
    config: dict[str, Any]
    K: Annotated[int, Field(ge=1, le=MAX_K)]
    steps_per_sec: Annotated[float, Field(ge=0, allow_inf_nan=False)] = Field(
        description="pace of the sensor stream; 0 means as fast as possible"
    )

    @field_validator("config")
    @classmethod
    def _config_ok(cls, v: dict[str, Any]) -> dict[str, Any]:
        from tltrack.config import Config, describe_validation_error

        if not _all_finite(v):
            raise PydanticCustomError("non_finite", "config holds a NaN or infinity")
        try:  # untrusted: a kind it names must be registered here; nothing is imported
            cfg = Config.model_validate(v, context={"trusted": False})
        except ValidationError as err:
            unknown = any(e["type"] == "unknown_kind" for e in err.errors())
            detail = {"detail": describe_validation_error(err)}
            reason = "unknown_kind" if unknown else "invalid"
            raise PydanticCustomError(reason, "config: {detail}", detail) from None
        return cfg.model_dump(mode="json")  # canonical: presets filled in, tuples as lists

    def parsed_config(self) -> Any:
        """The validated :class:`tltrack.config.Config`."""
        from tltrack.config import make_config

        return make_config(self.config)


class EpisodeEnd(Message):
    """sensor_sim closes an episode after its last step ``k`` (or aborts it)."""

    TYPE: ClassVar[str] = "episode_end"
    type: Literal["episode_end"] = "episode_end"
    reason: Literal["complete", "aborted"] = "complete"
    steps_sent: Annotated[int, Field(ge=0, le=MAX_K)]


class Tick(Message):
    """sensor_sim's world clock: step ``k`` is due, so each operator's sensor publishes its
    measurement of it (the federated topology, where no raw data passes through the referee)."""

    TYPE: ClassVar[str] = "tick"
    type: Literal["tick"] = "tick"


class Schedule(Message):
    """When the primary samples, on its own clock: its sample j at ``t0_s + j period_s`` seconds
    from the episode's start. Public to its sources, who address each transfer to one of these
    times (``Transfer.t_apply``); none of its data."""

    TYPE: ClassVar[str] = "schedule"
    type: Literal["schedule"] = "schedule"
    period_s: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    t0_s: Annotated[float, Field(allow_inf_nan=False)]


#: every message class by its ``type`` tag
MESSAGE_TYPES: dict[str, type[Message]] = {
    m.TYPE: m
    for m in (
        Measurement, Truth, Transfer, EstimateMsg, EpisodeStart, EpisodeEnd, Tick, Schedule
    )
}  # fmt: skip

M = TypeVar("M", bound=Message)


# ---- encode / decode --------------------------------------------------------------------------


def encode(msg: Message) -> bytes:
    """Pack a message as a msgpack map. ``ValueError`` if it exceeds :data:`MAX_PAYLOAD_BYTES`."""
    data = msgpack.packb(msg.model_dump(mode="python"), use_bin_type=True)
    if len(data) > MAX_PAYLOAD_BYTES:
        raise ValueError(f"{type(msg).__name__} encodes to {len(data)} B > {MAX_PAYLOAD_BYTES} B")
    return data


_SCALARS = (str, int, float, bool, type(None))


def _check_plain(obj: Any, depth: int = 0) -> None:
    """Only plain msgpack types (no ext types, no bytes), nested at most MAX_DEPTH."""
    if depth > MAX_DEPTH:
        raise MessageRejected("bad_structure", f"nested deeper than {MAX_DEPTH}")
    if isinstance(obj, _SCALARS):
        return
    if isinstance(obj, list):
        for item in obj:
            _check_plain(item, depth + 1)
        return
    if isinstance(obj, dict):
        for key, item in obj.items():
            if not isinstance(key, str):
                raise MessageRejected("bad_structure", "map key is not a string")
            _check_plain(item, depth + 1)
        return
    raise MessageRejected("bad_structure", f"value of type {type(obj).__name__}")


def _unpack(payload: bytes) -> Any:
    n = len(payload)
    return msgpack.unpackb(
        payload,
        raw=False,
        use_list=True,
        strict_map_key=True,
        max_str_len=min(n, 4096),
        max_bin_len=0,
        max_ext_len=0,
        max_array_len=n,  # a scan's thousands of detections; each entry takes a byte at least
        max_map_len=min(n, 256),
    )


def _reason_of(err: ValidationError) -> tuple[str, str]:
    first = err.errors()[0]
    kind = first["type"]
    loc = ".".join(str(p) for p in first["loc"]) or "(message)"
    detail = f"{loc}: {first['msg']}"
    if kind in REASONS:
        return kind, detail
    if kind == "finite_number":
        return "non_finite", detail
    if kind in ("too_short", "too_long"):
        return "bad_shape", detail
    return "invalid", detail


def decode(
    payload: bytes | bytearray | memoryview, expected_type: type[M] | tuple[type[M], ...]
) -> M:
    """Unpack and validate one ``expected_type`` message (or one of a tuple of types, chosen by
    the type tag); only :class:`MessageRejected` escapes."""
    try:
        return _decode(payload, expected_type)
    except MessageRejected:
        raise
    except Exception as err:  # a bug in a validator must not take a service down
        raise MessageRejected("internal", f"{type(err).__name__}: {err}") from None


def _decode(
    payload: bytes | bytearray | memoryview, expected_type: type[M] | tuple[type[M], ...]
) -> M:
    if not isinstance(payload, bytes | bytearray | memoryview):
        raise MessageRejected("bad_structure", f"payload is {type(payload).__name__}, not bytes")
    n = len(payload)
    if n > MAX_PAYLOAD_BYTES:
        raise MessageRejected("too_large", f"{n} B > {MAX_PAYLOAD_BYTES} B")
    try:
        data = _unpack(bytes(payload))
    except Exception as err:
        raise MessageRejected("not_msgpack", f"{type(err).__name__}: {err}") from None
    if not isinstance(data, dict):
        raise MessageRejected("bad_structure", f"top level is {type(data).__name__}, not a map")
    _check_plain(data)
    version = data.get("schema_version")
    if type(version) is not int or version not in SUPPORTED_VERSIONS:
        raise MessageRejected("unknown_version", f"schema_version {version!r}")
    tag = data.get("type")
    candidates = expected_type if isinstance(expected_type, tuple) else (expected_type,)
    chosen = next((t for t in candidates if tag == t.TYPE), None)
    if chosen is None:
        wanted = " or ".join(repr(t.TYPE) for t in candidates)
        raise MessageRejected("wrong_type", f"type {tag!r}, expected {wanted}")
    try:
        return chosen.model_validate(data, strict=True)
    except ValidationError as err:
        reason, detail = _reason_of(err)
        raise MessageRejected(reason, detail) from None


# ---- reject accounting ------------------------------------------------------------------------


class RejectCounter:
    """Thread-safe counts of rejected payloads per key expression and per reason.

    At most ``max_keys`` distinct keys are tracked; later ones are folded into ``"(other)"`` so a
    sender spraying fresh key names cannot grow it without bound.
    """

    OTHER = "(other)"

    def __init__(self, max_keys: int = 256) -> None:
        self._lock = threading.Lock()
        self._max_keys = max_keys
        self._by_key: dict[str, int] = {}
        self._by_reason: dict[str, int] = {}
        self._by_key_reason: dict[tuple[str, str], int] = {}
        self._total = 0

    def add(self, key: str, reason: str) -> None:
        key = str(key)
        with self._lock:
            if key not in self._by_key and len(self._by_key) >= self._max_keys:
                key = self.OTHER
            self._by_key[key] = self._by_key.get(key, 0) + 1
            self._by_reason[reason] = self._by_reason.get(reason, 0) + 1
            kr = (key, reason)
            self._by_key_reason[kr] = self._by_key_reason.get(kr, 0) + 1
            self._total += 1

    def record(self, key: str, err: MessageRejected) -> None:
        self.add(key, err.reason)

    @property
    def total(self) -> int:
        with self._lock:
            return self._total

    def by_reason(self) -> dict[str, int]:
        with self._lock:
            return dict(self._by_reason)

    def by_key(self) -> dict[str, int]:
        with self._lock:
            return dict(self._by_key)

    def count(self, key: str | None = None, reason: str | None = None) -> int:
        with self._lock:
            if key is None and reason is None:
                return self._total
            if key is None:
                return self._by_reason.get(str(reason), 0)
            if reason is None:
                return self._by_key.get(key, 0)
            return self._by_key_reason.get((key, reason), 0)

    def snapshot(self) -> dict[str, Any]:
        """A plain dict for a stats message: total, by_reason, by_key."""
        with self._lock:
            return {
                "total": self._total,
                "by_reason": dict(self._by_reason),
                "by_key": dict(self._by_key),
            }


def json_object(payload: bytes) -> dict[str, Any]:
    """A JSON object (a service's statistics, the scorer's summary); else :class:`ValueError`,
    saying why, for any payload (json.loads raises RecursionError on deep nesting)."""
    if not isinstance(payload, bytes | bytearray | memoryview):
        raise ValueError(f"payload is {type(payload).__name__}, not bytes")
    try:
        data = json.loads(payload)
    except RecursionError:  # absurdly nested
        raise ValueError("nested too deeply") from None
    if not isinstance(data, dict):
        raise ValueError(f"a JSON {type(data).__name__}, not an object")
    return data


def decode_stats(payload: bytes) -> dict[str, Any]:
    """A service's statistics (JSON, :meth:`~tltrack.live.service.Service.publish_stats`): an
    object of at most :data:`MAX_PAYLOAD_BYTES`; else :class:`ValueError`, saying why."""
    if isinstance(payload, bytes | bytearray | memoryview) and len(payload) > MAX_PAYLOAD_BYTES:
        raise ValueError(f"{len(payload)} B > {MAX_PAYLOAD_BYTES} B")
    return json_object(payload)


def counts(value: Any, limit: int = 256) -> dict[str, int]:
    """The ``{str: whole number >= 0}`` entries of a statistics mapping (``counters``, the
    rejections ``by_key``), at most ``limit``: anything else is left out (not ``True``, not -1)."""
    out: dict[str, int] = {}
    if isinstance(value, dict):
        for key, n in value.items():
            if len(out) >= limit:
                break
            if isinstance(key, str) and type(n) is int and n >= 0:
                out[key[:256]] = n
    return out
