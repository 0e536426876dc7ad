"""Operator isolation enforced by the router, with the ACL and credentials the package ships.

Every service runs under its own operator's identity. Spy sessions under each identity subscribe
to what it may read and to what it may not, and query liveliness, while a real episode publishes
everything; the other identities forge transfers. Then the same over mutual TLS with the
certificates of scripts/make_certs.sh, and what an eavesdropper on the wire sees.
"""

from __future__ import annotations

import contextlib
import shutil
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh
from doubles import RADAR
from livestack import SIM_DEFAULTS, estimates, logs, stack
from security_helpers import (
    IDENTITY,
    ROUTER_TLS_ENV,
    TRACKING,
    load_acl,
    make_certs,
    passwords,
    router_tls_env,
    session,
    start_router,
    start_sensor,
    start_trackers_and_scorer,
    summary,
    wait_for_scored,
)
from tltrack.config import make_config
from tltrack.engine.montecarlo import trace_run
from tltrack.live import supervisor
from tltrack.wire import keys
from tltrack.wire.messages import EpisodeStart, Transfer, decode, encode
from tltrack.wire.transport import Subscriber

pytestmark = [pytest.mark.integration, pytest.mark.timeout(170)]
needs_openssl = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl")

E = "ep-r0"
FILTERS = ("tl-rpf", "rpf", "source-rpf")

#: identity -> (key expressions it may read, key expressions it may not)
READS: dict[str, tuple[list[str], list[str]]] = {
    "primary": (
        [keys.TRANSFERS, keys.PRIMARY_MEAS, keys.EPISODES],
        [
            keys.SOURCE_MEAS,
            keys.SOURCE_ESTIMATES,
            keys.TRUTHS,
            "tltrack/source/s1/**",
            keys.stats("source/s1", "source_tracker"),
            keys.ALL,
        ],
    ),
    "source-s1": (
        [keys.source_meas("s1", keys.ANY), keys.EPISODES],
        [keys.PRIMARY_MEAS, keys.PRIMARY_ESTIMATES, keys.TRUTHS, "tltrack/primary/**", keys.ALL],
    ),
    # another source operator (not in this episode's config): nothing of s1 or of the primary
    "source-s2": (
        [keys.EPISODES],
        [keys.source_meas("s1", keys.ANY), "tltrack/source/s1/**", keys.TRANSFERS, keys.ALL],
    ),
    "referee": (
        [keys.TRUTHS, keys.SOURCE_ESTIMATES, keys.PRIMARY_ESTIMATES, f"{keys.ROOT}/**/stats/*"],
        [keys.PRIMARY_MEAS, keys.SOURCE_MEAS, keys.ALL],
    ),
    "sensor": ([], [keys.PRIMARY_ESTIMATES, keys.SOURCE_ESTIMATES, keys.TRANSFERS, keys.ALL]),
    "dashboard": (
        [keys.TRUTHS, keys.SOURCE_ESTIMATES, keys.PRIMARY_ESTIMATES, keys.EPISODES],
        [keys.PRIMARY_MEAS, keys.SOURCE_MEAS, keys.ALL],
    ),
}


def _liveliness(z: zenoh.Session, pattern: str) -> set[str]:
    return {str(r.ok.key_expr) for r in z.liveliness().get(pattern, timeout=3) if r.ok}


