"""The federated topology with real routers and processes: a router per operator, and a relay on
every link between routers that keeps each byte it forwards (tests/relay.py).

The sentinels are the raw measurements themselves (:func:`relay.sentinels`): each component of z
travels as its own 9 bytes, unique to one operator's sensor.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from livestack import (
    end_episode_once,
    estimates,
    logs,
    mostly_used,
    primary_stats,
    sim_flags,
    wait_until,
)
from relay import Relay, found, sentinels
from security_helpers import make_certs, session
from tltrack.config import Config, make_config
from tltrack.engine.montecarlo import trace_run
from tltrack.engine.scenario import measurements, reports, truth
from tltrack.engine.setup import Setup
from tltrack.live import supervisor, topology
from tltrack.wire import keys
from tltrack.wire.transport import Publisher, Subscriber

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]

#: (dialler, dialled): every link between routers
LINKS = [("source/s1", "primary"), ("source/s1", keys.REFEREE), ("primary", keys.REFEREE)]
K, N = 30, 500
SIM = dict(preset="arasaratnam-haykin", truth="fixed", seed=7)


#: both radars in clutter (the relay test's episode): every detection is raw data
CLUTTER = {
    "primary_detection": {"pd": 0.9, "clutter_rate": 5.0},
    "sources": [{"id": "s1", "detection": {"pd": 0.9, "clutter_rate": 3.0}}],
}


def config(steps: int = K, **more: Any) -> Config:
    return make_config(**SIM, K=steps, particles=N, recovery=True, **more)  # recovery: trackers'


@contextlib.contextmanager
def federation(
    tmp: Path, lag_s: dict[tuple[str, str], float] | None = None
) -> Iterator[tuple[supervisor.Stack, dict[tuple[str, str], Relay]]]:
    """A federated stack whose routers dial each other through relays (not yet started);
    ``lag_s``: links slow towards their dialler."""
    topo = topology.federated(["s1"])
    lag = lag_s or {}
    with contextlib.ExitStack() as stack:
        relays = {
            link: stack.enter_context(
                Relay(topo.routers[link[1]].endpoint, lag_s=lag.get(link, 0.0))
            )
            for link in LINKS
        }
        topo = dataclasses.replace(topo, via={link: r.endpoint for link, r in relays.items()})
        s = stack.enter_context(
            supervisor.Stack(topo.referee.endpoint, tmp / "logs", topology=topo)
        )
        yield s, relays


#: the filters of a live episode, as the engine names them
LIVE = ("tl-rpf", "rpf", "source-rpf")


def every_step(db: Path, s: supervisor.Stack) -> dict[str, dict[int, tuple[list[float], bool]]]:
    """The scorer's record of the episode, which must hold every step of every filter."""
    live = estimates(db)
    steps = {name: sorted(live.get(name, {})) for name in LIVE}
    assert all(ks == list(range(1, K + 1)) for ks in steps.values()), (steps, logs(s))
    return live


def run_episode(
    s: supervisor.Stack,
    db: Path,
    steps: int,
    pace: float,
    primary_env: dict[str, str] | None = None,
    sensor_env: dict[str, dict[str, str]] | None = None,
    sim_config: Path | None = None,
    source_env: dict[str, str] | None = None,
) -> None:
    """The scorer, the trackers and the sensors, then sensor_sim (routers already started);
    ``sim_config``: a config file for the episodes, over the test's defaults."""
    s.start_service("scorer", env={"TLTRACK_SCORER_DB": str(db), "TLTRACK_SCORER_GRACE_S": "3"})
    s.start_service("primary_tracker", env=primary_env)
    s.start_service("source_tracker", identity="source-s1", env=source_env)
    cfg = config(steps)
    for sid, user in (("primary", "primary"), ("s1", "source-s1")):
        env = {"TLTRACK_SENSOR_SENSOR": sid, **(sensor_env or {}).get(sid, {})}
        s.start_service(f"sensor_{sid}", service="sensor", identity=user, env=env)
    wait = ["primary:primary_tracker", "referee:scorer", "source/s1:source_tracker"]
    wait += ["primary:sensor", "source/s1:sensor"]
    s.wait_transfer_routes(["s1"])
    s.start_service(
        "sensor_sim",
        *sim_flags(steps, N, pace=pace),
        *([f"--config={sim_config}"] if sim_config else []),
        env={**supervisor.sim_env(wait), "TLTRACK_SIM_WAIT_TIMEOUT_S": "60"},
    )
    assert steps == cfg.K


