"""Process supervision and stop signals: the routers (one per operator, or one for all:
:mod:`tltrack.live.topology`) and the services as separate processes (:class:`Stack`, what
``tltrack demo`` runs), and how every process of the product stops.

A service or router given a stop signal closes gracefully, and ends anyway after a grace
(:func:`exit_unless_stopped`). Children never outlive the command that started them. Whatever
stops it:

- SIGTERM, SIGHUP or SIGINT (even in a background job, whose SIGINT a shell sets to ignored):
  :func:`stop_on_signals` turns each into :class:`Interrupted` in the main thread, and
  :class:`Stack` stops the services, then the router;
- SIGKILL, or any other death: each child asked the kernel at birth for SIGTERM when its parent
  dies (Linux ``prctl(PR_SET_PDEATHSIG)``), so it shuts down as on a plain SIGTERM.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import IO, Any

import zenoh
from tltrack.config import Config, plugins
from tltrack.live import access, topology
from tltrack.live.manifest import DEFAULT, REFEREE_SERVICES, Manifest, load_manifest
from tltrack.live.manifest import ENV as MANIFEST_ENV
from tltrack.live.topology import Topology
from tltrack.live.topology import free_port as free_port
from tltrack.wire import keys
from tltrack.wire.messages import counts, decode_stats, json_object
from tltrack.wire.transport import Publisher, Subscriber, ZenohSettings, open_session, query

#: the signals that stop a command and every process it started
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


#: the identity each service runs under (docs/isolation.md: who may read what); a source's
#: tracker runs as its own operator, ``source-<id>`` (here the first source of the package's
#: manifest)
IDENTITY = {
    **REFEREE_SERVICES,
    "primary_tracker": keys.PRIMARY,
    "source_tracker": f"source-{load_manifest(DEFAULT).source_ids[0]}",
}


class AccessControlMissingError(RuntimeError):
    """The manifest does not know an operator: the demo refuses to run a router that does not
    know whom to let in."""


def check_access(manifest: Manifest, cfg: Config) -> None:
    """Raise :class:`AccessControlMissingError` unless the manifest lists every source operator
    of ``cfg``."""
    unknown = [s.id for s in cfg.sources if s.id not in manifest.source_ids]
    if unknown:
        raise AccessControlMissingError(
            f"the operator manifest lists sources {', '.join(manifest.source_ids)}, not "
            f"{', '.join(unknown)}: rename the sources, or add them to the manifest "
            f"(--manifest FILE; the package's is {DEFAULT})"
        )


# ---- stopping -----------------------------------------------------------------------------------

#: how long a process may take to close after a stop signal before it exits anyway
STOP_GRACE_S = 5.0


def exit_unless_stopped(signum: int, grace_s: float = STOP_GRACE_S) -> None:
    """Called on a stop signal: end the process in ``grace_s`` if its graceful close has not.

    A close normally takes well under a second, but a BLOCK put towards a router that is itself
    going away can wait for seconds, and a process that outlives its stop is an orphan. What is
    committed is durable (the scorer's rows survive kill -9), so ending it then loses nothing.

    The timer is a Python thread, so it cannot run while a native call holds the GIL; a second
    later the kernel ends the process anyway (``alarm``: SIGALRM's default action), whatever the
    interpreter is doing.
    """
    timer = threading.Timer(grace_s, os._exit, args=(128 + signum,))
    timer.daemon = True
    timer.start()
    signal.alarm(math.ceil(grace_s) + 1)


class Interrupted(BaseException):
    """A stop signal reached the command; ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


class _Deferral:
    """While ``depth`` > 0 a stop signal is only noted; it is raised when the depth returns to 0."""

    depth = 0
    pending: int | None = None


def _on_stop_signal(signum: int, _frame: FrameType | None) -> None:
    if _Deferral.depth:
        _Deferral.pending = signum
        return
    raise Interrupted(signum)


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """Within the block, SIGINT, SIGTERM and SIGHUP raise :class:`Interrupted`.

    SIGINT is handled even when it was inherited as ignored (a background job), since the
    children run in their own sessions and only this process can stop them.
    """
    previous = {sig: signal.signal(sig, _on_stop_signal) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """A stop signal inside the block is raised at its end: a child is never started without
    being recorded, and a stop is never cut short."""
    _Deferral.depth += 1
    try:
        yield
    finally:
        _Deferral.depth -= 1
        if _Deferral.depth == 0 and _Deferral.pending is not None:
            signum, _Deferral.pending = _Deferral.pending, None
            raise Interrupted(signum)


_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
_libc = ctypes.CDLL(ctypes.util.find_library("c")) if sys.platform == "linux" else None


def _child_setup(parent: int) -> Callable[[], None]:
    """What a child runs between fork and exec: SIGTERM when ``parent`` dies, no blocked signal."""

    def setup() -> None:
        signal.pthread_sigmask(signal.SIG_SETMASK, set())
        if _libc is not None:
            _libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM))
            if os.getppid() != parent:  # the parent died before prctl: no signal would come
                os.kill(os.getpid(), signal.SIGTERM)

    return setup


@dataclass
class Stack:
    """Routers and services as child processes, each logging to ``logs/<name>.log``.

    ``secure``: the routers enforce the shipped ACLs and each service runs under its operator's
    identity, as in a deployment. ``topology``: one router at ``endpoint`` (the default), or a
    federated one (always secure; ``endpoint`` is then the referee's router, where the summary
    is asked for). In the federated topology each operator's sensor runs beside its tracker.
    """

    endpoint: str
    logs: Path
    secure: bool = False
    env: dict[str, str] = field(default_factory=dict)
    topology: Topology | None = None
    #: the operator manifest (None: $TLTRACK_MANIFEST or the package's); the routers it starts
    #: read the same file
    manifest_file: Path | None = None
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    _files: list[IO[bytes]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.topology is None:
            self.topology = topology.single(self.endpoint)
        self.endpoint = self.topology.referee.endpoint
        self.secure = self.secure or self.federated
        self.manifest = load_manifest(self.manifest_file)
        if self.manifest_file is not None:
            self.env = {MANIFEST_ENV: str(Path(self.manifest_file).resolve()), **self.env}

    @property
    def federated(self) -> bool:
        return self.topology is not None and self.topology.kind == "federated"

    def start(self, name: str, argv: list[str], env: dict[str, str] | None = None) -> None:
        self.logs.mkdir(parents=True, exist_ok=True)
        log = open(self.logs / f"{name}.log", "ab")  # noqa: SIM115 (closed in stop())
        self._files.append(log)
        full_env = {
            **os.environ,
            "TLTRACK_ZENOH_ENDPOINTS": json.dumps([self.endpoint]),
            "PYTHONUNBUFFERED": "1",
            plugins.ENV: plugins.passed_on(),  # the kinds this process imported, by import path
            **self.env,
            **(env or {}),
        }
        with _signals_deferred():
            self.procs[name] = subprocess.Popen(
                [sys.executable, *argv],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=full_env,
                start_new_session=True,  # a terminal's Ctrl-C reaches this process alone
                preexec_fn=_child_setup(os.getpid()),
            )

    def start_router(self) -> None:
        """The router (single), or every operator's router (federated: ``router_<operator>``)."""
        if not self.federated:
            env = access.single_env(self.manifest, self.logs / "access") if self.secure else {}
            self.start("router", ["-m", "tltrack", "router", "--listen", self.endpoint], env)
            return
        assert self.topology is not None
        for r in self.topology.routers.values():  # the dialled before those that dial them
            self.start_operator_router(r.operator)
            self.wait_listening(f"router_{r.name}")

    def wait_listening(self, name: str, timeout: float = 60.0) -> None:
        """Wait for router ``name`` to listen. A router that dials one not yet listening redials
        only a second later, and what is published meanwhile travels without that link: a
        source's first transfers would go the long way round and be dropped (no router forwards
        one operator's traffic for another)."""
        log, deadline = self.logs / f"{name}.log", time.monotonic() + timeout
        while b" listening on " not in log.read_bytes():
            code = self.procs[name].poll()
            if code is not None or time.monotonic() > deadline:
                tail = log.read_text(errors="replace")[-2000:]
                why = f"exited with {code}" if code is not None else f"not listening in {timeout} s"
                raise RuntimeError(f"{name} {why}:\n{tail}")
            time.sleep(0.02)

    def start_operator_router(self, operator: str, env: dict[str, str] | None = None) -> None:
        """(Re)start one operator's router of the federated topology (``env``: overrides, such
        as another ACL file or TLS settings)."""
        assert self.topology is not None
        r = self.topology.routers[operator]
        self.start(
            f"router_{r.name}", ["-m", "tltrack", *topology.router_argv(self.topology, r)], env
        )

    def start_service(
        self,
        name: str,
        *flags: str,
        env: dict[str, str] | None = None,
        service: str | None = None,
        identity: str | None = None,
    ) -> None:
        """Start ``service`` (default: ``name``) as process ``name``, under ``identity``
        (default: the service's, :data:`IDENTITY`) when the stack is secure."""
        module = service or name
        user = identity or IDENTITY[module]
        extra = access.identity_env(user) if self.secure else {}
        if self.federated and self.topology is not None:
            extra["TLTRACK_ZENOH_ENDPOINTS"] = json.dumps([self.topology.endpoint(user)])
            if module == "sensor_sim":  # each operator's sensor measures; sensor_sim keeps time
                extra["TLTRACK_SIM_MEASUREMENTS"] = "false"
        self.start(name, ["-m", f"tltrack.services.{module}", *flags], {**extra, **(env or {})})

    def start_trackers(self, cfg: Config) -> list[str]:
        """The primary's tracker and one tracker per source of ``cfg``, each under its operator's
        identity (federated: and each operator's sensor, and a wait for the transfers' routes,
        :meth:`wait_transfer_routes`); returns the liveliness tokens (``operator:service``)
        sensor_sim must await."""
        self.start_service("primary_tracker")
        wait = ["primary:primary_tracker", "referee:scorer"]
        if self.federated:
            wait += self.start_sensors(cfg)
        for src in cfg.sources:
            self.start_service(
                self.manifest.tracker_service(src.id),
                service="source_tracker",
                identity=f"source-{src.id}",
                env={"TLTRACK_SOURCE_SOURCE_ID": src.id},
            )
            wait.append(f"source/{src.id}:source_tracker")
        if self.federated:
            self.wait_transfer_routes([src.id for src in cfg.sources])
        return wait

    def wait_transfer_routes(self, sources: list[str], timeout: float = 60.0) -> None:
        """Wait until each source's router knows of the primary's subscription to its transfers.

        Routers learn each other's subscribers asynchronously, after the liveliness tokens that
        sensor_sim awaits may have reached it. A source that steps before its router has heard
        of the subscription loses its first transfers there, and a lock-step primary then waits
        for ever. A publisher on the source's transfer key, declared under the source's identity
        and never sent on, asks that router just this (its matching status).
        """
        assert self.topology is not None
        deadline = time.monotonic() + timeout
        for sid in sources:
            user = f"source-{sid}"
            with (
                client(self.topology.endpoint(user), user) as session,
                Publisher(session, keys.transfer(sid, "route-probe")) as probe,
            ):
                while not probe.wait_for_subscribers(0.1):
                    code = self.procs["primary_tracker"].poll()
                    if code is not None or time.monotonic() > deadline:
                        why = f"exited with {code}" if code is not None else f"not in {timeout} s"
                        raise RuntimeError(
                            f"no route from source {sid} to the primary's tracker ({why}); "
                            f"see {self.logs / 'primary_tracker.log'}"
                        )

    def start_sensors(self, cfg: Config) -> list[str]:
        """Each operator's sensor, on its operator's router; returns their liveliness tokens."""
        self.start_service(
            "sensor_primary",
            service="sensor",
            identity="primary",
            env={"TLTRACK_SENSOR_SENSOR": "primary"},
        )
        for src in cfg.sources:
            self.start_service(
                f"sensor_{src.id}",
                service="sensor",
                identity=f"source-{src.id}",
                env={"TLTRACK_SENSOR_SENSOR": src.id},
            )
        return ["primary:sensor", *(f"source/{src.id}:sensor" for src in cfg.sources)]

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

    def stop(self, timeout: float = 6.0) -> dict[str, int | None]:
        """SIGTERM every service at once, then the routers; SIGKILL what outlives ``timeout``.

        The routers go last, so the services' last messages (and the scorer's final rows) still
        reach them while they close.
        """
        with _signals_deferred():
            services = [p for n, p in self.procs.items() if not n.startswith("router")]
            _terminate(services, timeout)
            _terminate([p for n, p in self.procs.items() if n.startswith("router")], timeout)
        for f in self._files:
            f.close()
        return {n: p.returncode for n, p in self.procs.items()}

    def __enter__(self) -> Stack:
        return self

    def __exit__(self, *_: object) -> None:
        self.stop()


def _terminate(procs: list[subprocess.Popen[bytes]], timeout: float) -> None:
    """SIGTERM ``procs`` together, wait for all up to ``timeout`` s, then SIGKILL the rest."""
    live = [p for p in procs if p.poll() is None]
    for p in live:
        p.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + timeout
    for p in live:
        try:
            p.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


@contextlib.contextmanager
def client(endpoint: str, user: str | None = None) -> Iterator[zenoh.Session]:
    """A client session, under identity ``user`` when the router enforces the ACL."""
    creds: dict[str, Any] = {}
    if user is not None:
        creds = {"username": user, "password": Manifest.password(user)}
    with open_session(ZenohSettings(endpoints=[endpoint], **creds)) as session:
        yield session


def fetch_summary(
    endpoint: str, timeout: float = 5.0, user: str | None = None
) -> dict[str, Any] | None:
    with client(endpoint, user) as session:
        for r in query(session, keys.SCORER_SUMMARY, timeout):
            if (s := _summary(r.payload)) is not None:
                return s
    return None


def _summary(payload: bytes) -> dict[str, Any] | None:
    """The scorer's summary in a reply; None if the reply is none (without access control any
    session may answer on the key)."""
    try:
        s = json_object(payload)
    except ValueError:
        return None
    return s if isinstance(s.get("episodes", []), list) else None


def wait_for_scored(
    endpoint: str, episodes: int, timeout: float, user: str | None = None
) -> dict[str, Any] | None:
    """Poll the scorer until ``episodes`` episodes are scored."""
    deadline = time.monotonic() + timeout
    with client(endpoint, user) as session:
        while time.monotonic() < deadline:
            for r in query(session, keys.SCORER_SUMMARY, 5.0):
                s = _summary(r.payload)
                if s is not None and _scored(s) >= episodes:
                    return s
            time.sleep(0.2)
    return None


def _scored(summary: dict[str, Any]) -> int:
    """How many of the summary's episodes are scored (an entry that is no object is none)."""
    return sum(isinstance(e, dict) and bool(e.get("scored")) for e in summary.get("episodes", []))


def _steps_reported(payload: bytes) -> int | None:
    """The steps a service's statistics count; None if they do not say (or are no statistics:
    without access control anyone may publish on the key)."""
    try:
        return counts(decode_stats(payload).get("counters")).get("steps")
    except ValueError:
        return None


def wait_for_episode(stack: Stack, timeout: float, on_step: Callable[[int], None]) -> int | None:
    """Wait up to ``timeout`` for sensor_sim to end its episode, telling ``on_step`` of each step
    it reports (its statistics, once a second, read as the referee); its exit code, or None."""
    deadline = time.monotonic() + timeout
    sim = stack.procs["sensor_sim"]
    with (
        client(stack.endpoint, keys.REFEREE if stack.secure else None) as session,
        Subscriber(session, [keys.stats(keys.REFEREE, "sensor_sim")]) as stats,
    ):
        while (code := sim.poll()) is None and time.monotonic() < deadline:
            item = stats.recv(0.2)
            if item is not None and (steps := _steps_reported(item.payload)) is not None:
                on_step(steps)
    return code if code is not None else stack.wait("sensor_sim", 0.0)


def serve_until_interrupted(stack: Stack, name: str) -> None:
    """Keep the stack up until a stop signal (see :func:`stop_on_signals`) or ``name`` dies."""
    while stack.procs[name].poll() is None:
        time.sleep(0.5)


def sim_env(wait_for: Sequence[str]) -> dict[str, str]:
    """sensor_sim's environment that makes it await the ``operator:service`` tokens ``wait_for``
    (:meth:`Stack.start_trackers` returns those of the trackers it started)."""
    return {"TLTRACK_SIM_WAIT_FOR": json.dumps(list(wait_for))}


def sim_flags(
    steps: int | None,
    particles: int | None,
    pace: float,
    realtime: bool,
    preset: str | None,
    truth: str | None,
    seed: int | None,
    episodes: int = 1,
    config: Path | None = None,
) -> list[str]:
    """sensor_sim's flags: the config file (if any), then every setting given (not None)."""
    given = {
        "config": config,
        "steps": steps,
        "particles": particles,
        "preset": preset,
        "truth": truth,
        "seed": seed,
    }
    flags = [f"--{k}={v}" for k, v in given.items() if v is not None]
    flags += [f"--pace={pace}", f"--episodes={episodes}"]
    return [*flags, "--realtime=true"] if realtime else flags
