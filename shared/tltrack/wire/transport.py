"""Zenoh plumbing: settings, sessions, queued subscribers, blocking publishers, liveliness.

All services talk through Python-hosted routers (``tltrack router``, :mod:`tltrack.live.router`);
docs/background.md, section "Zenoh", lists the measured behaviour this module relies on:

- clients connect to explicit endpoints with ``connect/timeout_ms: -1`` (wait for the router) and
  multicast scouting off (it does not cross container boundaries);
- a slow Python callback delays the session's other subscribers, so :class:`Subscriber`'s callback
  only appends the payload to a bounded queue and the service thread does the work;
- DROP congestion control lost ~10 % at saturation, so :class:`Publisher` uses BLOCK;
- a process that exits without closing a session that holds a callback subscriber hangs: always
  ``with open_session(...) as session:``;
- the link lease (2 s here) bounds how long a *hung* peer's liveliness token survives.
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import zenoh
from pydantic import (
    Field,
    FilePath,
    SecretStr,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict
from tltrack.wire.messages import (
    MAX_PAYLOAD_BYTES,
    Message,
    MessageRejected,
    RejectCounter,
    decode,
    encode,
)

log = logging.getLogger(__name__)

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"

M = TypeVar("M", bound=Message)


# ---- settings ---------------------------------------------------------------------------------


def split_list(v: Any) -> Any:
    """From the environment: a JSON list (``["tcp/a:1"]``) or ``tcp/a:1,tcp/b:2``."""
    if isinstance(v, str):
        text = v.strip()
        if text.startswith("["):
            return json.loads(text)
        return [part.strip() for part in text.split(",") if part.strip()]
    return v


#: zenoh's link protocols whose address is host:port, and the others
HOST_PORT_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
PROTOCOLS = (*HOST_PORT_PROTOCOLS, "unixsock-stream", "unixpipe", "serial", "vsock")


def check_endpoint(endpoint: str) -> str:
    """``endpoint``, or ``ValueError`` saying what is wrong with it. Zenoh refuses a malformed
    endpoint only as a session opens, with a traceback, and a client dials one of an unknown
    protocol, or whose port is not a number, for ever: all are caught here, at start."""
    locator = endpoint.split("#", 1)[0].split("?", 1)[0]
    protocol, _, address = locator.partition("/")
    if not protocol or not address:
        raise ValueError(f"{endpoint!r} is not <protocol>/<address>, e.g. {DEFAULT_ENDPOINT}")
    if protocol not in PROTOCOLS:
        known = ", ".join(PROTOCOLS)
        raise ValueError(f"{endpoint!r}: zenoh has no protocol {protocol!r} ({known})")
    if protocol in HOST_PORT_PROTOCOLS:
        host, _, port = address.rpartition(":")
        if not host or not port.isdigit() or int(port) > 65535:
            raise ValueError(f"{endpoint!r}: its address must be host:port, the port 0-65535")
    return endpoint


def refusal(err: zenoh.ZError) -> str:
    """What zenoh says of a configuration it refuses, without the Rust source locations."""
    said = re.search(r'msg: "(.*?)(?: at /[^"]*)?"', str(err))
    text = said.group(1).replace("\\n", " ") if said else str(err)
    text = re.sub(r"\s+at /\S+\.rs:\d+\.?", "", text)  # zenoh's own source, line by line
    return f"zenoh refuses it: {' '.join(text.split())}"


class ZenohSettings(BaseSettings):
    """How a service reaches the Zenoh network. Every field reads ``TLTRACK_ZENOH_<FIELD>``.

    Security (all optional; the router and its clients must agree):

    - user/password: clients set ``username`` and ``password``; the router sets
      ``usrpwd_dictionary_file`` (lines ``user:password``);
    - TLS: endpoints ``tls/host:port``, ``tls_root_ca`` on both sides; the router sets ``tls_cert``
      and ``tls_key``; with ``tls_mtls`` clients present their own ``tls_cert``/``tls_key`` too;
    - access control: ``access_control_file``, a JSON5 object for the router's ``access_control``
      section (rules, subjects, policies).
    """

    model_config = SettingsConfigDict(
        env_prefix="TLTRACK_ZENOH_", extra="forbid", env_ignore_empty=True
    )

    mode: Literal["client", "peer", "router"] = "client"
    endpoints: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: [DEFAULT_ENDPOINT], description="endpoints to connect to"
    )
    listen: Annotated[list[str], NoDecode] = Field(
        default_factory=list, description="endpoints to listen on (router, peer)"
    )
    #: -1: a client waits for its router forever
    connect_timeout_ms: Annotated[int, Field(ge=-1)] = -1
    #: link lease: a hung peer is declared dead (its tokens dropped) after this long
    lease_ms: Annotated[int, Field(ge=500, le=600_000)] = 2000
    keep_alive: Annotated[int, Field(ge=1, le=100)] = 4  #: keep-alives sent per lease
    username: str | None = None  #: a client's login, with ``password``
    password: SecretStr | None = None
    #: a router's logins, ``user:password`` a line (a file that must exist, as every file here)
    usrpwd_dictionary_file: FilePath | None = None
    tls_root_ca: FilePath | None = None  #: the CA certificate (PEM) that signs the routers'
    tls_cert: FilePath | None = None  #: this side's certificate (PEM), with ``tls_key``
    tls_key: FilePath | None = None
    tls_mtls: bool = False  #: clients present a certificate too
    tls_verify_name: bool = True  #: a client checks the router's name in its certificate
    access_control_file: FilePath | None = None  #: a router's ``access_control`` section (JSON5)

    @field_validator("endpoints", "listen", mode="before")
    @classmethod
    def _lists(cls, v: Any) -> Any:
        return split_list(v)

    @field_validator("endpoints", "listen")
    @classmethod
    def _endpoints(cls, v: list[str]) -> list[str]:
        return [check_endpoint(e) for e in v]

    @field_validator("tls_root_ca", "tls_cert", "tls_key")
    @classmethod
    def _pem(cls, v: Path | None, info: ValidationInfo) -> Path | None:
        """A PEM file of what the field needs: zenoh reads it only as a link opens, and a client
        given another file retried its router for ever, saying nothing."""
        want = "PRIVATE KEY-----" if info.field_name == "tls_key" else "BEGIN CERTIFICATE-----"
        if v is not None and want not in v.read_bytes().decode("ascii", "replace"):
            kind = "private key" if info.field_name == "tls_key" else "certificate"
            raise ValueError(f"{v} holds no PEM {kind}")
        return v

    @model_validator(mode="after")
    def _consistent(self) -> ZenohSettings:
        if (self.username is None) != (self.password is None):
            raise ValueError("username and password must be given together")
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ValueError("tls_cert and tls_key must be given together")
        if self.tls_mtls and (self.tls_cert is None or self.tls_root_ca is None):
            raise ValueError("tls_mtls needs tls_root_ca, tls_cert and tls_key")
        if self.mode == "client" and not self.endpoints:
            raise ValueError("a client needs at least one endpoint to connect to")
        try:  # what zenoh alone knows to refuse (an access control file it cannot parse)
            self.to_config()
        except zenoh.ZError as err:
            raise ValueError(refusal(err)) from None
        return self

    def entries(self) -> list[tuple[str, str]]:
        """The zenoh configuration as ``(path, JSON5 value)`` pairs (keys of zenoh's
        DEFAULT_CONFIG.json5): :meth:`to_config` and :meth:`to_json5` both write these, so a
        session opened here and a config file for another Zenoh tool say the same."""
        out: list[tuple[str, str]] = []

        def put(key: str, value: Any) -> None:
            out.append((key, json.dumps(value)))

        put("mode", self.mode)
        put("scouting/multicast/enabled", False)
        # routers link only where configured (tltrack.live.topology): no router learns of another
        # through a third, so none can route one operator's traffic through a neighbour's host
        put("scouting/gossip/enabled", False)
        put("connect/endpoints", list(self.endpoints))
        put("listen/endpoints", list(self.listen))
        if self.mode == "client":
            put("connect/timeout_ms", self.connect_timeout_ms)
        else:  # a router redials a lost neighbour every second at most
            put("connect/retry", {"period_max_ms": 1000})
        put("transport/link/tx/lease", self.lease_ms)
        put("transport/link/tx/keep_alive", self.keep_alive)
        if self.username is not None and self.password is not None:
            put("transport/auth/usrpwd/user", self.username)
            put("transport/auth/usrpwd/password", self.password.get_secret_value())
        if self.usrpwd_dictionary_file is not None:
            put("transport/auth/usrpwd/dictionary_file", str(self.usrpwd_dictionary_file))
        tls = "transport/link/tls"
        if self.tls_root_ca is not None:
            put(f"{tls}/root_ca_certificate", str(self.tls_root_ca))
        if self.tls_cert is not None and self.tls_key is not None:
            # One identity for both directions: a router listens with it, an mTLS client
            # connects with it, a peer does both.
            for side in ("listen", "connect"):
                put(f"{tls}/{side}_certificate", str(self.tls_cert))
                put(f"{tls}/{side}_private_key", str(self.tls_key))
        if self.tls_mtls:
            put(f"{tls}/enable_mtls", True)
        if any(e.startswith("tls/") for e in self.endpoints) or self.tls_root_ca is not None:
            put(f"{tls}/verify_name_on_connect", self.tls_verify_name)
        if self.access_control_file is not None:
            try:
                out.append(("access_control", self.access_control_file.read_text()))
            except UnicodeDecodeError:
                raise ValueError(
                    f"access_control_file {self.access_control_file}: not UTF-8 text (JSON5)"
                ) from None
        return out

    def to_config(self) -> zenoh.Config:
        """The zenoh configuration of :meth:`entries`."""
        cfg = zenoh.Config()
        for key, value in self.entries():
            cfg.insert_json5(key, value)
        return cfg

    def to_json5(self) -> str:
        """:meth:`entries` as the text of a zenoh config file (``zenoh.Config.from_file``), each
        value as zenoh itself parsed it."""
        cfg = self.to_config()
        tree: dict[str, Any] = {}
        for key, _ in self.entries():
            *parents, leaf = key.split("/")
            node = tree
            for part in parents:
                node = node.setdefault(part, {})
            node[leaf] = json.loads(cfg.get_json(key))
        return json.dumps(tree, indent=2) + "\n"


def open_session(settings: ZenohSettings) -> zenoh.Session:
    """Open a session; use it as ``with open_session(s) as session:`` so it is always closed.

    A client with ``connect_timeout_ms == -1`` blocks here until its router is reachable.
    """
    return zenoh.open(settings.to_config())


# ---- subscribing ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Received:
    """One sample as handed to the service thread."""

    key: str
    payload: bytes
    kind: zenoh.SampleKind
    t_recv: float  #: time.time() when the callback queued it

    @property
    def is_put(self) -> bool:
        return self.kind == zenoh.SampleKind.PUT


class _BoundedQueue:
    """A deque with a capacity that drops the *oldest* item when full, counting drops."""

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError("capacity must be >= 1")
        self._items: deque[Received] = deque()
        self._capacity = capacity
        self._cv = threading.Condition()
        self._closed = False
        self.received = 0
        self.dropped = 0

    def push(self, item: Received) -> None:
        with self._cv:
            if self._closed:
                return
            if len(self._items) >= self._capacity:
                self._items.popleft()
                self.dropped += 1
            self._items.append(item)
            self.received += 1
            self._cv.notify()

    def pop(self, timeout: float | None) -> Received | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cv:
            while not self._items:
                if self._closed:
                    return None
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return None
                self._cv.wait(remaining)
            return self._items.popleft()

    def drain(self) -> list[Received]:
        with self._cv:
            items = list(self._items)
            self._items.clear()
            return items

    def close(self) -> None:
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    def __len__(self) -> int:
        with self._cv:
            return len(self._items)


class Subscriber:
    """Subscribes to one or more key expressions and queues their samples for the caller's thread.

    All ``key_exprs`` feed one inbox, in arrival order. The zenoh callback only copies the payload
    into a bounded queue (``capacity`` items); when the queue is full the oldest sample is dropped
    and :attr:`dropped` counts it, so a slow consumer never blocks the session's other
    subscribers. ``liveliness=True`` subscribes to liveliness tokens instead (PUT = appeared,
    DELETE = gone; ``history=True`` also reports tokens already alive).
    """

    def __init__(
        self,
        session: zenoh.Session,
        key_exprs: str | Sequence[str],
        capacity: int = 4096,
        *,
        liveliness: bool = False,
        history: bool = False,
        rejects: RejectCounter | None = None,
    ) -> None:
        self.rejects = rejects
        self.key_exprs: tuple[str, ...] = (
            (key_exprs,) if isinstance(key_exprs, str) else tuple(key_exprs)
        )
        if not self.key_exprs:
            raise ValueError("no key expression to subscribe to")
        self._queue = _BoundedQueue(capacity)
        self._subs: list[zenoh.Subscriber[None]] = []
        try:
            for key in self.key_exprs:
                if liveliness:
                    sub = session.liveliness().declare_subscriber(
                        key, self._on_sample, history=history
                    )
                else:
                    # indirect=False: zenoh calls back on its own thread, in arrival order across
                    # all the keys, instead of one thread per subscription.
                    handler = zenoh.handlers.Callback(self._on_sample, indirect=False)
                    sub = session.declare_subscriber(key, handler)
                self._subs.append(sub)
        except BaseException:
            self.close()
            raise

    def _on_sample(self, sample: zenoh.Sample) -> None:
        """Queue the sample; one too large to be any message is refused before it is copied."""
        key = str(sample.key_expr)
        if len(sample.payload) > MAX_PAYLOAD_BYTES:
            if self.rejects is not None:
                self.rejects.add(key, "too_large")
            return
        self._queue.push(Received(key, sample.payload.to_bytes(), sample.kind, time.time()))

    def recv(self, timeout: float | None = None) -> Received | None:
        """The next sample, waiting up to ``timeout`` s (forever if None); None on timeout/close."""
        return self._queue.pop(timeout)

    def drain(self) -> list[Received]:
        """Everything queued now, without waiting."""
        return self._queue.drain()

    def recv_message(
        self,
        expected_type: type[M],
        timeout: float | None = None,
        rejects: RejectCounter | None = None,
    ) -> tuple[Received, M] | None:
        """The next sample that decodes as ``expected_type``; rejected ones are counted, skipped.

        Returns None when ``timeout`` expires (or the subscriber is closed) first.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            item = self._queue.pop(remaining)
            if item is None:
                return None
            msg = decode_received(item, expected_type, rejects)
            if msg is not None:
                return item, msg

    @property
    def received(self) -> int:
        return self._queue.received

    @property
    def dropped(self) -> int:
        return self._queue.dropped

    def __len__(self) -> int:
        return len(self._queue)

    def close(self) -> None:
        self._queue.close()
        for sub in self._subs:
            with contextlib.suppress(Exception):  # already undeclared with its closed session
                sub.undeclare()
        self._subs.clear()

    def __enter__(self) -> Subscriber:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