def test_raw_data_never_leaves_its_owners_router_and_lockstep_equals_the_engine(tmp_path):
    """Both radars in clutter: no detection of either (nor the truth) crosses a link between
    routers, and the lock-step estimates are the engine's. Also a slow link that costs no transfer:
    the primary's subscription reaches the source's router 0.3 s late, long after the tokens
    sensor_sim awaits. The stack waits for that route (Stack.wait_transfer_routes), so the
    source's first transfers are not dropped there and the lock-step primary takes every step
    with a transfer."""
    db = tmp_path / "scorer.sqlite"
    given = tmp_path / "clutter.json"
    given.write_text(json.dumps(CLUTTER))
    with (
        federation(tmp_path, {("source/s1", "primary"): 0.3}) as (s, relays),
        Relay(s.topology.routers["source/s1"].endpoint) as tap,
    ):
        s.start_router()
        # a tap between the source's sensor and its own router: the sentinels do travel there
        run_episode(
            s,
            db,
            K,
            0.0,
            primary_env={"TLTRACK_PRIMARY_LOCKSTEP": "true"},
            sensor_env={"s1": {"TLTRACK_ZENOH_ENDPOINTS": json.dumps([tap.endpoint])}},
            sim_config=given,
        )
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        assert supervisor.wait_for_scored(s.endpoint, 1, 120, "referee") is not None, logs(s)
        live = every_step(db, s)
        wire = {link: r.bytes() for link, r in relays.items()}
        local = tap.bytes()
    cfg = config(**CLUTTER)
    x = truth(Setup(cfg), 0)
    raw = {
        sid: sentinels(np.concatenate(reports(Setup(cfg), 0, x, sid))) for sid in ("primary", "s1")
    }
    assert found(raw["s1"], local) == len(raw["s1"]), "the sentinels are not what travels"
    # the source's link carried every step's transfer (each names its kind once)
    assert wire["source/s1", "primary"].count(b"\xa8transfer") >= K - 1
    for link, data in wire.items():
        assert data, link
        assert found(raw["s1"], data) == 0, f"source s1's raw data on {link}"
        assert found(raw["primary"], data) == 0, f"the primary's raw data on {link}"
        assert found(sentinels(x[1:]), data) == 0, f"the truth on {link}"
    assert b"\xa8transfer" in wire["source/s1", "primary"], "no transfer on the source's link"
    assert b"\xa8transfer" not in wire["source/s1", keys.REFEREE]
    assert b"\xa8transfer" not in wire["primary", keys.REFEREE]

    offline = trace_run(cfg, list(LIVE), run=0)
    for name in LIVE:
        got = np.array([live[name][k][0] for k in range(1, K + 1)])
        np.testing.assert_allclose(got, offline[name], rtol=0, atol=1e-9, err_msg=name)
    assert [live["tl-rpf"][k][1] for k in range(1, K + 1)] == [False] + [True] * (K - 1)


#: a source sampling every 2 s, its clock a quarter second ahead of the primary's
VEHICLES = {
    "max_clock_offset_s": 0.25,
    "sources": [{"id": "s1", "period_s": 2.0, "clock_offset_s": 0.25}],
}


