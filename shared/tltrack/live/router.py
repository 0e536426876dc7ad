"""A Zenoh router as a process (``tltrack router``), or in a thread for tests and demos.

The Python package runs a router by itself (``mode: "router"``): no zenohd is needed
(docs/background.md, "Zenoh"). A stop signal closes it within the supervisor's grace
(:func:`~tltrack.live.supervisor.exit_unless_stopped`).
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

import zenoh
from tltrack.live.supervisor import exit_unless_stopped
from tltrack.wire.transport import ZenohSettings

log = logging.getLogger(__name__)


def router_settings(
    listen: list[str], settings: ZenohSettings | None = None, connect: list[str] | None = None
) -> ZenohSettings:
    """``settings`` (its security options) as a router's on ``listen``, meshed with ``connect``:
    validated again, as ``model_copy`` would not, so a bad endpoint is refused here
    (``ValueError``) rather than by zenoh as the session opens."""
    if not listen:
        raise ValueError("a router needs at least one listen endpoint")
    base = (settings or ZenohSettings()).model_dump()
    update = {"mode": "router", "listen": list(listen), "endpoints": list(connect or [])}
    return ZenohSettings.model_validate(base | update)


def run_router(
    listen: list[str],
    settings: ZenohSettings | None = None,
    *,
    connect: list[str] | None = None,
    stop: threading.Event | None = None,
    on_ready: Callable[[zenoh.Session], None] | None = None,
    announce: bool = True,
) -> None:
    """Run a Zenoh router on ``listen`` until SIGINT/SIGTERM (or ``stop`` is set), then close it.

    ``settings`` supplies security options (TLS, user/password dictionary, access control); its
    mode and endpoints are replaced. ``connect`` lists other routers to mesh with. With
    ``announce`` a line ``tltrack router <zid> listening on <endpoints>`` goes to stdout once the
    router is listening. Signal handlers are installed only when called from the main thread.
    """
    cfg = router_settings(listen, settings, connect)
    stop = stop or threading.Event()

    previous: dict[signal.Signals, Any] = {}
    if threading.current_thread() is threading.main_thread():

        def _handler(signum: int, _frame: FrameType | None) -> None:
            if not stop.is_set():
                exit_unless_stopped(signum)
            stop.set()

        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, _handler)
    try:
        with zenoh.open(cfg.to_config()) as session:
            if announce:
                print(
                    f"tltrack router {session.zid()} listening on {', '.join(listen)}", flush=True
                )
            if on_ready is not None:
                on_ready(session)
            while not stop.wait(0.2):
                pass
            log.info("router stopping")
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@contextlib.contextmanager
def background_router(listen: list[str], settings: ZenohSettings | None = None) -> Iterator[None]:
    """Run :func:`run_router` in a thread for the duration of a ``with`` block (tests, demos)."""
    stop = threading.Event()
    ready = threading.Event()
    errors: list[BaseException] = []

    def target() -> None:
        try:
            run_router(listen, settings, stop=stop, on_ready=lambda _s: ready.set(), announce=False)
        except BaseException as err:
            errors.append(err)
            ready.set()

    thread = threading.Thread(target=target, name="tltrack-router", daemon=True)
    thread.start()
    ready.wait()
    if errors:
        raise errors[0]
    try:
        yield
    finally:
        stop.set()
        thread.join(timeout=10)
