"""Plugin kinds across processes: what a process was told to import, passed on to its children.

A user's sensor, motion model or filter kind named by import path in their own config is imported
by the process that reads the config (:mod:`tltrack.declare`). The services that process starts
never import anything a message names, so they are told, at start, which paths to import: the
environment variable ``TLTRACK_PLUGINS`` (``concept=package.module:Class``, comma-separated, with
``concept`` one of sensor, motion, filter). Every service loads it, and the installed entry
points, before it reads its settings.
"""

from __future__ import annotations

import os
from typing import Any

from tltrack.declare import Registry
from tltrack.filters.kinds import FILTERS
from tltrack.models.kinds import MOTIONS, SENSORS

ENV = "TLTRACK_PLUGINS"
REGISTRIES: dict[str, Registry[Any]] = {"sensor": SENSORS, "motion": MOTIONS, "filter": FILTERS}


def load(spec: str | None = None) -> None:
    """Load every installed plugin, and import the kinds ``spec`` (default: ``$TLTRACK_PLUGINS``)
    names; a ValueError names an entry that is malformed or cannot be imported."""
    for registry in REGISTRIES.values():
        registry.load_plugins()
    text = os.environ.get(ENV, "") if spec is None else spec
    for entry in filter(None, (e.strip() for e in text.split(","))):
        concept, sep, path = entry.partition("=")
        if not sep or concept not in REGISTRIES:
            raise ValueError(
                f"{ENV}: {entry!r} is not concept=package.module:Class, concept one of "
                f"{', '.join(REGISTRIES)}"
            )
        REGISTRIES[concept].get(path, trusted=True)


def passed_on() -> str:
    """The ``TLTRACK_PLUGINS`` value that makes a child import what this process imported (and
    what it was itself told to)."""
    mine = [
        f"{concept}={path}"
        for concept, registry in REGISTRIES.items()
        for path in registry.imported.values()
    ]
    told = [e.strip() for e in os.environ.get(ENV, "").split(",") if e.strip()]
    return ",".join(dict.fromkeys([*told, *mine]))
