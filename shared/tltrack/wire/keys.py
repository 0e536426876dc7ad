"""Zenoh key expressions: one builder per stream, wildcard patterns, and a parser.

Every key starts with ``tltrack/``. The operator that owns the data is a path segment right after
it (``primary``, ``source/<sid>``), so an access-control rule can grant or deny a whole operator
by prefix: the primary may read ``tltrack/source/*/transfer/**`` and nothing else of a source.

Layout (``e`` is an episode id, ``sid`` a source id, both ``[A-Za-z0-9_-]{1,64}``)::

    tltrack/episode/{e}                          EpisodeStart / EpisodeEnd   (sensor_sim)
    tltrack/truth/{e}                            Truth                       (sensor_sim, referee)
    tltrack/clock/{e}                            Tick: step k is due         (sensor_sim -> sensors)
    tltrack/primary/meas/{e}                     Measurement                 (primary's sensor)
    tltrack/source/{sid}/meas/{e}                Measurement                 (source's sensor)
    tltrack/source/{sid}/transfer/{e}            Transfer                    (source -> primary)
    tltrack/source/{sid}/heartbeat               empty put, every period     (source -> primary)
    tltrack/source/{sid}/estimate/{e}            EstimateMsg                 (source -> scorer)
    tltrack/primary/estimate/{tl|isolated}/{e}   EstimateMsg                 (primary -> scorer)
    tltrack/alive/{operator}/{service}           liveliness tokens
    tltrack/{operator}/stats/{service}           service statistics
    tltrack/scorer/summary                       queryable: the scorer's summary

Operators are ``primary``, ``source/<sid>`` and ``referee`` (sensor_sim and scorer).

Builders take concrete ids; pass :data:`ANY` (``"*"``) for any id argument to get the matching
subscriber pattern, e.g. ``transfer(ANY, ANY) == "tltrack/source/*/transfer/*"``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

ROOT = "tltrack"  #: the first segment of every key
ANY = "*"  #: matches exactly one id segment in a pattern
ALL = f"{ROOT}/**"  #: every tltrack key

PRIMARY = "primary"
REFEREE = "referee"

_ID_RE = re.compile(r"^[A-Za-z0-9_-]{1,64}$")

_ROLES = ("tl", "isolated")


def valid_id(value: str) -> bool:
    """Whether ``value`` is a usable episode/source/service id (no ``/``, ``*``, ``$``...)."""
    return isinstance(value, str) and _ID_RE.fullmatch(value) is not None


def _seg(value: str, what: str) -> str:
    if value == ANY:
        return value
    if not valid_id(value):
        raise ValueError(f"invalid {what} {value!r}: must match [A-Za-z0-9_-]{{1,64}}")
    return value


# ---- operators --------------------------------------------------------------------------------


def source_operator(sid: str) -> str:
    """The operator path of a source: ``source/<sid>``."""
    return f"source/{_seg(sid, 'source id')}"


def _operator(operator: str) -> str:
    """Validate an operator path: ``primary``, ``referee`` or ``source/<sid>`` (sid may be ANY)."""
    if operator in (PRIMARY, REFEREE, ANY):
        return operator
    parts = operator.split("/")
    if len(parts) == 2 and parts[0] == "source":
        _seg(parts[1], "source id")
        return operator
    raise ValueError(f"invalid operator {operator!r}: use 'primary', 'referee' or 'source/<sid>'")


# ---- data streams -----------------------------------------------------------------------------


def episode(e: str) -> str:
    """EpisodeStart / EpisodeEnd announcements."""
    return f"{ROOT}/episode/{_seg(e, 'episode id')}"


def truth(e: str) -> str:
    """Ground truth (referee data; no tracker may read it)."""
    return f"{ROOT}/truth/{_seg(e, 'episode id')}"


def clock(e: str) -> str:
    """The world clock: one Tick per step, to which every operator's sensor answers."""
    return f"{ROOT}/clock/{_seg(e, 'episode id')}"


def primary_meas(e: str) -> str:
    """The primary sensor's measurements."""
    return f"{ROOT}/primary/meas/{_seg(e, 'episode id')}"


def source_meas(sid: str, e: str) -> str:
    """Source ``sid``'s measurements."""
    return f"{ROOT}/source/{_seg(sid, 'source id')}/meas/{_seg(e, 'episode id')}"


def meas(sensor: str, e: str) -> str:
    """The measurements of ``sensor``: the primary's (``"primary"``), or source ``sensor``'s."""
    return primary_meas(e) if sensor == PRIMARY else source_meas(sensor, e)


def transfer(sid: str, e: str) -> str:
    """Source ``sid``'s transfer messages: the only source data the primary may read."""
    return f"{ROOT}/source/{_seg(sid, 'source id')}/transfer/{_seg(e, 'episode id')}"


def schedule(e: str) -> str:
    """The primary's schedule in episode ``e``: when its clock says it samples, none of its data.
    Its sources read it to address their transfers (:mod:`tltrack.config.timeline`)."""
    return f"{ROOT}/schedule/{_seg(e, 'episode id')}"


def heartbeat(sid: str) -> str:
    """Source ``sid``'s heartbeat: an empty put every period, which the routers let through on
    the direct source-primary link only, so that its silence means that link is down."""
    return f"{ROOT}/source/{_seg(sid, 'source id')}/heartbeat"


def source_estimate(sid: str, e: str) -> str:
    """Source ``sid``'s state estimates."""
    return f"{ROOT}/source/{_seg(sid, 'source id')}/estimate/{_seg(e, 'episode id')}"


