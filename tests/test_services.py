"""The four services and a router as real processes over loopback Zenoh."""

import contextlib
import json
import shutil
import sqlite3

import msgpack
import numpy as np
import pytest
from livestack import (
    connecting,
    estimates,
    logs,
    mostly_used,
    sim_flags,
    stack,
    start_all,
    wait_until,
)
from tltrack.config import make_config
from tltrack.engine.montecarlo import trace_run
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import Setup
from tltrack.live import latency, supervisor
from tltrack.wire import keys
from tltrack.wire.messages import SCHEMA_VERSION

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]


#: a primary radar that misses the target one scan in ten among 5 false alarms a scan, and a
#: source that misses one in ten among 0.5 (some of its scans are empty: two of this run's 30)
CLUTTER = {
    "primary_detection": {"pd": 0.9, "clutter_rate": 5.0},
    "sources": [{"id": "s1", "detection": {"pd": 0.9, "clutter_rate": 0.5}}],
}


def _empty_scans(cfg) -> dict[str, int]:
    """Each tracker's empty scans in run 0, as the scorer's summary names the trackers."""
    scans = simulate(Setup(cfg), 0).scans
    trackers = {"primary": "primary/primary_tracker", "s1": "source/s1/source_tracker"}
    empty = {trackers[sid]: sum(len(d) == 0 for d in scans[sid].detections) for sid in trackers}
    return {name: n for name, n in empty.items() if n}


@pytest.mark.parametrize(
    ("robust", "clutter"),
    [(False, False), (True, False), (False, True)],
    ids=["tl-rpf", "robust-tl-rpf", "tl-rpf-in-clutter"],
)
def test_lockstep_episode_equals_the_offline_engine(tmp_path, robust, clutter):
    """The live services step exactly as the engine; in clutter, every scan goes on the wire."""
    db = tmp_path / "scorer.sqlite"
    K, N = 30, 500
    tl = "robust-tl-rpf" if robust else "tl-rpf"
    primary_env = {"TLTRACK_PRIMARY_LOCKSTEP": "true", "TLTRACK_PRIMARY_ROBUST": str(robust)}
    sim = sim_flags(K, N, pace=0)
    if clutter:
        given = tmp_path / "clutter.json"
        given.write_text(json.dumps(CLUTTER))
        sim.append(f"--config={given}")
    cfg = make_config(
        preset="arasaratnam-haykin",
        truth="fixed",
        seed=7,
        K=K,
        particles=N,
        recovery=True,  # the trackers' default, as the engine's is off
        **(CLUTTER if clutter else {}),
    )
    with stack(tmp_path) as s:
        start_all(s, db, primary_env=primary_env, sim=sim)
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        summary = supervisor.wait_for_scored(s.endpoint, 1, 120)
        assert summary is not None, logs(s)
        if clutter:  # each tracker counts the empty scans it stepped through; the scorer shows it
            want = _empty_scans(cfg)
            assert want, "no empty scan in this run: the check would prove nothing"

            def shown() -> dict:
                now = supervisor.wait_for_scored(s.endpoint, 1, 10)
                return {} if now is None else now["messages"]["empty_scans"]

            assert wait_until(lambda: shown() == want, 10), (shown(), want)
    offline = trace_run(cfg, [tl, "rpf", "source-rpf"], run=0)
    live = estimates(db)
    for name in (tl, "rpf", "source-rpf"):
        x = np.array([live[name][k][0] for k in range(1, K + 1)])
        np.testing.assert_allclose(x, offline[name], rtol=0, atol=1e-9, err_msg=name)
    used = [live[tl][k][1] for k in range(1, K + 1)]
    if robust:  # the first steps gather evidence about the source before using it
        assert not any(used[:3]) and sum(used) >= K // 2, used
    else:
        assert used == [False] + [True] * (K - 1)
    # the TL estimate goes out first; the isolated twin steps twin_delay_ms (2) later, unless
    # it stepped inside the robust TL step
    with contextlib.closing(sqlite3.connect(db)) as con:
        rows = con.execute(
            "SELECT twin.t_step - tl.t_sent FROM estimates AS tl JOIN estimates AS twin"
            " ON tl.episode = twin.episode AND tl.k = twin.k"
            " WHERE tl.filter = ? AND twin.filter = 'rpf'",
            (tl,),
        ).fetchall()
    assert len(rows) == K
    assert min(r[0] for r in rows) >= (0.0 if robust else 0.002), rows
    # where the time goes: every estimate timed its stages, and the two hops take time
    for where in [summary, *summary["filters"].values()]:
        stages = where["stages_ms"]
        assert list(stages) == list(latency.STAGES) and None not in stages.values(), stages
        assert stages["to_tracker"] > 0 and stages["step"] > 0 and stages["to_receiver"] > 0


