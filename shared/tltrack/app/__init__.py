"""The ``tltrack`` command: one module per command, each registering on the shared Typer app.

Option names are a contract: other tools call them.
"""

from tltrack.app import (
    access,
    bench,
    demo,
    experiment,
    fit,
    link,
    reproduce,
    router,
    scores,
    study,
    track,
)
from tltrack.app.common import app

__all__ = [
    "access",
    "app",
    "bench",
    "demo",
    "experiment",
    "fit",
    "link",
    "reproduce",
    "router",
    "scores",
    "study",
    "track",
]