def test_on_their_own_clocks_the_schedule_crosses_the_routers_and_lockstep_equals_the_engine(
    tmp_path,
):
    """The primary's schedule goes from its router to the source's (the routers' ACLs let that
    key, and nothing else of the primary, out to a source); the source addresses its transfers
    by it, and the lock-step estimates are the engine's."""
    steps = 16
    db = tmp_path / "scorer.sqlite"
    given = tmp_path / "vehicles.json"
    given.write_text(json.dumps(VEHICLES))
    with federation(tmp_path) as (s, relays):
        s.start_router()
        run_episode(s, db, steps, 0.0, {"TLTRACK_PRIMARY_LOCKSTEP": "true"}, sim_config=given)
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        assert supervisor.wait_for_scored(s.endpoint, 1, 120, "referee") is not None, logs(s)
        live = estimates(db)
        direct = relays["source/s1", "primary"].bytes()  # both ways
    assert b"\xa8schedule" in direct, "no schedule on the primary-source link"
    cfg = config(steps, **VEHICLES)
    offline = trace_run(cfg, list(LIVE), run=0)
    for name in LIVE:
        n = cfg.timeline.steps("s1") if name.startswith("source-") else steps
        got = np.array([live[name][k][0] for k in range(1, n + 1)])
        np.testing.assert_allclose(got, offline[name], rtol=0, atol=1e-9, err_msg=name)
    # the source's first step, at 2 s, sends for the primary's 3 s: every step from there is TL
    assert [live["tl-rpf"][k][1] for k in range(1, steps + 1)] == [False] * 2 + [True] * 14


def test_the_owner_enforces_even_against_a_primary_router_that_allows_everything(tmp_path):
    """The primary's router runs without access control, and a client on it subscribes to every
    key: it still gets none of the source's raw data, since the source's router never lets it
    out."""
    db = tmp_path / "scorer.sqlite"
    open_acl = tmp_path / "allow-everything.json5"
    open_acl.write_text('{ enabled: false, default_permission: "allow" }')
    with federation(tmp_path) as (s, relays):
        topo = s.topology
        for r in topo.routers.values():
            acl = {"TLTRACK_ZENOH_ACCESS_CONTROL_FILE": str(open_acl)}
            s.start_operator_router(r.operator, acl if r.operator == "primary" else None)
        with (
            supervisor.client(topo.routers["primary"].endpoint, "primary") as z,
            Subscriber(z, [keys.ALL, "tltrack/source/s1/meas/*"]) as sub,
        ):
            run_episode(s, db, K, 0.0)
            assert s.wait("sensor_sim", 120) == 0, logs(s)
            assert supervisor.wait_for_scored(s.endpoint, 1, 120, "referee") is not None, logs(s)
            got = [item.key for item in sub.drain()]
        wire = relays["source/s1", "primary"].bytes()
    cfg = config()
    assert not [k for k in got if k.startswith("tltrack/source/s1/meas/")]
    assert any(k.startswith("tltrack/source/s1/transfer/") for k in got), "no transfer seen"
    assert any(k.startswith("tltrack/primary/meas/") for k in got), "the open router is not open"
    assert found(sentinels(measurements(Setup(cfg), 0, truth(Setup(cfg), 0), "s1")), wire) == 0


FAULT_K = 200
#: an episode that outlasts the slowest recovery seen (a restarted router and its services'
#: reconnection took 10 s on a loaded machine); it ends once the test has seen the steps after it
RECOVERY_K = 1000
#: the steps the primary takes after the fault is over before the episode ends: its reconnection
#: first, then 21 judged steps
AFTER = 60


def _transfer_use(db: Path) -> dict[int, bool]:
    return {k: used for k, (_x, used) in estimates(db).get("tl-rpf", {}).items()}


def _why(db: Path, s: supervisor.Stack) -> str:
    """Why steps went without their transfer: a cut (the primary logs it) or a deadline passed
    (it counts them); read only when an assertion fails."""
    return f"{primary_stats(db).get('counters')}\n{logs(s)}"


def _reached(db: Path, k: int, name: str = "tl-rpf") -> bool:
    """Whether ``name``'s estimates reached step ``k``."""
    return max(estimates(db).get(name, {}), default=0) >= k


