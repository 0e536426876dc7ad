"""Who runs which Zenoh router, and which router dials which: the single and the federated
topology (docs/howto/separate-hosts.md; deploy/zenoh/README.md has the rules and a drawing).

- ``single``: one router for everyone, enforcing ``access/acl.json5``: every operator's data
  passes through one host, which every operator must trust.
- ``federated`` (the default): one router per operator, the referee (sensor_sim's clock and
  truth, the scorer, the dashboard), the primary and each source. Each source's router dials the
  primary's, and every router dials the referee's; gossip and multicast scouting are off, so the
  links are exactly these. Each router enforces its owner's rules (``access/routers/*.json5``)
  on what leaves it, so a misconfigured or hostile router on the other side of a link cannot pull
  out raw measurements, and no router forwards one operator's traffic to another.

A router dials others under its own identity, ``router-<operator>``; the routers it listens for
know that name and password, beside its own services' identities (:mod:`tltrack.live.access`
writes each router's rules and dictionary from the operator manifest).
"""

from __future__ import annotations

import contextlib
import itertools
import random
import socket
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from tltrack.live.manifest import REFEREE_SERVICES
from tltrack.wire import keys

Kind = Literal["single", "federated"]
TOPOLOGIES: tuple[Kind, ...] = ("federated", "single")


def why_cannot_listen(host: str, port: int) -> str | None:
    """Why a TCP server could not listen on host:port (a host that does not resolve, a port in
    use, an address not this machine's), found by binding it for a moment; None if it could."""
    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers do
            probe.bind(address)
    except (OSError, UnicodeError) as err:  # socket.gaierror is an OSError
        return str(err)
    return None


def free_port() -> int:
    return free_ports(1)[0]


def free_ports(n: int) -> list[int]:
    """``n`` distinct free ports, for routers that bind them later.

    They are sought below the kernel's ephemeral range, from which every outgoing connection takes
    its local port: a port of that range, free when found, can be a client's by the time its
    router binds it (a router once failed so, "Address already in use"). Each is held until all
    are found, so none is handed out twice.
    """
    with contextlib.ExitStack() as held:
        found: list[int] = []
        for port in _candidates():
            sock = held.enter_context(socket.socket())
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            found.append(int(sock.getsockname()[1]))
            if len(found) == n:
                return found
    raise RuntimeError(f"no {n} free ports on 127.0.0.1")


def _candidates() -> Iterator[int]:
    """Ports 10000 up to the ephemeral range's start, in random order (port 0, the kernel's
    choice, where that range leaves no room or is unknown)."""
    try:
        low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        low = 0
    if low - 10000 < 1000:
        return itertools.repeat(0)
    return iter(random.sample(range(10000, low), low - 10000))


def identity_operator(identity: str) -> str:
    """The operator whose router a service under ``identity`` logs in to."""
    if identity in REFEREE_SERVICES.values():
        return keys.REFEREE
    if identity.startswith("source-"):
        return keys.source_operator(identity.removeprefix("source-"))
    return identity


def _name(operator: str) -> str:
    return operator.replace("/", "-")  # source/s1 -> source-s1


@dataclass(frozen=True)
class Router:
    """One operator's router: where it listens and which routers it dials."""

    operator: str  #: ``referee``, ``primary`` or ``source/<sid>``
    endpoint: str
    dials: tuple[str, ...] = ()  #: operators whose routers this one connects to

    @property
    def name(self) -> str:
        """``referee``, ``primary``, ``source-s1``: its process and file names."""
        return _name(self.operator)


@dataclass(frozen=True)
class Topology:
    kind: Kind
    routers: dict[str, Router] = field(default_factory=dict)  #: by operator
    #: (dialler, dialled) -> the endpoint to dial instead of the dialled router's own (a relay)
    via: dict[tuple[str, str], str] = field(default_factory=dict)

    @property
    def referee(self) -> Router:
        """The router the referee's tools (summary, dashboard) talk to."""
        return self.routers[keys.REFEREE]

    def endpoint(self, identity: str) -> str:
        """Where a service under ``identity`` connects."""
        if self.kind == "single":
            return self.referee.endpoint
        return self.routers[identity_operator(identity)].endpoint


def single(endpoint: str) -> Topology:
    return Topology("single", {keys.REFEREE: Router(keys.REFEREE, endpoint)})


def federated(source_ids: list[str], host: str = "127.0.0.1") -> Topology:
    """A router per operator on ``host``, each on a free port."""
    at = [f"tcp/{host}:{port}" for port in free_ports(2 + len(source_ids))]
    routers = [
        Router(keys.REFEREE, at[0]),
        Router(keys.PRIMARY, at[1], (keys.REFEREE,)),
        *(
            Router(keys.source_operator(sid), ep, (keys.PRIMARY, keys.REFEREE))
            for sid, ep in zip(source_ids, at[2:], strict=True)
        ),
    ]
    return Topology("federated", {r.operator: r for r in routers})


def build(kind: Kind, source_ids: list[str]) -> Topology:
    """``kind`` on loopback, on free ports."""
    if kind == "federated":
        return federated(source_ids)
    return single(f"tcp/127.0.0.1:{free_port()}")


def describe(topology: Topology) -> str:
    """One line: which router listens where."""
    return ", ".join(f"{r.name} {r.endpoint}" for r in topology.routers.values())


def router_argv(topology: Topology, router: Router) -> list[str]:
    """``tltrack router``'s arguments for ``router`` (federated: as its operator's)."""
    if topology.kind == "single":
        return ["router", f"--listen={router.endpoint}"]
    dials = [
        f"--connect={topology.via.get((router.operator, op), topology.routers[op].endpoint)}"
        for op in router.dials
    ]
    return ["router", f"--operator={router.operator}", f"--listen={router.endpoint}", *dials]