def decode_received(
    item: Received,
    expected_type: type[M] | tuple[type[M], ...],
    rejects: RejectCounter | None = None,
) -> M | None:
    """Decode a queued sample; on rejection log it, count it under its key and return None."""
    if not item.is_put:
        return None
    try:
        msg = decode(item.payload, expected_type)
    except MessageRejected as err:
        if rejects is not None:
            rejects.record(item.key, err)
        log.warning("rejected a payload on %s: %s", item.key, err)
        return None
    msg.received(item.t_recv)
    return msg


# ---- publishing -------------------------------------------------------------------------------


class Publisher:
    """Publishes messages on one key with congestion control BLOCK (no silent loss)."""

    def __init__(
        self,
        session: zenoh.Session,
        key_expr: str,
        *,
        block: bool = True,
        express: bool = False,
    ) -> None:
        self.key_expr = key_expr
        cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        self._pub = session.declare_publisher(key_expr, congestion_control=cc, express=express)
        self.sent = 0

    def put(self, msg: Message | bytes) -> int:
        """Encode (if a message) and publish; returns the payload size in bytes."""
        data = msg if isinstance(msg, bytes) else encode(msg)
        self._pub.put(data)
        self.sent += 1
        return len(data)

    @property
    def has_subscribers(self) -> bool:
        status: Any = self._pub.matching_status  # the stub says bool; 1.10.2 returns an object
        return bool(getattr(status, "matching", status))

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait until some subscriber matches the key (up to ``timeout`` s)."""
        deadline = time.monotonic() + timeout
        while not self.has_subscribers:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.01)
        return True

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._pub.undeclare()

    def __enter__(self) -> Publisher:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


# ---- queries ----------------------------------------------------------------------------------


class Queryable:
    """Answers gets on the concrete key ``key_expr`` with ``answer(selector_parameters) -> bytes``.

    ``answer`` runs in zenoh's callback thread, so it must be quick (e.g. encode a snapshot the
    service keeps up to date). If it raises, the querier gets a reply error instead. Replies go
    out on ``key_expr`` itself (a query's own key may be a glob such as ``tltrack/scorer/*``),
    and every query is dropped explicitly so the querier's ``get`` finishes at once.
    """

    def __init__(
        self,
        session: zenoh.Session,
        key_expr: str,
        answer: Callable[[dict[str, str]], bytes],
    ) -> None:
        if "*" in key_expr or "$" in key_expr:
            raise ValueError(f"a Queryable needs a concrete key, not {key_expr!r}")
        self.key_expr = key_expr
        self._answer = answer
        self.served = 0
        self.failed = 0
        self._q = session.declare_queryable(key_expr, self._on_query)

    def _on_query(self, query: zenoh.Query) -> None:
        with query:  # drop() on exit: finalizes the query on the querier's side
            try:
                params: dict[str, str] = dict(list(query.parameters))  # type: ignore[call-overload]
                payload = self._answer(params)
            except Exception as err:
                self.failed += 1
                log.exception("queryable %s failed", self.key_expr)
                with contextlib.suppress(Exception):
                    query.reply_err(f"{type(err).__name__}: {err}".encode())
                return
            query.reply(self.key_expr, payload)
            self.served += 1

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._q.undeclare()

    def __enter__(self) -> Queryable:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


def query(session: zenoh.Session, selector: str, timeout: float = 5.0) -> list[Received]:
    """Get from every matching queryable; returns the OK replies (errors are logged)."""
    out: list[Received] = []
    for reply in session.get(selector, timeout=timeout):
        sample = reply.ok
        if sample is not None:
            out.append(
                Received(str(sample.key_expr), sample.payload.to_bytes(), sample.kind, time.time())
            )
        elif reply.err is not None:
            log.warning("query %s: error reply %r", selector, reply.err.payload.to_bytes())
    return out


# ---- liveliness -------------------------------------------------------------------------------


def declare_token(session: zenoh.Session, key: str) -> zenoh.LivelinessToken:
    """Announce this service as alive on ``key`` until the token or the session is dropped.

    Keep the returned token referenced (``with declare_token(...):`` or an attribute).
    """
    return session.liveliness().declare_token(key)


class LivelinessWatcher:
    """Tracks which liveliness tokens matching ``pattern`` are alive (history included).

    ``on_change(key, alive)`` is called from zenoh's callback thread on every change; keep it
    quick. A killed holder disappears within milliseconds; a hung one after the link lease.
    """

    def __init__(
        self,
        session: zenoh.Session,
        pattern: str,
        on_change: Callable[[str, bool], None] | None = None,
    ) -> None:
        self.pattern = pattern
        self._alive: set[str] = set()
        self._cv = threading.Condition()
        self._on_change = on_change
        self._sub = session.liveliness().declare_subscriber(pattern, self._on_sample, history=True)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        up = sample.kind == zenoh.SampleKind.PUT
        with self._cv:
            changed = (key in self._alive) != up
            if up:
                self._alive.add(key)
            else:
                self._alive.discard(key)
            self._cv.notify_all()
        if changed and self._on_change is not None:
            try:
                self._on_change(key, up)
            except Exception:
                log.exception("liveliness on_change callback failed")

    def alive(self) -> frozenset[str]:
        with self._cv:
            return frozenset(self._alive)

    def wait_until(self, key: str, alive: bool = True, timeout: float | None = None) -> bool:
        """Wait until ``key`` is (or is no longer) alive; False on timeout."""
        with self._cv:
            return self._cv.wait_for(lambda: (key in self._alive) == alive, timeout)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._sub.undeclare()

    def __enter__(self) -> LivelinessWatcher:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


# ---- router -----------------------------------------------------------------------------------
