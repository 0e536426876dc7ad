"""Key layout, Zenoh settings, and real sessions over loopback through a router subprocess.

The router runs :func:`tltrack.wire.transport.run_router` in its own process on a free port; clients
are real sessions (in this process or in child processes). Every session is closed with ``with``.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh
from doubles import RADAR
from security_helpers import make_certs
from tltrack.live.router import background_router
from tltrack.live.topology import free_port
from tltrack.wire import keys
from tltrack.wire.messages import Measurement, RejectCounter, Transfer, decode, encode
from tltrack.wire.transport import (
    LivelinessWatcher,
    Publisher,
    Queryable,
    Received,
    Subscriber,
    ZenohSettings,
    declare_token,
    open_session,
    query,
)

pytestmark = pytest.mark.timeout(60)

T0 = 1_700_000_000.0


# ---- keys -------------------------------------------------------------------------------------


@pytest.mark.unit
def test_key_builders() -> None:
    assert keys.truth("e1") == "tltrack/truth/e1"
    assert keys.episode("e1") == "tltrack/episode/e1"
    assert keys.primary_meas("e1") == "tltrack/primary/meas/e1"
    assert keys.source_meas("s1", "e1") == "tltrack/source/s1/meas/e1"
    assert keys.transfer("s1", "e1") == "tltrack/source/s1/transfer/e1"
    assert keys.source_estimate("s1", "e1") == "tltrack/source/s1/estimate/e1"
    assert keys.primary_estimate("tl", "e1") == "tltrack/primary/estimate/tl/e1"
    assert keys.primary_estimate("isolated", "e1") == "tltrack/primary/estimate/isolated/e1"
    assert keys.alive("source/s1", "source_tracker") == "tltrack/alive/source/s1/source_tracker"
    assert keys.alive(keys.source_operator("s1"), "x") == "tltrack/alive/source/s1/x"
    assert keys.alive(keys.PRIMARY, "primary_tracker") == "tltrack/alive/primary/primary_tracker"
    assert keys.stats("source/s1", "source_tracker") == "tltrack/source/s1/stats/source_tracker"
    assert keys.stats(keys.REFEREE, "scorer") == "tltrack/referee/stats/scorer"
    assert keys.SCORER_SUMMARY == "tltrack/scorer/summary"


@pytest.mark.unit
def test_key_patterns() -> None:
    assert keys.PRIMARY_MEAS == "tltrack/primary/meas/*"
    assert keys.TRANSFERS == "tltrack/source/*/transfer/*"
    assert keys.transfer("s1", keys.ANY) == "tltrack/source/s1/transfer/*"
    assert keys.PRIMARY_ESTIMATES == "tltrack/primary/estimate/*/*"
    for pattern, key in [
        (keys.PRIMARY_MEAS, keys.primary_meas("e9")),
        (keys.TRANSFERS, keys.transfer("s2", "e9")),
        (keys.SOURCE_MEAS, keys.source_meas("s2", "e9")),
        (keys.ALIVE, keys.alive("source/s2", "source_tracker")),
        (keys.alive("source/*", "*"), keys.alive("source/s2", "source_tracker")),
        (keys.ALL, keys.SCORER_SUMMARY),
    ]:
        assert zenoh.KeyExpr(pattern).intersects(key), (pattern, key)
    # the primary's pattern for transfers never matches a source's raw measurements
    assert not zenoh.KeyExpr(keys.TRANSFERS).intersects(keys.source_meas("s1", "e1"))
    assert not zenoh.KeyExpr("tltrack/source/*/transfer/**").intersects(
        keys.source_estimate("s1", "e1")
    )
    # every builder output is a canonical zenoh key expression
    for k in (keys.TRANSFERS, keys.PRIMARY_ESTIMATES, keys.ALIVE, keys.alive("source/*", "*")):
        assert str(zenoh.KeyExpr(k)) == k


@pytest.mark.parametrize("bad", ["", "a/b", "**", "$*", "a b", "é", "x" * 65, "e*"])
@pytest.mark.unit
def test_key_builders_refuse_bad_ids(bad: str) -> None:
    with pytest.raises(ValueError):
        keys.truth(bad)
    with pytest.raises(ValueError):
        keys.transfer(bad, "e1")
    with pytest.raises(ValueError):
        keys.alive("source/" + bad, "svc")
    with pytest.raises(ValueError):
        keys.stats("primary", bad)


@pytest.mark.unit
def test_key_builders_refuse_bad_operator_and_role() -> None:
    for op in ("source", "source/a/b", "primaryx", "tltrack"):
        with pytest.raises(ValueError):
            keys.alive(op, "svc")
    with pytest.raises(ValueError):
        keys.primary_estimate("fused", "e1")


@pytest.mark.unit
def test_parse_round_trips() -> None:
    cases = {
        keys.truth("e1"): ("truth", "e1", None),
        keys.episode("e1"): ("episode", "e1", None),
        keys.primary_meas("e1"): ("primary_meas", "e1", None),
        keys.source_meas("s1", "e1"): ("source_meas", "e1", "s1"),
        keys.transfer("s-2", "run_7"): ("transfer", "run_7", "s-2"),
        keys.source_estimate("s1", "e1"): ("source_estimate", "e1", "s1"),
        keys.primary_estimate("tl", "e1"): ("primary_estimate", "e1", None),
        keys.alive("source/s1", "source_tracker"): ("alive", None, "s1"),
        keys.alive("primary", "primary_tracker"): ("alive", None, None),
        keys.stats("source/s1", "source_tracker"): ("stats", None, "s1"),
        keys.stats("referee", "sensor_sim"): ("stats", None, None),
        keys.SCORER_SUMMARY: ("scorer_summary", None, None),
    }
    for key, (kind, ep, src) in cases.items():
        info = keys.parse(key)
        assert (info.kind, info.episode, info.source) == (kind, ep, src), key
    assert keys.parse(keys.primary_estimate("isolated", "e3")).role == "isolated"
    info = keys.parse(keys.alive("source/s1", "source_tracker"))
    assert (info.operator, info.service) == ("source/s1", "source_tracker")
    info = keys.parse(keys.SCORER_SUMMARY)
    assert info.episode is None and info.source is None


@pytest.mark.parametrize(
    "bad",
    [
        "",
        "tltrack",
        "other/truth/e1",
        "tltrack/truth/*",
        "tltrack/truth/e1/extra",
        "tltrack/source/s1/secret/e1",
        "tltrack/primary/estimate/fused/e1",
        "tltrack/alive/source/s1",
        "tltrack//truth",
    ],
)
@pytest.mark.unit
def test_parse_refuses_foreign_keys(bad: str) -> None:
    with pytest.raises(ValueError):
        keys.parse(bad)


# ---- settings ---------------------------------------------------------------------------------


@pytest.mark.unit
def test_settings_defaults_map_to_zenoh_config() -> None:
    cfg = ZenohSettings().to_config()

    def get(key: str) -> object:
        value = cfg.get_json(key)
        return json.loads(value) if isinstance(value, str) else value

    assert get("mode") == "client"
    assert get("connect/endpoints") == ["tcp/127.0.0.1:7447"]
    assert get("connect/timeout_ms") == -1
    assert get("scouting/multicast/enabled") is False
    assert get("transport/link/tx/lease") == 2000


@pytest.mark.unit
def test_settings_from_environment(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("TLTRACK_ZENOH_MODE", "peer")
    monkeypatch.setenv("TLTRACK_ZENOH_ENDPOINTS", "tcp/10.0.0.1:7447, tcp/10.0.0.2:7447")
    monkeypatch.setenv("TLTRACK_ZENOH_LISTEN", '["tcp/0.0.0.0:7448"]')
    monkeypatch.setenv("TLTRACK_ZENOH_USERNAME", "primary")
    monkeypatch.setenv("TLTRACK_ZENOH_PASSWORD", "s3cret")
    monkeypatch.setenv("TLTRACK_ZENOH_TLS_ROOT_CA", str(tmp_path / "ca.pem"))
    # a file it names must be there and hold a PEM certificate: the rest is TLS's to check
    (tmp_path / "ca.pem").write_text("-----BEGIN CERTIFICATE-----\n-----END CERTIFICATE-----\n")
    s = ZenohSettings()
    assert s.mode == "peer"
    assert s.endpoints == ["tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447"]
    assert s.listen == ["tcp/0.0.0.0:7448"]
    assert "s3cret" not in repr(s)
    cfg = s.to_config()
    assert cfg.get_json("transport/auth/usrpwd/user") in ("primary", '"primary"')
    assert "ca.pem" in str(cfg.get_json("transport/link/tls/root_ca_certificate"))


@pytest.mark.parametrize(
    ("kwargs", "said"),
    [
        ({"mode": "broker"}, "Input should be 'client', 'peer' or 'router'"),
        ({"username": "u"}, "username and password must be given together"),
        ({"password": "p"}, "username and password must be given together"),
        ({"tls_cert": "c.pem"}, "Path does not point to a file"),
        ({"tls_mtls": True}, "tls_mtls needs tls_root_ca, tls_cert and tls_key"),
        ({"endpoints": []}, "a client needs at least one endpoint"),
        ({"lease_ms": 10}, "greater than or equal to 500"),
        ({"unknown_field": 1}, "Extra inputs are not permitted"),
    ],
)
@pytest.mark.unit
def test_settings_refuse_inconsistent_values(kwargs: dict[str, object], said: str) -> None:
    with pytest.raises(ValueError, match=re.escape(said)):
        ZenohSettings(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "said"),
    [
        ({"endpoints": ["garbage"]}, "is not <protocol>/<address>"),
        ({"endpoints": ["tcp/127.0.0.1"]}, "host:port"),  # zenoh dials this for ever
        ({"endpoints": ["tcp/127.0.0.1:notaport"]}, "host:port"),  # ... and this
        ({"listen": ["tls/0.0.0.0:70000"]}, "the port 0-65535"),
        ({"endpoints": ["bogus/x"]}, "zenoh has no protocol 'bogus'"),  # ... and this
        ({"tls_root_ca": "/nonexistent/ca.pem"}, "does not point to a file"),  # a client hung
        ({"access_control_file": "ACL"}, "zenoh refuses it: --> 1:1"),  # a traceback at start
        ({"access_control_file": "BIN"}, "not UTF-8 text (JSON5)"),  # named no field
        ({"tls_root_ca": "TXT"}, "holds no PEM certificate"),  # a client retried for ever
        ({"tls_cert": "TXT", "tls_key": "TXT"}, "holds no PEM"),
    ],
)
@pytest.mark.unit
def test_settings_refuse_what_zenoh_would_crash_or_hang_on(
    kwargs: dict[str, object], said: str, tmp_path: Path
) -> None:
    files = {"ACL": b"rules: [", "BIN": b"\xff\xfe\x00", "TXT": b"not a certificate"}
    for field, marker in list(kwargs.items()):  # a file, but not what the field reads
        if isinstance(marker, str) and marker in files:
            (tmp_path / field).write_bytes(files[marker])
            kwargs[field] = tmp_path / field
    with pytest.raises(ValueError, match=re.escape(said)):
        ZenohSettings(**kwargs)  # type: ignore[arg-type]


@pytest.mark.unit
def test_settings_take_every_form_of_endpoint_zenoh_takes() -> None:
    ok = ["tcp/[::1]:7447", "unixsock-stream//tmp/z.sock", "tcp/h:7447?iface=lo#rx_buffer=1"]
    assert ZenohSettings(endpoints=ok, listen=["udp/0.0.0.0:0"]).endpoints == ok


# ---- process helpers --------------------------------------------------------------------------


class Child:
    """A Python child process whose stdout lines are read by a thread."""

    def __init__(self, code: str, *args: str, env: dict[str, str] | None = None) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-u", "-c", textwrap.dedent(code), *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, **(env or {})},
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.output: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.output.append(line)
            self.lines.put(line)

    def wait_line(self, prefix: str, timeout: float = 20.0) -> str:
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no line starting {prefix!r}; output: {''.join(self.output)}")
            try:
                line = self.lines.get(timeout=min(remaining, 0.5))
            except queue.Empty:
                if self.proc.poll() is not None:
                    raise RuntimeError(
                        f"child exited {self.proc.returncode}: {''.join(self.output)}"
                    ) from None
                continue
            if line.startswith(prefix):
                return line

    def send(self, sig: int) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int:
        """Signal the child and wait; SIGKILL it if it does not exit in time."""
        self.send(sig)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
            raise


ROUTER_CODE = """
    import json, sys
    from tltrack.live.router import run_router
    from tltrack.wire.transport import ZenohSettings
    settings = ZenohSettings(**json.loads(sys.argv[2]))
    run_router([sys.argv[1]], settings)
    print("router exited cleanly", flush=True)
