"""The HTTP side: FastAPI routes for the page, its JSON snapshot and ``/metrics``, and a uvicorn
server in a background thread (the main thread runs the Zenoh loop and owns the signals).

The page's HTML, JS and CSS are package data under ``static/``: no CDN, no Node build step.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path

import uvicorn
from fastapi import FastAPI, Query
from fastapi.responses import FileResponse, Response
from fastapi.staticfiles import StaticFiles
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from tltrack.live.topology import why_cannot_listen
from tltrack.services.dashboard.metrics import Metrics
from tltrack.services.dashboard.state import State

log = logging.getLogger("dashboard")

STATIC = Path(__file__).parent / "static"
NO_STORE = {"Cache-Control": "no-store"}


def create_app(state: State, metrics: Metrics) -> FastAPI:
    app = FastAPI(title="tltrack dashboard", docs_url=None, redoc_url=None, openapi_url=None)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(STATIC / "index.html", headers=NO_STORE)

    @app.get("/api/state")
    def api_state(episode: str | None = Query(None, max_length=64)) -> Response:
        """The page's data: the shown episode (latest by default), health, rejections."""
        body = json.dumps(state.snapshot(episode), separators=(",", ":"))
        return Response(body, media_type="application/json", headers=NO_STORE)

    @app.get("/metrics")
    def prometheus() -> Response:
        return Response(generate_latest(metrics.registry), media_type=CONTENT_TYPE_LATEST)

    @app.get("/healthz")
    def healthz() -> dict[str, bool]:
        return {"ok": True}

    return app


class WebServer:
    """uvicorn in a daemon thread; :meth:`start` returns once it listens, or raises."""

    def __init__(self, app: FastAPI, host: str, port: int) -> None:
        config = uvicorn.Config(
            app,
            host=host,
            port=port,
            log_level="warning",
            lifespan="off",
            access_log=False,
            timeout_graceful_shutdown=2,
        )
        self.server = uvicorn.Server(config)
        self.host, self.port = host, port
        self._thread = threading.Thread(target=self.server.run, name="dashboard-http", daemon=True)

    def start(self, timeout: float = 15.0) -> None:
        if why := why_cannot_listen(self.host, self.port):  # uvicorn's thread would hide it
            raise RuntimeError(f"cannot serve on host {self.host!r}, port {self.port}: {why}")
        self._thread.start()
        deadline = time.monotonic() + timeout
        while not self.server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError(f"cannot serve on {self.host}:{self.port} (port in use?)")
            time.sleep(0.02)

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def stop(self) -> None:
        self.server.should_exit = True
        self._thread.join(timeout=10)