@pytest.mark.xdist_group("live")  # 20 steps a second, a 20 ms deadline: never beside a stack
@pytest.mark.parametrize("fault", ["link-cut", "primary-router-restarts", "source-router-gone"])
def test_faults_between_routers(tmp_path, fault):
    """Cut the source-primary link (the primary steps isolated, then transfer resumes), restart
    the primary's router (its services reconnect), or stop the source's router for good (the
    primary carries on alone); asserted on the scorer's record."""
    db = tmp_path / "scorer.sqlite"
    recovers = fault != "source-router-gone"
    K = RECOVERY_K if recovers else FAULT_K
    with federation(tmp_path) as (s, relays):
        s.start_router()
        # The primary's router still knows the source's router, through the referee's (the
        # routers share one link-state graph), so the source's token outlives a cut link: the
        # primary waits deadline_ms for each transfer, which the referee's router drops. Keep
        # that wait under the step period (50 ms), with room for a loaded machine's delays.
        run_episode(s, db, K, 20.0, primary_env={"TLTRACK_PRIMARY_DEADLINE_MS": "40"})
        assert wait_until(lambda: _reached(db, 30), 90), logs(s)
        if fault == "link-cut":
            relays["source/s1", "primary"].cut()
        else:
            s.kill("router_primary" if fault == "primary-router-restarts" else "router_source-s1")
        hit = max(_transfer_use(db))
        # the clock: the tracker that the fault leaves in reach of the referee
        clock = "source-rpf" if fault == "primary-router-restarts" else "rpf"
        assert wait_until(lambda: _reached(db, hit + 30, clock), 60), logs(s)
        if fault == "link-cut":
            relays["source/s1", "primary"].restore()
        elif fault == "primary-router-restarts":
            s.start_operator_router("primary")
        back = max(_transfer_use(db), default=hit)
        if recovers:
            seen = end_episode_once(s, lambda: _reached(db, back + AFTER), 60)
            assert seen, f"the primary took no {AFTER} steps after the fault\n" + logs(s)
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        assert supervisor.wait_for_scored(s.endpoint, 1, 120, "referee") is not None, logs(s)
    used = _transfer_use(db)
    # from step 4: a tracker's first steps are its kernels' first calls, late on a loaded machine
    before = [used[k] for k in range(4, hit - 1)]
    assert mostly_used(before), f"transfer unused before the fault: {before}\n{_why(db, s)}"
    during = [used[k] for k in range(hit + 5, hit + 25) if k in used]
    if fault == "primary-router-restarts":  # its sensor had no clock: gaps, not estimates
        assert not during, "the primary stepped while its router was down"
    else:
        assert during and not any(during), "transfer used while the source was out of reach"
    last = max(used)
    if fault == "source-router-gone":
        tail = [used.get(k, False) for k in range(last - 20, last + 1)]
        assert sorted(used) == list(range(1, K + 1)), "the primary missed steps"
        assert not any(tail), "transfer after the source's router went away"
    else:
        # from the first step that used it again to the end (at least AFTER steps): one late
        # heartbeat on a loaded machine cuts the link for a few steps, and it comes back
        first = min((k for k in used if k > back and used[k]), default=None)
        assert first is not None, f"transfer did not resume after step {back}"
        resumed = [used.get(k, False) for k in range(first, last + 1)]
        assert mostly_used(resumed), f"transfer did not stay resumed: {resumed}\n{_why(db, s)}"