def primary_estimate(role: str, e: str) -> str:
    """The primary's estimates; ``role`` is ``tl`` (with transfer) or ``isolated`` (or ANY)."""
    if role != ANY and role not in _ROLES:
        raise ValueError(f"invalid estimate role {role!r}: use 'tl' or 'isolated'")
    return f"{ROOT}/primary/estimate/{role}/{_seg(e, 'episode id')}"


# ---- service plumbing -------------------------------------------------------------------------


def alive(operator: str, service: str) -> str:
    """Liveliness token key, e.g. ``alive('source/s1', 'source_tracker')``."""
    return f"{ROOT}/alive/{_operator(operator)}/{_seg(service, 'service name')}"


def stats(operator: str, service: str) -> str:
    """Statistics published by ``service`` of ``operator``."""
    return f"{ROOT}/{_operator(operator)}/stats/{_seg(service, 'service name')}"


SCORER_SUMMARY = f"{ROOT}/scorer/summary"  #: the scorer's queryable summary

# ---- subscriber patterns ----------------------------------------------------------------------

EPISODES = episode(ANY)  #: tltrack/episode/*
TRUTHS = truth(ANY)  #: tltrack/truth/*
CLOCKS = clock(ANY)  #: tltrack/clock/*
PRIMARY_MEAS = primary_meas(ANY)  #: tltrack/primary/meas/*
SOURCE_MEAS = source_meas(ANY, ANY)  #: tltrack/source/*/meas/*
TRANSFERS = transfer(ANY, ANY)  #: tltrack/source/*/transfer/*
SCHEDULES = schedule(ANY)  #: tltrack/schedule/*
HEARTBEATS = heartbeat(ANY)  #: ``tltrack/source/*/heartbeat``
SOURCE_ESTIMATES = source_estimate(ANY, ANY)  #: tltrack/source/*/estimate/*
PRIMARY_ESTIMATES = primary_estimate(ANY, ANY)  #: tltrack/primary/estimate/*/*
ALIVE = f"{ROOT}/alive/**"  #: every liveliness token
STATS = f"{ROOT}/**/stats/*"  #: every service's statistics
#: what the referee's services (the scorer, the dashboard) read: liveliness aside, all they score
#: or show
REFEREE_READS = (EPISODES, TRUTHS, SOURCE_ESTIMATES, PRIMARY_ESTIMATES, STATS)


# ---- parsing ----------------------------------------------------------------------------------

KeyKind = Literal[
    "episode",
    "truth",
    "clock",
    "primary_meas",
    "source_meas",
    "transfer",
    "schedule",
    "heartbeat",
    "source_estimate",
    "primary_estimate",
    "alive",
    "stats",
    "scorer_summary",
]


@dataclass(frozen=True)
class KeyInfo:
    """What a concrete key names. Unused fields are ``None``."""

    kind: KeyKind
    episode: str | None = None
    source: str | None = None
    role: str | None = None  #: ``tl`` / ``isolated`` for primary estimates
    operator: str | None = None  #: for alive/stats keys and as the owner of data keys
    service: str | None = None


def parse(key: str) -> KeyInfo:
    """Parse a concrete key (no wildcards) back into its parts; ``ValueError`` if it is not ours."""
    key = str(key)
    p = key.split("/")
    if len(p) < 2 or p[0] != ROOT or any(not valid_id(s) for s in p[1:]):
        raise ValueError(f"not a tltrack key: {key!r}")
    n = len(p)
    if n == 3 and p[1] == "episode":
        return KeyInfo("episode", episode=p[2], operator=REFEREE)
    if n == 3 and p[1] == "truth":
        return KeyInfo("truth", episode=p[2], operator=REFEREE)
    if n == 3 and p[1] == "clock":
        return KeyInfo("clock", episode=p[2], operator=REFEREE)
    if n == 3 and p[1] == "schedule":
        return KeyInfo("schedule", episode=p[2], operator=PRIMARY)
    if n == 3 and p[1:3] == ["scorer", "summary"]:
        return KeyInfo("scorer_summary", operator=REFEREE, service="scorer")
    if p[1] == PRIMARY:
        if n == 4 and p[2] == "meas":
            return KeyInfo("primary_meas", episode=p[3], operator=PRIMARY)
        if n == 5 and p[2] == "estimate" and p[3] in _ROLES:
            return KeyInfo("primary_estimate", episode=p[4], role=p[3], operator=PRIMARY)
        if n == 4 and p[2] == "stats":
            return KeyInfo("stats", operator=PRIMARY, service=p[3])
    if p[1] == REFEREE and n == 4 and p[2] == "stats":
        return KeyInfo("stats", operator=REFEREE, service=p[3])
    if p[1] == "source" and n == 4 and p[3] == "heartbeat":
        return KeyInfo("heartbeat", source=p[2], operator=f"source/{p[2]}")
    if p[1] == "source" and n >= 5:
        sid, op = p[2], f"source/{p[2]}"
        if n == 5 and p[3] == "meas":
            return KeyInfo("source_meas", episode=p[4], source=sid, operator=op)
        if n == 5 and p[3] == "transfer":
            return KeyInfo("transfer", episode=p[4], source=sid, operator=op)
        if n == 5 and p[3] == "estimate":
            return KeyInfo("source_estimate", episode=p[4], source=sid, operator=op)
        if n == 5 and p[3] == "stats":
            return KeyInfo("stats", source=sid, operator=op, service=p[4])
    if p[1] == "alive":
        if n == 4 and p[2] in (PRIMARY, REFEREE):
            return KeyInfo("alive", operator=p[2], service=p[3])
        if n == 5 and p[2] == "source":
            return KeyInfo("alive", source=p[3], operator=f"source/{p[3]}", service=p[4])
    raise ValueError(f"unknown tltrack key layout: {key!r}")
