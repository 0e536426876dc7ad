"""The shipped security configuration in tests: the package's access/ (ACL, credentials),
deploy/zenoh/router-tls.env and scripts/make_certs.sh, a router that enforces them, and services
and client sessions under their operators' identities.

The tests use the files as shipped, so a test that passes here passes for a deployment with them.
Only the fuzzer identity is test-only: it may publish anything anywhere, which no deployment may
allow, so it is added to a copy of the ACL (:func:`fuzz_access`), never to the shipped one.
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path
from typing import Any

import zenoh
from livestack import sim_flags
from tltrack.live import supervisor
from tltrack.live.access import ACCESS_DIR
from tltrack.live.supervisor import IDENTITY
from tltrack.wire import keys
from tltrack.wire.transport import LivelinessWatcher, ZenohSettings, open_session, query

ROOT = Path(__file__).resolve().parents[1]
ACL = ACCESS_DIR / "acl.json5"
USERS = ACCESS_DIR / "users.txt"
ROUTER_TLS_ENV = ROOT / "deploy" / "zenoh" / "router-tls.env"
MAKE_CERTS = ROOT / "scripts" / "make_certs.sh"

TRACKING = ("scorer", "primary_tracker", "source_tracker", "sensor_sim")  #: what an episode needs
FUZZER = "fuzzer"
SCORER_ENV = {"TLTRACK_SCORER_GRACE_S": "3"}


def load_acl(path: Path = ACL) -> dict[str, Any]:
    """The ACL as zenoh's own JSON5 parser reads it."""
    cfg = zenoh.Config()
    cfg.insert_json5("access_control", path.read_text())
    return dict(json.loads(cfg.get_json("access_control")))


def fuzz_access(tmp: Path) -> tuple[Path, Path]:
    """A copy of the shipped ACL and dictionary plus the test-only ``fuzzer``: it may publish on
    every key and read every key (to replay genuine messages), nothing else changes."""
    acl = load_acl()
    acl["rules"] += [
        {
            "id": "fuzzer-publish",
            "permission": "allow",
            "flows": ["ingress"],
            "messages": ["put", "declare_subscriber"],
            "key_exprs": ["tltrack/**"],
        },
        {
            "id": "fuzzer-receive",
            "permission": "allow",
            "flows": ["egress"],
            "messages": ["put", "declare_subscriber"],
            "key_exprs": ["tltrack/**"],
        },
    ]
    acl["subjects"].append({"id": FUZZER, "usernames": [FUZZER]})
    acl["policies"].append(
        {"id": FUZZER, "rules": ["fuzzer-publish", "fuzzer-receive"], "subjects": [FUZZER]}
    )
    acl_path, users_path = tmp / "acl-fuzz.json5", tmp / "users-fuzz.txt"
    acl_path.write_text(json.dumps(acl))
    users_path.write_text(USERS.read_text().rstrip("\n") + f"\n{FUZZER}:fuzz-only-pw\n")
    return acl_path, users_path


def make_certs(out: Path, *hosts: str, names: str | None = None) -> Path:
    """Run scripts/make_certs.sh into ``out``."""
    env = {**os.environ, **({"TLTRACK_CERT_NAMES": names} if names is not None else {})}
    subprocess.run(
        ["bash", str(MAKE_CERTS), str(out), *hosts],
        check=True,
        env=env,
        capture_output=True,
        timeout=60,
    )
    return out


def router_tls_env(certs: Path) -> dict[str, str]:
    """deploy/zenoh/router-tls.env with its repository paths resolved (certificates: ``certs``)."""
    env = {}
    for line in ROUTER_TLS_ENV.read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            name, value = line.split("=", 1)
            value = value.strip()
            if value.startswith("deploy/certs/"):
                value = str(certs / value.removeprefix("deploy/certs/"))
            elif value.startswith(("deploy/", "shared/")):
                value = str(ROOT / value)
            env[name.strip()] = value
    return env


# ---- processes --------------------------------------------------------------------------------


def start_router(
    s: supervisor.Stack, acl: Path = ACL, users: Path = USERS, env: dict[str, str] | None = None
) -> None:
    """``tltrack router`` enforcing ``acl`` with the credentials in ``users``; returns once it
    listens."""
    announced = router_starts(s)
    s.start(
        "router",
        ["-m", "tltrack", "router", "--listen", s.endpoint],
        env={
            "TLTRACK_ZENOH_ACCESS_CONTROL_FILE": str(acl),
            "TLTRACK_ZENOH_USRPWD_DICTIONARY_FILE": str(users),
            **(env or {}),
        },
    )
    wait_for_router(s, announced + 1)


