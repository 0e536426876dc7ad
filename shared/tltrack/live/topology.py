"""Who runs which Zenoh router, and which router dials which: the single and the federated
topology (README, "The live dual tracker"; deploy/zenoh/README.md has the rules and a drawing).

- ``single``: one router for everyone, enforcing ``access/acl.json5``: every operator's data
  passes through one host, which every operator must trust.
- ``federated`` (the default): one router per operator, the referee (sensor_sim's clock and
  truth, the scorer, the dashboard), the primary and each source. Each source's router dials the
  primary's, and every router dials the referee's; gossip and multicast scouting are off, so the
  links are exactly these. Each router enforces its owner's rules (``access/routers/*.json5``)
  on what leaves it, so a misconfigured or hostile router on the other side of a link cannot pull
  out raw measurements, and no router forwards one operator's traffic to another.

A router dials others under its own identity, ``router-<operator>``; the routers it listens for
know that name and password (``access/routers/users.txt``), beside its own services' identities.
"""

from __future__ import annotations

import contextlib
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from tltrack.wire import keys

Kind = Literal["single", "federated"]
TOPOLOGIES: tuple[Kind, ...] = ("federated", "single")

ACCESS_DIR = Path(__file__).resolve().parents[1] / "access"


def free_port() -> int:
    return free_ports(1)[0]


def free_ports(n: int) -> list[int]:
    """``n`` distinct free ports (each held until all are found, so none is handed out twice)."""
    with contextlib.ExitStack() as held:
        socks = [held.enter_context(socket.socket()) for _ in range(n)]
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [int(s.getsockname()[1]) for s in socks]


def identity_operator(identity: str) -> str:
    """The operator whose router a service under ``identity`` logs in to."""
    if identity in ("sensor", "referee", "dashboard"):
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

    @property
    def user(self) -> str:
        """The identity it dials other routers under."""
        return f"router-{self.name}"

    @property
    def local_identities(self) -> tuple[str, ...]:
        """The identities of its owner's services."""
        if self.operator == keys.REFEREE:
            return ("sensor", "referee", "dashboard")
        return (self.name,)


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


# ---- per-router configuration -------------------------------------------------------------------


def passwords(users: Path) -> dict[str, str]:
    """user -> password from a Zenoh usrpwd dictionary (``user:password`` lines)."""
    lines = [ln.strip() for ln in users.read_text().splitlines() if ln.strip()]
    return {user: pw for user, pw in (ln.split(":", 1) for ln in lines)}


def all_passwords(access: Path = ACCESS_DIR) -> dict[str, str]:
    """Every service's and every router's password."""
    return {**passwords(access / "users.txt"), **passwords(access / "routers" / "users.txt")}


def acl_text(router: Router, access: Path = ACCESS_DIR) -> str:
    """The router's ``access_control`` section, from the package's templates."""
    if router.operator in (keys.PRIMARY, keys.REFEREE):
        return (access / "routers" / f"{router.name}.json5").read_text()
    sid = router.operator.removeprefix("source/")
    return (access / "routers" / "source.json5").read_text().replace("SID", sid)


def diallers(operator: str, access: Path = ACCESS_DIR) -> list[str]:
    """The routers that may dial ``operator``'s: every operator's dials the referee's, every
    source's the primary's."""
    routers = passwords(access / "routers" / "users.txt")
    if operator == keys.REFEREE:
        return list(routers)
    if operator == keys.PRIMARY:
        return [u for u in routers if u.startswith("router-source-")]
    return []


def access_env(operator: str, out: Path, access: Path = ACCESS_DIR) -> dict[str, str]:
    """Write ``operator``'s router ACL and password dictionary into ``out``; the environment of
    its ``tltrack router`` (those files, and the identity it dials other routers under)."""
    router = Router(operator, "")
    pw = all_passwords(access)
    known = [*router.local_identities, *diallers(operator, access)]
    out.mkdir(parents=True, exist_ok=True)
    acl, users = out / f"{router.name}.acl.json5", out / f"{router.name}.users.txt"
    acl.write_text(acl_text(router, access))
    users.write_text("".join(f"{u}:{pw[u]}\n" for u in known))
    users.chmod(0o600)
    env = {
        "TLTRACK_ZENOH_ACCESS_CONTROL_FILE": str(acl),
        "TLTRACK_ZENOH_USRPWD_DICTIONARY_FILE": str(users),
    }
    if operator != keys.REFEREE:
        env |= {"TLTRACK_ZENOH_USERNAME": router.user, "TLTRACK_ZENOH_PASSWORD": pw[router.user]}
    return env


def router_argv(topology: Topology, router: Router) -> list[str]:
    """``tltrack router``'s arguments for ``router`` (federated: as its operator's)."""
    if topology.kind == "single":
        return ["router", f"--listen={router.endpoint}"]
    dials = [
        f"--connect={topology.via.get((router.operator, op), topology.routers[op].endpoint)}"
        for op in router.dials
    ]
    return ["router", f"--operator={router.operator}", f"--listen={router.endpoint}", *dials]
