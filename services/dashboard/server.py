"""The dashboard service: the Zenoh loop in the main thread, the web server beside it.

The page is bound first and the liveliness token declared last, once every subscription is in
place, so whoever sees ``dashboard`` alive (sensor_sim can wait for it) can open the page and the
dashboard will not miss the episode's first step.
"""

from __future__ import annotations

import logging

from tltrack.live.service import Service, load_settings, setup_logging
from tltrack.services.dashboard.ingest import Ingest
from tltrack.services.dashboard.metrics import Metrics
from tltrack.services.dashboard.settings import NAME, Settings
from tltrack.services.dashboard.state import State
from tltrack.services.dashboard.web import WebServer, create_app
from tltrack.wire import keys

log = logging.getLogger("dashboard")


def main(argv: list[str] | None = None) -> None:
    settings = load_settings(Settings, argv)
    setup_logging(settings.log_level)
    state = State(
        settings.max_episodes,
        settings.max_steps,
        settings.max_filters,
        settings.max_points,
        settings.poll_ms,
    )
    metrics = Metrics(state)
    web = WebServer(create_app(state, metrics), settings.host, settings.port)
    try:
        web.start()  # before Zenoh: a taken port fails at once, even with no router yet
    except RuntimeError as err:
        log.error("%s", err)
        raise SystemExit(2) from None
    try:
        with Service(NAME, keys.REFEREE, settings.zenoh) as svc:
            ingest = Ingest(state, metrics, svc.rejects)
            inbox = svc.subscribe(*keys.REFEREE_READS)  # liveliness: its own subscriber
            alive = svc.subscribe(keys.ALIVE, liveliness=True)
            svc.announce()
            log.info(
                "dashboard on http://%s:%d/ (metrics on /metrics)", settings.host, settings.port
            )
            while not svc.stop.is_set() and web.running:
                for item in alive.drain():
                    ingest.handle(item)
                for item in svc.drain(inbox, timeout=0.2):
                    ingest.handle(item)
                state.on_stats(keys.REFEREE, NAME, svc.stats())  # its own, without a round trip
                svc.publish_stats()
    finally:
        web.stop()
    if not svc.stop.is_set():
        log.error("the web server stopped")
        raise SystemExit(1)
