"""``tltrack demo``: the router and the four services as separate processes on loopback, one
episode, the scorer's summary, and a clean shutdown (no orphan, no hang)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import zenoh

from tltrack import keys
from tltrack.transport import ZenohSettings, open_session, query

SERVICES = ("scorer", "primary_tracker", "source_tracker", "sensor_sim")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


#: The shipped access control (deploy/zenoh in a checkout): one identity per operator.
ACCESS_DIR = Path(__file__).resolve().parents[2] / "deploy" / "zenoh"
#: the identity each service runs under (README: who may read what)
IDENTITY = {
    "sensor_sim": "sensor",
    "scorer": "referee",
    "primary_tracker": "primary",
    "source_tracker": "source-s1",
    "dashboard": "dashboard",
}


def passwords(users: Path = ACCESS_DIR / "users.txt") -> dict[str, str]:
    """user -> password from a Zenoh usrpwd dictionary (``user:password`` lines)."""
    lines = [ln.strip() for ln in users.read_text().splitlines() if ln.strip()]
    return {user: pw for user, pw in (ln.split(":", 1) for ln in lines)}


def identity_env(user: str, users: Path = ACCESS_DIR / "users.txt") -> dict[str, str]:
    """The environment that makes a service connect as ``user``."""
    return {"TLTRACK_ZENOH_USERNAME": user, "TLTRACK_ZENOH_PASSWORD": passwords(users)[user]}


def router_access_env(access: Path = ACCESS_DIR) -> dict[str, str]:
    """The router's environment for enforcing the ACL (for the router only: a client given it
    would apply the ACL to its own link and deny itself)."""
    return {
        "TLTRACK_ZENOH_ACCESS_CONTROL_FILE": str(access / "acl.json5"),
        "TLTRACK_ZENOH_USRPWD_DICTIONARY_FILE": str(access / "users.txt"),
    }


@dataclass
class Stack:
    """A router and services as child processes, each logging to ``logs/<name>.log``.

    ``secure``: the router enforces the shipped ACL and each service runs under its operator's
    identity, as in a deployment.
    """

    endpoint: str
    logs: Path
    secure: bool = False
    env: dict[str, str] = field(default_factory=dict)
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    _files: list[IO[bytes]] = field(default_factory=list)

    def start(self, name: str, argv: list[str], env: dict[str, str] | None = None) -> None:
        self.logs.mkdir(parents=True, exist_ok=True)
        log = open(self.logs / f"{name}.log", "ab")  # noqa: SIM115 (closed in stop())
        self._files.append(log)
        full_env = {
            **os.environ,
            "TLTRACK_ZENOH_ENDPOINTS": json.dumps([self.endpoint]),
            "PYTHONUNBUFFERED": "1",
            **self.env,
            **(env or {}),
        }
        self.procs[name] = subprocess.Popen(
            [sys.executable, *argv],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=full_env,
            start_new_session=True,
        )

    def start_router(self) -> None:
        access = router_access_env() if self.secure else {}
        self.start("router", ["-m", "tltrack", "router", "--listen", self.endpoint], access)

    def start_service(self, name: str, *flags: str, env: dict[str, str] | None = None) -> None:
        identity = identity_env(IDENTITY[name]) if self.secure else {}
        self.start(name, ["-m", f"services.{name}", *flags], {**identity, **(env or {})})

    def wait(self, name: str, timeout: float) -> int | None:
        try:
            return self.procs[name].wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def kill(self, name: str, sig: int = signal.SIGKILL) -> None:
        p = self.procs[name]
        if p.poll() is None:
            p.send_signal(sig)
            p.wait(10)

    def stop(self, timeout: float = 10.0) -> dict[str, int | None]:
        """SIGTERM everything (services first, router last); SIGKILL what outlives ``timeout``."""
        order = [n for n in self.procs if n != "router"] + (
            ["router"] if "router" in self.procs else []
        )
        for name in order:
            p = self.procs[name]
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(timeout)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
        for f in self._files:
            f.close()
        return {n: p.returncode for n, p in self.procs.items()}

    def __enter__(self) -> Stack:
        return self

    def __exit__(self, *_: object) -> None:
        self.stop()


@contextlib.contextmanager
def client(endpoint: str, user: str | None = None) -> Iterator[zenoh.Session]:
    """A client session, under identity ``user`` when the router enforces the ACL."""
    creds: dict[str, Any] = {}
    if user is not None:
        creds = {"username": user, "password": passwords()[user]}
    with open_session(ZenohSettings(endpoints=[endpoint], **creds)) as session:
        yield session


def fetch_summary(
    endpoint: str, timeout: float = 5.0, user: str | None = None
) -> dict[str, Any] | None:
    with client(endpoint, user) as session:
        for r in query(session, keys.SCORER_SUMMARY, timeout):
            return dict(json.loads(r.payload))
    return None


def wait_for_scored(
    endpoint: str, episodes: int, timeout: float, user: str | None = None
) -> dict[str, Any] | None:
    """Poll the scorer until ``episodes`` episodes are scored."""
    deadline = time.monotonic() + timeout
    with client(endpoint, user) as session:
        while time.monotonic() < deadline:
            for r in query(session, keys.SCORER_SUMMARY, 5.0):
                s = dict(json.loads(r.payload))
                if sum(1 for e in s.get("episodes", []) if e.get("scored")) >= episodes:
                    return s
            time.sleep(0.2)
    return None


def serve_until_interrupted(stack: Stack, name: str) -> None:
    """Keep the stack up until Ctrl-C or SIGTERM (or until ``name`` dies).

    A shell's background job ignores SIGINT, and a bare SIGTERM would orphan the children (each
    runs in its own session), so both become KeyboardInterrupt here and the stack shuts down.
    """

    def _stop(_signum: int, _frame: object) -> None:
        raise KeyboardInterrupt

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stop)
    try:
        while stack.procs[name].poll() is None:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass


def sim_flags(
    steps: int,
    particles: int,
    pace: float,
    realtime: bool,
    preset: str,
    truth: str,
    seed: int,
    episodes: int = 1,
) -> list[str]:
    flags = [
        f"--steps={steps}",
        f"--particles={particles}",
        f"--pace={pace}",
        f"--preset={preset}",
        f"--truth={truth}",
        f"--seed={seed}",
        f"--episodes={episodes}",
    ]
    return [*flags, "--realtime=true"] if realtime else flags
