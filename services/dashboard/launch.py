"""Starting the dashboard as one more service of a :class:`tltrack.live.supervisor.Stack`
(``tltrack demo --serve``, tests), and making sensor_sim wait for it so the page sees every step.

Light on purpose: no web framework is imported until the dashboard process itself runs.
"""

from __future__ import annotations

import time
import urllib.error
import urllib.request
from typing import Protocol

from tltrack.services.dashboard.settings import DEFAULT_HOST, DEFAULT_PORT, NAME

#: the dashboard's liveliness token, as sensor_sim's ``wait_for`` names it
TOKEN = f"referee:{NAME}"


class _Stack(Protocol):
    def start_service(self, name: str, *flags: str, env: dict[str, str] | None = None) -> None: ...


def env(port: int = DEFAULT_PORT, host: str = DEFAULT_HOST) -> dict[str, str]:
    """The dashboard's environment."""
    return {"TLTRACK_DASHBOARD_HOST": host, "TLTRACK_DASHBOARD_PORT": str(port)}


def url(port: int = DEFAULT_PORT, host: str = DEFAULT_HOST) -> str:
    """Where a browser on this machine opens the page (a wildcard host means loopback here)."""
    shown = "127.0.0.1" if host in ("0.0.0.0", "::", "") else host
    if ":" in shown:
        shown = f"[{shown}]"
    return f"http://{shown}:{port}/"


def start(stack: _Stack, port: int = DEFAULT_PORT, host: str = DEFAULT_HOST) -> str:
    """Start the dashboard in ``stack``; returns the page's URL."""
    stack.start_service(NAME, env=env(port, host))
    return url(port, host)


def wait_ready(page: str, timeout: float = 30.0) -> bool:
    """Poll ``<page>healthz`` until it answers (the dashboard also needs its router first)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(f"{page}healthz", timeout=2) as r:
                if r.status == 200:
                    return True
        except (urllib.error.URLError, OSError):
            pass
        time.sleep(0.2)
    return False