"""


def start_router(endpoint: str, **settings: object) -> Child:
    child = Child(ROUTER_CODE, endpoint, json.dumps(settings, default=str))
    child.wait_line("tltrack router ")
    return child


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    child = start_router(endpoint)
    try:
        yield endpoint
    finally:
        assert child.stop(signal.SIGTERM) == 0, "".join(child.output)


def client(endpoint: str, **kw: object) -> zenoh.Session:
    return open_session(ZenohSettings(endpoints=[endpoint], **kw))  # type: ignore[arg-type]


def put_once_subscribed(session: zenoh.Session, key: str, payload: bytes) -> None:
    """Put ``payload`` on ``key`` once a subscriber's route has reached ``session`` (a put before
    that goes nowhere), waiting for that rather than for a fixed time."""
    with Publisher(session, key) as pub:
        assert pub.wait_for_subscribers(10), f"no subscriber for {key} reached the publisher"
        pub.put(payload)


# ---- integration ------------------------------------------------------------------------------


@pytest.mark.integration
def test_router_exits_cleanly_on_sigint_and_sigterm() -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        child = start_router(endpoint)
        with client(endpoint) as s:
            assert s.info.routers_zid()
        t = time.monotonic()
        assert child.stop(sig) == 0, "".join(child.output)
        assert time.monotonic() - t < 5
        assert any("router exited cleanly" in line for line in child.output)


@pytest.mark.integration
def test_pub_sub_delivers_messages_in_order(router: str) -> None:
    key = keys.primary_meas("pubsub")
    with (
        client(router) as a,
        client(router) as b,
        Subscriber(b, keys.PRIMARY_MEAS) as sub,
        Publisher(a, key) as pub,
    ):
        assert pub.wait_for_subscribers(10)
        sent = [
            Measurement(
                episode="pubsub",
                sender="sim",
                k=k,
                t_sensor=T0 + k,
                sensor="p",
                z=[[1000.0 + k, 0.1]],
            )
            for k in range(200)
        ]
        for m in sent:
            pub.put(m)
        got: list[Measurement] = []
        while len(got) < len(sent):
            r = sub.recv_message(Measurement, timeout=10)
            assert r is not None, f"only {len(got)} of {len(sent)} arrived"
            item, msg = r
            assert item.key == key and item.is_put
            got.append(msg)
        assert got == sent
        assert sub.dropped == 0 and pub.sent == 200


@pytest.mark.integration
def test_subscriber_counts_rejects_and_skips_them(router: str) -> None:
    key = keys.transfer("s1", "rej")
    good = Transfer(
        episode="rej",
        sender="s1",
        k=0,
        k_apply=1,
        t_sensor=T0,
        sensor=RADAR,
        eta=[1.0, 2.0],
        P_eta=[[1.0, 0.0], [0.0, 1.0]],
    )
    rejects = RejectCounter()
    with (
        client(router) as a,
        client(router) as b,
        Subscriber(b, keys.TRANSFERS) as sub,
        Publisher(a, key) as pub,
    ):
        assert pub.wait_for_subscribers(10)
        pub.put(b"\xc1garbage")
        pub.put(encode(good)[:-2])
        pub.put(good)
        r = sub.recv_message(Transfer, timeout=10, rejects=rejects)
        assert r is not None and r[1] == good
    assert rejects.total == 2 and rejects.count(key=key, reason="not_msgpack") == 2


@pytest.mark.integration
def test_one_inbox_for_several_keys(router: str) -> None:
    with (
        client(router) as a,
        client(router) as b,
        Subscriber(b, [keys.EPISODES, keys.PRIMARY_MEAS]) as sub,
    ):
        put_once_subscribed(a, keys.episode("multi"), b"1")
        put_once_subscribed(a, keys.primary_meas("multi"), b"2")
        got = {sub.recv(10).key, sub.recv(10).key}  # type: ignore[union-attr]
        assert got == {keys.episode("multi"), keys.primary_meas("multi")}


@pytest.mark.integration
def test_full_queue_drops_oldest_without_blocking_others(router: str) -> None:
    with client(router) as a, client(router) as b:
        slow = Subscriber(b, "tltrack/test/slow", capacity=10)
        fast = Subscriber(b, "tltrack/test/fast")
        with slow, fast:
            pub_slow = Publisher(a, "tltrack/test/slow")
            pub_fast = Publisher(a, "tltrack/test/fast")
            assert pub_slow.wait_for_subscribers(10) and pub_fast.wait_for_subscribers(10)
            for i in range(50):
                pub_slow.put(str(i).encode())
                pub_fast.put(str(i).encode())
            fast_got = [fast.recv(10) for _ in range(50)]
            assert all(r is not None for r in fast_got)
            deadline = time.monotonic() + 10
            while slow.received < 50 and time.monotonic() < deadline:
                time.sleep(0.01)
            assert slow.received == 50 and slow.dropped == 40 and len(slow) == 10
            assert [r.payload for r in slow.drain()] == [str(i).encode() for i in range(40, 50)]
            pub_slow.close()
            pub_fast.close()


@pytest.mark.integration
def test_queryable_answers_a_get(router: str) -> None:
    seen: list[dict[str, str]] = []

    def answer(params: dict[str, str]) -> bytes:
        seen.append(params)
        return json.dumps({"runs": 3, "rmse": 14.3}).encode()

    with client(router) as a, client(router) as b, Queryable(a, keys.SCORER_SUMMARY, answer) as q:
        deadline = time.monotonic() + 10
        replies: list[Received] = []
        while not replies and time.monotonic() < deadline:
            replies = query(b, keys.SCORER_SUMMARY + "?episode=e1", timeout=2)
        assert len(replies) == 1
        assert replies[0].key == keys.SCORER_SUMMARY
        assert json.loads(replies[0].payload) == {"runs": 3, "rmse": 14.3}
        assert seen[-1] == {"episode": "e1"} and q.served >= 1
        # a glob query is answered on the queryable's concrete key, and promptly
        t = time.monotonic()
        replies = query(b, "tltrack/scorer/*", timeout=5)
        assert [r.key for r in replies] == [keys.SCORER_SUMMARY]
        assert time.monotonic() - t < 2
    with pytest.raises(ValueError):
        Queryable(a, "tltrack/scorer/*", answer)


@pytest.mark.integration
def test_queryable_failure_becomes_an_error_reply(router: str) -> None:
    def broken(_params: dict[str, str]) -> bytes:
        raise RuntimeError("boom")

    with client(router) as a, client(router) as b, Queryable(a, "tltrack/test/broken", broken):
        # ask until the queryable's route has reached b (a get before that has no answer)
        errors: list[Any] = []
        deadline = time.monotonic() + 10
        while not errors and time.monotonic() < deadline:
            t = time.monotonic()
            errors = [r.err for r in b.get("tltrack/test/broken", timeout=5) if r.err is not None]
        assert errors and b"boom" in errors[0].payload.to_bytes()
        assert time.monotonic() - t < 3  # the failed query was finalized, not timed out
        t = time.monotonic()
        assert query(b, "tltrack/test/broken", timeout=5) == []
        assert time.monotonic() - t < 3  # the failed query was finalized, not timed out


HOLDER_CODE = """
    import sys, time
    from tltrack.wire.transport import ZenohSettings, declare_token, open_session
    with open_session(ZenohSettings(endpoints=[sys.argv[1]])) as session:
        token = declare_token(session, sys.argv[2])
        print("holding", flush=True)
        time.sleep(120)