#: a source sampling 4 times slower than the primary, its clock a quarter period ahead
VEHICLES = {
    "max_clock_offset_s": 0.25,
    "sources": [{"id": "s1", "period_s": 4.0, "clock_offset_s": 0.25}],
}


def test_a_lockstep_episode_on_their_own_clocks_equals_the_offline_engine(tmp_path):
    """Each operator samples at its own rate and stamps with its own clock: the source steps at
    4, 8, ... s and sends, after each step, a transfer for each of the primary's next four
    samples (t_apply on the primary's schedule); the live estimates are the engine's."""
    db = tmp_path / "scorer.sqlite"
    K, N = 30, 500
    given = tmp_path / "vehicles.json"
    given.write_text(json.dumps(VEHICLES))
    cfg = make_config(
        preset="arasaratnam-haykin", truth="fixed", seed=7, K=K, particles=N, recovery=True,
        **VEHICLES,
    )  # fmt: skip
    steps = cfg.timeline.steps("s1")
    assert steps == K // 4
    with stack(tmp_path) as s:
        sim = [*sim_flags(K, N, pace=0), f"--config={given}"]
        start_all(s, db, primary_env={"TLTRACK_PRIMARY_LOCKSTEP": "true"}, sim=sim)
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        summary = supervisor.wait_for_scored(s.endpoint, 1, 120)
        assert summary is not None, logs(s)
    offline = trace_run(cfg, ["tl-rpf", "rpf", "source-rpf"], run=0)
    live = estimates(db)
    for name, n in (("tl-rpf", K), ("rpf", K), ("source-rpf", steps)):
        assert sorted(live[name]) == list(range(1, n + 1)), name
        x = np.array([live[name][k][0] for k in range(1, n + 1)])
        np.testing.assert_allclose(x, offline[name], rtol=0, atol=1e-9, err_msg=name)
    # nothing before the source's first step at 4 s; then every step has its transfer
    assert [live["tl-rpf"][k][1] for k in range(1, K + 1)] == [False] * 4 + [True] * (K - 4)
    # the scorer scored each at its own samples: the source's 7 against the truth at 4, 8, ...
    assert summary["filters"]["source-rpf"]["steps"] == steps
    assert summary["filters"]["source-rpf"]["gaps"] == 0
    x = simulate(Setup(cfg), 0).truth[cfg.timeline.indices("s1")]
    err = np.hypot(*(offline["source-rpf"] - x)[:, [0, 2]].T)
    assert summary["filters"]["source-rpf"]["rmse_overall"] == pytest.approx(err.mean(), rel=1e-9)


@pytest.mark.xdist_group("live")  # "isolated within 3 steps" at 20 steps a second
def test_killing_the_source_leaves_the_primary_going_isolated(tmp_path):
    db = tmp_path / "scorer.sqlite"
    K = 60
    with stack(tmp_path) as s:
        start_all(s, db, sim=sim_flags(K, 500, pace=20))
        assert wait_until(lambda: len(estimates(db).get("tl-rpf", {})) >= 20, 60), logs(s)
        # the scorer stores behind the primary: what it holds before the kill is surely before
        # it, and what it holds just after bounds the kill from above
        stored_before = max(estimates(db)["tl-rpf"])
        s.kill("source_tracker")
        killed_at = max(estimates(db)["tl-rpf"])
        assert s.wait("sensor_sim", 60) == 0, logs(s)
        summary = supervisor.wait_for_scored(s.endpoint, 1, 120)
        assert summary is not None, logs(s)
    tl = estimates(db)["tl-rpf"]
    assert sorted(tl) == list(range(1, K + 1)), "the primary missed steps"
    before = [tl[k][1] for k in range(2, stored_before - 1)]
    assert mostly_used(before), f"transfer unused before the kill: {before}"
    assert not any(tl[k][1] for k in range(killed_at + 3, K + 1)), "transfer after the kill"
    assert summary["filters"]["tl-rpf"]["steps_with_transfer"] < K - 10


