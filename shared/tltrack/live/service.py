"""What every service process shares: settings, a session, a stop flag, a liveliness token, an
inbox, and its statistics.

A service's life: parse settings (environment and flags; a bad one exits with the field named),
open a session with ``with``, subscribe, *then* declare its liveliness token (so anyone who sees it
alive knows its subscriptions are in place), loop on its inbox until SIGTERM/SIGINT, and close
everything on the way out (an unclosed session with a callback subscriber hangs:
docs/background.md, "Zenoh").
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Annotated, Any, Literal, TypeVar

import zenoh
from pydantic import BeforeValidator, Field, ValidationError
from pydantic_settings import BaseSettings, SettingsError
from tltrack.config import describe_validation_error, plugins
from tltrack.live.supervisor import exit_unless_stopped
from tltrack.wire import keys
from tltrack.wire.messages import Message, RejectCounter
from tltrack.wire.transport import (
    Publisher,
    Received,
    Subscriber,
    ZenohSettings,
    declare_token,
    open_session,
    query,
    refusal,
)

log = logging.getLogger(__name__)

LogLevel = Annotated[
    Literal["DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"],
    BeforeValidator(lambda v: v.upper() if isinstance(v, str) else v),
]


class ServiceSettings(BaseSettings):
    """The settings every service has beside its own; each subclass sets its environment prefix.

    The level is checked here, so a misspelt one is refused with the field named instead of
    failing inside :mod:`logging` after start."""

    log_level: LogLevel = Field("INFO", description="least severe level logged (any case)")
    zenoh: ZenohSettings = Field(default_factory=ZenohSettings)


S = TypeVar("S", bound=BaseSettings)
#: how often a service publishes its statistics (the dashboard's health panel, the demo's bar) [s]
STATS_EVERY_S = 1.0


def load_settings(cls: type[S], argv: list[str] | None = None) -> S:
    """Settings from the environment and ``--flags``, once the plugin kinds this process is told
    of are loaded (:mod:`tltrack.config.plugins`); exits with status 2 naming a bad field."""
    try:
        plugins.load()
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        raise SystemExit(2) from None
    except Exception as err:  # a plugin module that fails as it is imported
        print(f"error: a plugin (TLTRACK_PLUGINS) failed to import: {err!r}", file=sys.stderr)
        raise SystemExit(2) from None
    for name in _unknown_variables(cls):
        print(f"warning: {name} is no setting of this service; ignored", file=sys.stderr)
    args = sys.argv[1:] if argv is None else argv
    if empty := _empty_flags(args):
        print(
            f"error: invalid settings for {cls.__name__}: {', '.join(empty)} given an empty "
            "value (leave a flag out for its default)",
            file=sys.stderr,
        )
        raise SystemExit(2)
    try:
        return cls(_cli_parse_args=args)
    except ValidationError as err:
        print(
            f"error: invalid settings for {cls.__name__}: {describe_validation_error(err)}",
            file=sys.stderr,
        )
        raise SystemExit(2) from None
    except SettingsError as err:  # a value that is not the JSON its field needs ('[bad')
        cause = f": {err.__cause__}" if err.__cause__ else ""
        print(f"error: invalid settings for {cls.__name__}: {err}{cause}", file=sys.stderr)
        raise SystemExit(2) from None


def _unknown_variables(cls: type[BaseSettings]) -> list[str]:
    """The environment's variables under the prefix of ``cls`` or of its zenoh settings that
    name no field: a misspelt one would be ignored in silence."""
    unknown: set[str] = set()
    for settings in (cls, ZenohSettings):
        prefix = str(settings.model_config.get("env_prefix") or "").upper()
        known = {prefix + name.upper() for name in settings.model_fields}
        if prefix:
            unknown |= {v for v in os.environ if v.upper().startswith(prefix)} - known
    return sorted(unknown)


def _empty_flags(args: list[str]) -> list[str]:
    """The flags given ``''``: the settings drop an empty value, as they do an empty variable
    of the environment, and would run on the default in silence."""
    empty = []
    for i, arg in enumerate(args):
        flag, eq, value = arg.partition("=")
        if not flag.startswith("--"):
            continue
        if (eq and not value) or (not eq and i + 1 < len(args) and args[i + 1] == ""):
            empty.append(flag)
    return empty


def setup_logging(level: LogLevel = "INFO") -> None:
    logging.basicConfig(
        level=level,
        stream=sys.stderr,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )


class Service:
    """The plumbing of one service; use as ``with Service(...) as svc:``."""

    def __init__(self, name: str, operator: str, zenoh_settings: ZenohSettings) -> None:
        self.name, self.operator = name, operator
        self.stop = threading.Event()
        self.rejects = RejectCounter()
        self.counters: dict[str, int] = {}
        #: what a service adds to its statistics beside the counters (the primary: its links)
        self.status: dict[str, Any] = {}
        self._zenoh = zenoh_settings
        self._subs: list[Subscriber] = []
        self._pubs: dict[str, Publisher] = {}
        self._token: Any = None
        self._stats_pub: Publisher | None = None
        self._last_stats = 0.0

    def __enter__(self) -> Service:
        # Until its router answers, zenoh.open blocks in native code, where no Python handler
        # runs: a stop signal then ends the process at once (there is nothing to close yet).
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, signal.SIG_DFL)
        self._exit = contextlib.ExitStack()
        try:
            self.session: zenoh.Session = self._exit.enter_context(open_session(self._zenoh))
        except zenoh.ZError as err:  # no router within connect_timeout_ms, a TLS file zenoh refuses
            where = ", ".join(self._zenoh.endpoints)
            log.error("%s: no zenoh session with %s: %s", self.name, where, refusal(err))
            raise SystemExit(1) from None
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self._on_signal)
        self._stats_pub = Publisher(self.session, keys.stats(self.operator, self.name))
        log.info("%s: session open (%s)", self.name, ", ".join(self._zenoh.endpoints))
        return self

    def _on_signal(self, signum: int, _frame: FrameType | None) -> None:
        log.info("%s: signal %d, stopping", self.name, signum)
        if not self.stop.is_set():
            exit_unless_stopped(signum)
        self.stop.set()

    def subscribe(self, *key_exprs: str, liveliness: bool = False) -> Subscriber:
        """One inbox for all ``key_exprs``: samples arrive in one queue, in arrival order."""
        sub = Subscriber(
            self.session,
            list(key_exprs),
            liveliness=liveliness,
            history=liveliness,
            rejects=self.rejects,
        )
        self._subs.append(sub)
        return sub

    def running_episodes(self) -> list[Received]:
        """The EpisodeStart of every episode under way, from sensor_sim's queryables: a service
        that (re)starts mid-episode joins it instead of sitting it out."""
        return query(self.session, keys.EPISODES, timeout=2.0)

    def announce(self) -> None:
        """Declare the liveliness token; call it once every subscription is in place."""
        self._token = declare_token(self.session, keys.alive(self.operator, self.name))

    def publish(self, key: str, msg: Message | Callable[[], Message]) -> None:
        """Publish ``msg`` (or what ``msg()`` builds); a message that cannot be built or sent is
        counted and logged: one bad estimate must not take the service down."""
        try:
            message = msg() if callable(msg) else msg
            pub = self._pubs.get(key)
            if pub is None:  # express: one message a step has nothing to batch with, so send now
                pub = self._pubs[key] = Publisher(self.session, key, express=True)
            pub.put(message)
        except (ValidationError, ValueError, zenoh.ZError) as err:
            self.count("publish_failed")
            log.error("%s: could not publish on %s: %s", self.name, key, err)

    def key_info(self, item: Received) -> keys.KeyInfo | None:
        """What the sample's key names; a key outside the layout is counted as rejected."""
        try:
            return keys.parse(item.key)
        except ValueError:
            self.rejects.add(item.key, "bad_key")
            return None

    def count(self, what: str) -> None:
        self.counters[what] = self.counters.get(what, 0) + 1

    def stats(self) -> dict[str, Any]:
        return {
            "service": self.name,
            "operator": self.operator,
            "t": time.time(),
            "counters": dict(self.counters),
            "rejected": self.rejects.snapshot(),
            "dropped": sum(s.dropped for s in self._subs),
            **self.status,
        }

    def publish_stats(self, force: bool = False) -> None:
        """Publish :meth:`stats` as JSON at most once per :data:`STATS_EVERY_S` (``force``: now)."""
        now = time.monotonic()
        if self._stats_pub is not None and (force or now - self._last_stats >= STATS_EVERY_S):
            self._stats_pub.put(json.dumps(self.stats()).encode())
            self._last_stats = now

    def drain(self, sub: Subscriber, timeout: float) -> Iterator[Received]:
        """Wait up to ``timeout`` for a sample, then yield it and everything queued behind it."""
        first = sub.recv(timeout)
        if first is not None:
            yield first
            yield from sub.drain()

    def __exit__(self, *exc: object) -> None:
        with contextlib.suppress(Exception):
            self.publish_stats(force=True)
        if self._token is not None:
            with contextlib.suppress(Exception):
                self._token.undeclare()
        for s in self._subs:
            s.close()
        for p in [*self._pubs.values(), *([self._stats_pub] if self._stats_pub else [])]:
            p.close()
        self._exit.close()
        log.info("%s: session closed", self.name)
