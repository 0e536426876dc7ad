"""The zenoh-cli decoder: ``zenoh subscribe -k 'tltrack/...' --decoder tltrack`` prints each
message as one line of JSON, and says why a service would refuse one.

zenoh-cli is how people look at Zenoh traffic, and a tltrack payload is msgpack, which it prints
as base64. This decoder, registered in zenoh-cli's entry-point group
``zenoh_cli.codecs.decoders`` (installed with ``pip install 'tltrack[cli]'``), reads a payload as
the services do: the key names the message it must hold (:func:`tltrack.wire.keys.parse`), the
wire format validates it (:func:`tltrack.wire.messages.decode`) and the key's owner must be its
sender (:func:`tltrack.wire.admission.refusal`). So what it prints is what a service would take,
or the reason code and detail that service would count, not a second opinion.

One line per sample, for ``jq`` and notebooks::

    {"key": ..., "kind": "transfer", "k": 3, "k_apply": 4, "t_sensor": ..., "fields": {...}}
    {"key": ..., "kind": "transfer", ..., "refused": "wrong_sender", "detail": ..., "fields": ...}
    {"key": ..., "refused": "not_msgpack", "detail": ..., "expected": "transfer"}
    {"key": "demo/x", "refused": "bad_key", "detail": "not a tltrack key: 'demo/x'"}

``fields`` is every field of the message, arrays as lists; a statistics key's JSON is passed
through as ``fields``. The decoder never raises: zenoh-cli would log a traceback and drop the
sample, and a sample nobody can read is exactly the one worth seeing.
"""

from __future__ import annotations

import json
from typing import Any

from tltrack.wire import admission, keys
from tltrack.wire.messages import (
    EpisodeEnd,
    EpisodeStart,
    EstimateMsg,
    Measurement,
    Message,
    MessageRejected,
    Schedule,
    Tick,
    Transfer,
    Truth,
    decode_stats,
    json_object,
)
from tltrack.wire.messages import decode as decode_message

#: the messages a key of each kind holds
EXPECTED: dict[str, tuple[type[Message], ...]] = {
    "episode": (EpisodeStart, EpisodeEnd),
    "truth": (Truth,),
    "clock": (Tick,),
    "primary_meas": (Measurement,),
    "source_meas": (Measurement,),
    "transfer": (Transfer,),
    "source_estimate": (EstimateMsg,),
    "primary_estimate": (EstimateMsg,),
    "schedule": (Schedule,),
}


def decode(key: Any, value: bytes) -> str:
    """One line of JSON about the sample ``value`` on ``key`` (zenoh-cli passes the sample's
    KeyExpr: any object whose ``str`` is the key)."""
    try:
        return json.dumps(describe(str(key), value))
    except Exception as err:  # a bug here: still a line, and the next sample still decoded
        return json.dumps({"refused": "internal", "detail": f"{type(err).__name__}: {err}"})


def describe(key: str, value: bytes) -> dict[str, Any]:
    """What :func:`decode` prints, as a dict."""
    try:
        info = keys.parse(key)
    except ValueError as err:  # what a service counts it as (tltrack.live.service)
        return {"key": key, "refused": "bad_key", "detail": str(err)}
    if info.kind in ("stats", "scorer_summary"):
        return _json(key, info.kind, value)
    if info.kind == "heartbeat":  # an empty put, as the primary takes it (tltrack.live.heartbeat)
        if value:
            return {"key": key, "refused": "invalid", "detail": "a heartbeat carries nothing"}
        return {"key": key, "kind": "heartbeat"}
    expected = EXPECTED.get(info.kind)
    if expected is None:  # a liveliness token's key: `zenoh liveliness sub` watches those
        return {"key": key, "kind": info.kind, "detail": "a liveliness key carries no message"}
    try:
        msg = decode_message(value, expected)
    except MessageRejected as err:
        wanted = " or ".join(t.TYPE for t in expected)
        return {"key": key, "refused": err.reason, "detail": err.detail, "expected": wanted}
    out: dict[str, Any] = {"key": key, "kind": msg.TYPE, "k": msg.k}
    if isinstance(msg, Transfer):
        out["k_apply"] = msg.k_apply
    out["t_sensor"] = msg.t_sensor
    if refused := admission.refusal(info, msg):
        out["refused"], out["detail"] = refused
    out["fields"] = msg.model_dump(mode="json")
    return out


def _json(key: str, kind: str, value: bytes) -> dict[str, Any]:
    """A service's statistics (an object, as the scorer and the dashboard take them), or the
    scorer's summary (a get's reply), passed through."""
    try:
        data = decode_stats(value) if kind == "stats" else json_object(value)  # the summary
    except ValueError as err:
        reason = "bad_stats" if kind == "stats" else "not_json"
        return {"key": key, "refused": reason, "detail": f"{type(err).__name__}: {err}"}
    return {"key": key, "kind": kind, "fields": data}