def test_each_operator_reads_only_what_the_acl_grants(tmp_path: Path) -> None:
    db = tmp_path / "scorer.sqlite"
    K, N = 25, 300
    with stack(tmp_path) as s, ExitStack() as spies:
        start_router(s)
        start_trackers_and_scorer(s, db, primary_env={"TLTRACK_PRIMARY_LOCKSTEP": "true"})
        # Denied subscriptions get sessions of their own: a session hands a sample it may
        # receive to all its matching subscribers, so `tltrack/**` beside the transfers'
        # subscription would see the transfers.
        z = {user: spies.enter_context(session(s.endpoint, user)) for user in READS}
        spy = {user: spies.enter_context(session(s.endpoint, user)) for user in READS}
        subs = {
            (user, key, allowed): spies.enter_context(
                Subscriber((z if allowed else spy)[user], key)
            )
            for user, (ok, denied) in READS.items()
            for allowed, key_list in ((True, ok), (False, denied))
            for key in key_list
        }
        episodes = subs["primary", keys.EPISODES, True]
        start_sensor(s, K, N, pace=10)
        started = episodes.recv_message(EpisodeStart, timeout=90)
        assert started is not None, logs(s)
        # Everyone else forges the source's transfers for every step, ahead of the real ones.
        forged = [
            encode(
                Transfer(
                    episode=E,
                    sender="s1",
                    k=k,
                    t_sensor=0.0,
                    k_apply=k + 1,
                    sensor=RADAR,
                    eta=[1.0, 0.0],
                    P_eta=[[1.0, 0.0], [0.0, 1.0]],
                )
            )
            for k in range(1, K)
        ]
        for user in ("primary", "referee", "sensor", "source-s2"):
            with session(s.endpoint, user) as forger:
                for payload in forged:
                    forger.put(keys.transfer("s1", E), payload)
                forger.put("tltrack/source/*/transfer/*", forged[-1])
        # Liveliness: the primary may see the sources' trackers, the source sees nobody; each
        # may look up its own token (compose.yaml's health check), nothing wider.
        alive_src = keys.alive("source/s1", "source_tracker")
        alive_primary = keys.alive("primary", "primary_tracker")
        assert _liveliness(z["primary"], keys.alive("source/*", "source_tracker")) == {alive_src}
        assert _liveliness(z["primary"], keys.ALIVE) == set()
        assert _liveliness(z["primary"], alive_primary) == {alive_primary}
        assert _liveliness(z["source-s1"], keys.ALIVE) == set()
        assert _liveliness(z["source-s1"], alive_src) == {alive_src}
        assert _liveliness(z["source-s2"], alive_src) == set()
        assert _liveliness(z["source-s2"], keys.alive("source/*", "source_tracker")) == set()
        assert alive_src in _liveliness(z["sensor"], keys.ALIVE)
        assert s.wait("sensor_sim", 90) == 0, logs(s)
        scored = wait_for_scored(s.endpoint, 1, 60)
        assert scored is not None, logs(s)
        # The summary is public: every operator may read it.
        for user in ("primary", "source-s1"):
            assert summary(z[user]) is not None, user
        received = {k: sub.received for k, sub in subs.items()}
        transfers = [
            decode(r.payload, Transfer) for r in subs["primary", keys.TRANSFERS, True].drain()
        ]

    for (user, key, allowed), n in received.items():
        if allowed:
            assert n > 0, f"{user} received nothing on {key}, which it may read"
        else:
            assert n == 0, f"{user} received {n} samples on {key}, which it may not read"
    assert received["primary", keys.PRIMARY_MEAS, True] == K
    assert received["source-s1", keys.source_meas("s1", keys.ANY), True] == K
    assert received["referee", keys.TRUTHS, True] == K
    # Only the genuine transfers reached anyone, and the primary never saw two for one step.
    assert len(transfers) == K - 1 and all(t.eta != [1.0, 0.0] for t in transfers)
    primary_rejects = scored["messages"]["rejected"]["primary/primary_tracker"]
    assert primary_rejects == {}, primary_rejects
    # ... so the lock-step episode is exactly the offline engine's: the ACL changed nothing else.
    cfg = make_config(**SIM_DEFAULTS, K=K, particles=N)
    offline = trace_run(cfg, list(FILTERS), run=0)
    live = estimates(db)
    for name in FILTERS:
        x = np.array([live[name][k][0] for k in range(1, K + 1)])
        np.testing.assert_allclose(x, offline[name], rtol=0, atol=1e-9, err_msg=name)
    assert [live["tl-rpf"][k][1] for k in range(1, K + 1)] == [False] + [True] * (K - 1)


def test_unknown_users_and_wrong_passwords_are_refused(tmp_path: Path) -> None:
    """A stranger, or an operator with a wrong password, gets no session at all."""
    with stack(tmp_path) as s:
        start_router(s)
        with session(s.endpoint, "primary") as z:
            assert z.info.routers_zid()
        for user, password in (("primary", "guess"), ("intruder", "x"), ("fuzzer", "x")):
            with pytest.raises(zenoh.ZError):
                session(s.endpoint, None, username=user, password=password, connect_timeout_ms=1500)
        with pytest.raises(zenoh.ZError):
            session(s.endpoint, None, connect_timeout_ms=1500)


# ---- transport security -----------------------------------------------------------------------


def _tls(certs: Path, name: str, ca: Path | None = None) -> dict[str, Any]:
    return {
        "tls_root_ca": ca or certs / "ca.pem",
        "tls_cert": certs / f"{name}.pem",
        "tls_key": certs / f"{name}.key",
        "tls_mtls": True,
    }