def _tls_env(ca: Path, cert: Path) -> dict[str, str]:
    return {
        "TLTRACK_ZENOH_TLS_ROOT_CA": str(ca),
        "TLTRACK_ZENOH_TLS_CERT": str(cert),
        "TLTRACK_ZENOH_TLS_KEY": str(cert.with_suffix(".key")),
        "TLTRACK_ZENOH_TLS_MTLS": "true",
    }


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl")
@pytest.mark.parametrize("issuer", ["operators-ca", "another-ca"])
def test_a_router_without_a_certificate_from_the_operators_ca_is_refused(tmp_path, issuer):
    """The referee's router listens with mutual TLS; the primary's router dials it with a
    certificate from the operators' CA (episodes flow) or from another CA (refused)."""
    certs = make_certs(tmp_path / "certs", names="sensor router-primary")
    rogue = make_certs(tmp_path / "rogue", names="router-primary")
    port = supervisor.free_port()
    topo = dataclasses.replace(
        topology.federated([]),
        via={("primary", keys.REFEREE): f"tls/localhost:{port}"},
    )
    ref = dataclasses.replace(topo.referee, endpoint=f"tls/127.0.0.1:{port}")
    topo = dataclasses.replace(topo, routers={**topo.routers, keys.REFEREE: ref})
    signer = certs if issuer == "operators-ca" else rogue
    with supervisor.Stack(topo.referee.endpoint, tmp_path / "logs", topology=topo) as s:
        for r in topo.routers.values():
            cert = certs / "router.pem" if r is ref else signer / "router-primary.pem"
            s.start_operator_router(r.operator, _tls_env(certs / "ca.pem", cert))
            s.wait_listening(f"router_{r.name}")
        tls = {
            "tls_root_ca": certs / "ca.pem",
            "tls_cert": certs / "sensor.pem",
            "tls_key": certs / "sensor.key",
            "tls_mtls": True,
        }
        with (
            session(f"tls/localhost:{port}", "sensor", connect_timeout_ms=20_000, **tls) as ref_z,
            supervisor.client(topo.routers["primary"].endpoint, "primary") as prim_z,
            Subscriber(prim_z, keys.EPISODES) as episodes,
            Publisher(ref_z, keys.episode("e1")) as pub,
        ):
            # a refusal waits it out; an admitted link ends it at its first announcement
            deadline = time.monotonic() + 15
            while time.monotonic() < deadline and not episodes.received:
                pub.put(b"an episode announcement")
                time.sleep(0.2)
            received = episodes.received
        router_log = (s.logs / "router_referee.log").read_text()
    assert router_log.count("listening on") == 1
    assert (received > 0) is (issuer == "operators-ca"), received


def test_each_operators_sensor_replays_its_own_rows(tmp_path):
    """Each operator's sensor replays a file of its own rows only (here the engine's draws, so
    the lock-step episode must equal the engine's)."""
    cfg = config()
    x = truth(Setup(cfg), 0)
    replays = {}
    for sid in ("primary", "s1"):
        model = Setup(cfg).sensor(sid)
        path = replays[sid] = tmp_path / f"{sid}.csv"
        with path.open("w", newline="") as fh:
            out = csv.writer(fh)
            out.writerow(["k", "sensor", *model.components])
            for k, z in enumerate(measurements(Setup(cfg), 0, x, sid), start=1):
                out.writerow([k, sid, *(repr(float(v)) for v in z)])
    db = tmp_path / "scorer.sqlite"
    with federation(tmp_path) as (s, _relays):
        s.start_router()
        run_episode(
            s,
            db,
            K,
            0.0,
            primary_env={"TLTRACK_PRIMARY_LOCKSTEP": "true"},
            sensor_env={sid: {"TLTRACK_SENSOR_REPLAY_CSV": str(p)} for sid, p in replays.items()},
        )
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        assert supervisor.wait_for_scored(s.endpoint, 1, 120, "referee") is not None, logs(s)
        for sid in ("primary", "s1"):
            assert "replaying" in (s.logs / f"sensor_{sid}.log").read_text(), logs(s)
        live = every_step(db, s)
    offline = trace_run(cfg, list(LIVE), run=0)
    for name in LIVE:
        got = np.array([live[name][k][0] for k in range(1, K + 1)])
        np.testing.assert_allclose(got, offline[name], rtol=0, atol=1e-9, err_msg=name)