def test_services_start_in_any_order_router_last(tmp_path):
    db = tmp_path / "scorer.sqlite"
    with stack(tmp_path) as s:
        s.start_service("sensor_sim", *sim_flags(20, 300, pace=0))
        s.start_service("source_tracker")
        s.start_service("scorer", env={"TLTRACK_SCORER_DB": str(db)})
        s.start_service("primary_tracker")
        # every service is up to its zenoh.open, waiting for the router, before it starts
        waiting = lambda: all(connecting(p.pid) for p in s.procs.values())  # noqa: E731
        assert wait_until(waiting, 60), logs(s)
        s.start_router()
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        summary = supervisor.wait_for_scored(s.endpoint, 1, 120)
        assert summary is not None, logs(s)
    for name in ("tl-rpf", "rpf", "source-rpf"):
        assert summary["filters"][name]["steps"] == 20
        assert summary["filters"][name]["gaps"] == 0


GARBAGE = [
    b"\x00\x01garbage",
    msgpack.packb({"schema_version": 1, "type": "measurement"})[:-3],
    msgpack.packb(
        {
            "schema_version": 99,
            "type": "measurement",
            "episode": "ep-r0",
            "sender": "x",
            "k": 1,
            "t_sensor": 0.0,
            "sensor": "primary",
            "z": [1.0, 0.1],
        }
    ),
    msgpack.packb(
        {
            "schema_version": SCHEMA_VERSION,
            "type": "transfer",
            "episode": "ep-r0",
            "sender": "s1",
            "k": 1,
            "t_sensor": 0.0,
            "k_apply": 2,
            "sensor": {"kind": "range-bearing", "position": [0.0, 0.0]},
            "eta": [1.0, float("nan")],
            "P_eta": [[1.0, 0.0], [0.0, 1.0]],
        }
    ),
]


def test_malformed_payloads_are_rejected_counted_and_survived(tmp_path):
    db = tmp_path / "scorer.sqlite"
    with stack(tmp_path) as s:
        s.start_router()
        s.start_service("scorer", env={"TLTRACK_SCORER_DB": str(db)})
        s.start_service("primary_tracker")
        s.start_service("source_tracker")
        subscribed = [
            keys.episode("ep-r0"),
            keys.primary_meas("ep-r0"),
            keys.source_meas("s1", "ep-r0"),
            keys.transfer("s1", "ep-r0"),
            keys.truth("ep-r0"),
            keys.primary_estimate("tl", "ep-r0"),
            keys.source_estimate("s1", "ep-r0"),
        ]
        with supervisor.client(s.endpoint) as session:
            from tltrack.wire.transport import LivelinessWatcher

            with LivelinessWatcher(session, keys.ALIVE) as w:
                for svc in (
                    "primary:primary_tracker",
                    "source/s1:source_tracker",
                    "referee:scorer",
                ):
                    assert w.wait_until(keys.alive(*svc.split(":")), True, 60), logs(s)
            for key in subscribed:
                for payload in GARBAGE:
                    session.put(key, payload)

            def rejected() -> int:
                summary = supervisor.fetch_summary(s.endpoint) or {}
                return int(summary.get("messages", {}).get("rejected_total", 0))

            # the session stays open until the services have counted the garbage (closing it
            # at once could drop what is still queued)
            assert wait_until(lambda: rejected() >= 3 * len(GARBAGE), 60), logs(s)
        s.start_service("sensor_sim", *sim_flags(15, 300, pace=0))
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        summary = supervisor.wait_for_scored(s.endpoint, 1, 120)
        assert summary is not None
        for svc in ("primary/primary_tracker", "source/s1/source_tracker", "referee/scorer"):
            assert sum(summary["messages"]["rejected"][svc].values()) >= len(GARBAGE), svc
        for name in ("tl-rpf", "rpf", "source-rpf"):
            assert summary["filters"][name]["steps"] == 15, name
        for name in ("primary_tracker", "source_tracker", "scorer"):
            assert s.procs[name].poll() is None, f"{name} died"


@pytest.mark.skipif(
    shutil.which("zenohd") is None,
    reason="no zenohd on PATH (make zenohd builds it with cargo, ~7.5 min)",
)
def test_services_run_against_a_stock_zenohd(tmp_path):
    db = tmp_path / "scorer.sqlite"
    with stack(tmp_path) as s:
        s.start(
            "router",
            [
                "-c",
                "import os, sys; os.execvp('zenohd', sys.argv[1:])",
                "zenohd",
                "--no-multicast-scouting",
                "-l",
                s.endpoint,
            ],
        )
        for name, env in (
            ("scorer", {"TLTRACK_SCORER_DB": str(db)}),
            ("primary_tracker", None),
            ("source_tracker", None),
        ):
            s.start_service(name, env=env)
        s.start_service("sensor_sim", *sim_flags(20, 300, pace=0))
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        summary = supervisor.wait_for_scored(s.endpoint, 1, 120)
        assert summary is not None, logs(s)
    assert summary["filters"]["tl-rpf"]["steps_with_transfer"] == 19