"""


@pytest.mark.integration
def test_liveliness_token_of_a_killed_process_disappears(router: str) -> None:
    token_key = keys.alive("source/s1", "source_tracker")
    changes: list[tuple[str, bool]] = []
    with (
        client(router) as watcher_session,
        LivelinessWatcher(
            watcher_session, keys.ALIVE, on_change=lambda k, up: changes.append((k, up))
        ) as watcher,
    ):
        holder = Child(HOLDER_CODE, router, token_key)
        try:
            holder.wait_line("holding")
            assert watcher.wait_until(token_key, alive=True, timeout=10)
            assert token_key in watcher.alive()
            holder.proc.kill()  # SIGKILL: no chance to undeclare anything
            t = time.monotonic()
            assert watcher.wait_until(token_key, alive=False, timeout=10)
            gone_after = time.monotonic() - t
        finally:
            if holder.proc.poll() is None:
                holder.proc.kill()
            holder.proc.wait(10)
        assert gone_after < 5
        assert changes == [(token_key, True), (token_key, False)]


@pytest.mark.integration
def test_liveliness_history_and_undeclare(router: str) -> None:
    key = keys.alive("primary", "primary_tracker")
    with client(router) as a, client(router) as b:
        token = declare_token(a, key)
        with LivelinessWatcher(b, key) as first:  # the token has reached the router
            assert first.wait_until(key, alive=True, timeout=10)
        # declared before the watcher: reported through history
        with LivelinessWatcher(b, keys.alive("primary", "*")) as watcher:
            assert watcher.wait_until(key, alive=True, timeout=10)
            token.undeclare()
            assert watcher.wait_until(key, alive=False, timeout=10)
        with Subscriber(b, keys.ALIVE, liveliness=True, history=True) as sub:
            with declare_token(a, keys.alive("referee", "scorer")):
                r = sub.recv(10)
                assert r is not None and r.key == keys.alive("referee", "scorer") and r.is_put
            r = sub.recv(10)
            assert r is not None and r.kind == zenoh.SampleKind.DELETE


# ---- security ---------------------------------------------------------------------------------


@pytest.mark.integration
def test_user_password_authentication(tmp_path: Path) -> None:
    users = tmp_path / "users.txt"
    users.write_text("primary:pw-primary\nsim:pw-sim\n")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router_proc = start_router(endpoint, usrpwd_dictionary_file=str(users))
    try:
        with (
            client(endpoint, username="sim", password="pw-sim") as a,
            client(endpoint, username="primary", password="pw-primary") as b,
            Subscriber(b, "tltrack/test/auth") as sub,
        ):
            put_once_subscribed(a, "tltrack/test/auth", b"ok")
            r = sub.recv(10)
            assert r is not None and r.payload == b"ok"
        with pytest.raises(zenoh.ZError):
            client(endpoint, username="primary", password="wrong", connect_timeout_ms=2000)
        with pytest.raises(zenoh.ZError):
            client(endpoint, connect_timeout_ms=2000)  # no credentials at all
    finally:
        assert router_proc.stop() == 0


ACL = {
    "enabled": True,
    "default_permission": "allow",
    "rules": [
        {
            "id": "source-private",
            "messages": ["put", "declare_subscriber", "query", "reply", "declare_queryable"],
            "flows": ["ingress", "egress"],
            "permission": "deny",
            "key_exprs": ["tltrack/source/*/meas/**", "tltrack/source/*/estimate/**"],
        }
    ],
    "subjects": [{"id": "primary-operator", "usernames": ["primary"]}],
    "policies": [{"id": "p1", "rules": ["source-private"], "subjects": ["primary-operator"]}],
}


@pytest.mark.integration
def test_acl_by_operator_prefix(tmp_path: Path) -> None:
    """The key layout lets an ACL hide a source's raw data from the primary but not transfers."""
    users = tmp_path / "users.txt"
    users.write_text("primary:pw1\nsource:pw2\n")
    acl = tmp_path / "acl.json5"
    acl.write_text(json.dumps(ACL))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router_proc = start_router(
        endpoint, usrpwd_dictionary_file=str(users), access_control_file=str(acl)
    )
    try:
        with (
            client(endpoint, username="source", password="pw2") as src,
            client(endpoint, username="primary", password="pw1") as prim,
            Subscriber(prim, "tltrack/source/**") as sub,
            Publisher(src, keys.transfer("s1", "e1")) as transfer,
        ):
            # the primary's subscription has reached the source (the transfer may go to it)
            assert transfer.wait_for_subscribers(10)
            src.put(keys.source_meas("s1", "e1"), b"raw")
            src.put(keys.source_estimate("s1", "e1"), b"estimate")
            transfer.put(b"transfer")
            r = sub.recv(10)
            assert r is not None and r.key == keys.transfer("s1", "e1")
            assert sub.recv(1.0) is None
    finally:
        assert router_proc.stop() == 0


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl CLI")
@pytest.mark.integration
def test_mutual_tls(tmp_path: Path) -> None:
    make_certs(tmp_path, names="primary")  # scripts/make_certs.sh
    port = free_port()
    router_proc = start_router(
        f"tls/127.0.0.1:{port}",
        tls_root_ca=str(tmp_path / "ca.pem"),
        tls_cert=str(tmp_path / "router.pem"),
        tls_key=str(tmp_path / "router.key"),
        tls_mtls=True,
    )
    tls = {
        "tls_root_ca": str(tmp_path / "ca.pem"),
        "tls_cert": str(tmp_path / "primary.pem"),
        "tls_key": str(tmp_path / "primary.key"),
        "tls_mtls": True,
    }
    endpoint = f"tls/localhost:{port}"
    try:
        with (
            client(endpoint, **tls) as a,
            client(endpoint, **tls) as b,
            Subscriber(b, "tltrack/test/tls") as sub,
        ):
            put_once_subscribed(a, "tltrack/test/tls", b"secret")
            r = sub.recv(10)
            assert r is not None and r.payload == b"secret"
        # without a client certificate the router refuses the link
        with pytest.raises(zenoh.ZError):
            client(endpoint, tls_root_ca=str(tmp_path / "ca.pem"), connect_timeout_ms=2000)
        # plain TCP to a TLS port goes nowhere
        with pytest.raises(zenoh.ZError):
            client(f"tcp/127.0.0.1:{port}", connect_timeout_ms=2000)
    finally:
        assert router_proc.stop() == 0


@pytest.mark.integration
def test_decode_of_a_received_sample_is_the_only_entry(router: str) -> None:
    """What the primary does with a transfer: decode it from the wire payload."""
    key = keys.transfer("s1", "dec")
    msg = Transfer(
        episode="dec",
        sender="s1",
        k=4,
        k_apply=5,
        t_sensor=T0,
        sensor=RADAR,
        eta=[10.0, 0.2],
        P_eta=[[2.0, 0.1], [0.1, 1.0]],
    )
    with client(router) as a, client(router) as b, Subscriber(b, key) as sub:
        put_once_subscribed(a, key, encode(msg))
        r = sub.recv(10)
        assert r is not None and decode(r.payload, Transfer) == msg
        info = keys.parse(r.key)
        assert (info.source, info.episode) == ("s1", "dec")


@pytest.mark.integration
def test_background_router_in_a_thread() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        background_router([endpoint]),
        client(endpoint) as a,
        client(endpoint) as b,
        Subscriber(b, "tltrack/test/bg") as sub,
    ):
        put_once_subscribed(a, "tltrack/test/bg", b"x")
        r = sub.recv(10)
        assert r is not None and r.payload == b"x"