def router_starts(s: supervisor.Stack) -> int:
    """How many times the router of ``s`` has announced that it listens."""
    log = s.logs / "router.log"
    return log.read_text().count("listening on") if log.exists() else 0


def wait_for_router(s: supervisor.Stack, starts: int, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while router_starts(s) < starts:
        assert s.procs["router"].poll() is None, (s.logs / "router.log").read_text()
        assert time.monotonic() < deadline, "the router did not start"
        time.sleep(0.05)


def passwords(users: Path = USERS) -> dict[str, str]:
    """user -> password from a Zenoh usrpwd dictionary (``user:password`` lines)."""
    lines = [ln.strip() for ln in users.read_text().splitlines() if ln.strip()]
    return {user: pw for user, pw in (ln.split(":", 1) for ln in lines)}


def start_service(
    s: supervisor.Stack,
    name: str,
    *flags: str,
    users: Path = USERS,
    env: dict[str, str] | None = None,
) -> None:
    """A service under its operator's identity (:data:`IDENTITY`)."""
    user = IDENTITY[name]
    creds = {"TLTRACK_ZENOH_USERNAME": user, "TLTRACK_ZENOH_PASSWORD": passwords(users)[user]}
    s.start_service(name, *flags, env={**creds, **(env or {})})


def start_trackers_and_scorer(
    s: supervisor.Stack, db: Path, users: Path = USERS, primary_env: dict[str, str] | None = None
) -> None:
    start_service(s, "scorer", users=users, env={"TLTRACK_SCORER_DB": str(db), **SCORER_ENV})
    start_service(s, "primary_tracker", users=users, env=primary_env)
    start_service(s, "source_tracker", users=users)


def start_sensor(
    s: supervisor.Stack,
    steps: int,
    particles: int,
    pace: float,
    users: Path = USERS,
    first_run: int = 0,
    **kw: Any,
) -> None:
    """sensor_sim for episodes of runs ``first_run``, ... (livestack's other settings)."""
    flags = [*sim_flags(steps, particles, pace=pace, **kw), f"--first_run={first_run}"]
    start_service(s, "sensor_sim", *flags, users=users)


def session(endpoint: str, user: str | None, users: Path = USERS, **kw: Any) -> zenoh.Session:
    """A client session as ``user`` (None: no credentials); give up connecting after 5 s."""
    creds = {} if user is None else {"username": user, "password": passwords(users)[user]}
    return open_session(
        ZenohSettings(**{"endpoints": [endpoint], "connect_timeout_ms": 5000, **creds, **kw})
    )


def summary(session: zenoh.Session) -> dict[str, Any] | None:
    for r in query(session, keys.SCORER_SUMMARY, 5.0):
        return dict(json.loads(r.payload))
    return None


def wait_for_scored(
    endpoint: str, episodes: int, timeout: float, users: Path = USERS, user: str = "referee"
) -> dict[str, Any] | None:
    """Poll the scorer's summary (as ``user``) until ``episodes`` episodes are scored."""
    deadline = time.monotonic() + timeout
    with session(endpoint, user, users) as z:
        while time.monotonic() < deadline:
            s = summary(z)
            if s and sum(1 for e in s.get("episodes", []) if e.get("scored")) >= episodes:
                return s
            time.sleep(0.3)
    return None


def wait_alive(z: zenoh.Session, services: list[str], timeout: float) -> bool:
    """Wait for the liveliness tokens of ``services`` (names of :data:`IDENTITY`)."""
    ops = {
        "sensor_sim": keys.REFEREE,
        "scorer": keys.REFEREE,
        "primary_tracker": keys.PRIMARY,
        "source_tracker": keys.source_operator("s1"),
    }
    deadline = time.monotonic() + timeout
    with LivelinessWatcher(z, keys.ALIVE) as w:
        return all(
            w.wait_until(keys.alive(ops[n], n), True, max(0.0, deadline - time.monotonic()))
            for n in services
        )


def rss_kb(pid: int) -> int:
    """Resident set size of a process, from /proc/<pid>/status."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise ValueError(f"no VmRSS for pid {pid}")