@needs_openssl
def test_mutual_tls_episode_with_operator_certificates(tmp_path: Path) -> None:
    """deploy/zenoh/router-tls.env: the router knows each operator by its certificate's common
    name, applies the same ACL, and refuses certificates it did not issue."""
    assert ROUTER_TLS_ENV.exists()
    certs = make_certs(tmp_path / "certs")
    rogue = make_certs(tmp_path / "rogue", names="primary")
    port = supervisor.free_port()
    db = tmp_path / "scorer.sqlite"
    with stack(tmp_path) as s:
        s.endpoint = f"tls/localhost:{port}"
        s.start(
            "router",
            ["-m", "tltrack", "router", "--listen", f"tls/127.0.0.1:{port}"],
            env=router_tls_env(certs),
        )
        s.wait_listening("router")  # a loaded machine takes seconds to bring up a TLS router
        for name in TRACKING:
            tls = {
                f"TLTRACK_ZENOH_{k.upper()}": str(v) for k, v in _tls(certs, IDENTITY[name]).items()
            }
            env = {**tls, "TLTRACK_SCORER_DB": str(db)} if name == "scorer" else tls
            if name == "sensor_sim":
                s.start_service(
                    name,
                    *supervisor.sim_flags(15, 300, 0, False, "arasaratnam-haykin", "fixed", 7),
                    env=env,
                )
            else:
                s.start_service(name, env=env)
        with session(s.endpoint, None, **_tls(certs, "primary")) as prim:
            # a certificate from another CA is refused, and so is a router we do not trust
            for bad in (_tls(rogue, "primary"), _tls(certs, "primary", ca=rogue / "ca.pem")):
                with pytest.raises(zenoh.ZError):
                    session(s.endpoint, None, connect_timeout_ms=1500, **bad)
            denied = Subscriber(prim, keys.SOURCE_MEAS)
            assert s.wait("sensor_sim", 120) == 0, logs(s)
            deadline = time.monotonic() + 60
            # every filter's 15 estimates, read by the primary's certificate: the summary is public
            while (result := summary(prim)) is None or any(
                result["filters"].get(name, {}).get("steps") != 15 for name in FILTERS
            ):
                assert time.monotonic() < deadline, logs(s)
                time.sleep(0.3)
            assert denied.received == 0
            denied.close()
    assert result["filters"]["tl-rpf"]["steps_with_transfer"] == 14


@contextmanager
def _tap(target_port: int) -> Iterator[tuple[int, bytearray]]:
    """A TCP relay to ``target_port`` that keeps a copy of every byte it forwards: what anyone
    on the path between a client and the router can read."""
    seen = bytearray()
    lock = threading.Lock()
    server = socket.create_server(("127.0.0.1", 0))
    server.settimeout(0.2)
    stop = threading.Event()

    def pipe(a: socket.socket, b: socket.socket) -> None:
        with a, b, contextlib.suppress(OSError):  # the other direction closed both
            while data := a.recv(65536):
                with lock:
                    seen.extend(data)
                b.sendall(data)

    def serve() -> None:
        while not stop.is_set():
            try:
                client, _ = server.accept()
            except TimeoutError:
                continue
            upstream = socket.create_connection(("127.0.0.1", target_port))
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=pipe, args=(a, b), daemon=True).start()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield server.getsockname()[1], seen
    finally:
        stop.set()
        thread.join(5)
        server.close()


@needs_openssl
@pytest.mark.parametrize("tls", [False, True], ids=["tcp", "tls"])
def test_an_eavesdropper_reads_plain_tcp_but_not_tls(tmp_path: Path, tls: bool) -> None:
    secret = b"eta=1234.5678 rad; raw range of the source"
    certs = make_certs(tmp_path / "certs", names="primary source-s1")
    port = supervisor.free_port()
    proto = "tls" if tls else "tcp"
    with stack(tmp_path) as s:
        s.endpoint = f"{proto}/127.0.0.1:{port}"
        env = router_tls_env(certs) if tls else {}
        start_router(s, env=env)
        with _tap(port) as (tap_port, seen):
            wire = f"{proto}/localhost:{tap_port}"

            def creds(name: str) -> dict[str, Any]:
                return _tls(certs, name) if tls else {}

            with (
                session(wire, "source-s1", **creds("source-s1")) as src,
                session(wire, "primary", **creds("primary")) as prim,
                Subscriber(prim, keys.TRANSFERS) as sub,
            ):
                time.sleep(0.3)
                src.put(keys.transfer("s1", E), secret)
                got = sub.recv(10)
            assert got is not None and got.payload == secret, "the message did not go through"
            assert len(seen) > 0
            assert (secret in seen) is not tls
            assert (b"source-s1" in seen) is not tls  # the username, too


def test_every_identity_has_credentials_and_a_policy() -> None:
    """The ACL (as zenoh parses it) and the dictionary agree on who the operators are."""
    acl = load_acl()
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    users = set(passwords())
    named = {u for s_ in acl["subjects"] for u in s_["usernames"] or []}
    certified = {u for s_ in acl["subjects"] for u in s_["cert_common_names"] or []}
    # the demo's services, and the two more sources of compose.yaml's profile three-sources
    operators = set(IDENTITY.values()) | {"source-s2", "source-s3"}
    assert named == certified == users == operators
    in_policy = {s_ for p in acl["policies"] for s_ in p["subjects"]}
    assert in_policy == {s_["id"] for s_ in acl["subjects"]}
