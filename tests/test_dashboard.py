"""The dashboard: its bounded state, metrics and web app in-process, then as a real process beside
the four services over loopback Zenoh, checked against the scorer."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from typing import Any

import msgpack
import pytest
import zenoh
from livestack import WAIT_WITH_DASHBOARD, logs, sim_flags, stack, wait_until
from prometheus_client import generate_latest
from prometheus_client.parser import text_string_to_metric_families
from tltrack.config import make_config
from tltrack.live import supervisor
from tltrack.services.dashboard import launch
from tltrack.services.dashboard.ingest import Ingest
from tltrack.services.dashboard.metrics import Metrics
from tltrack.services.dashboard.server import main
from tltrack.services.dashboard.state import State, clean_stats
from tltrack.services.dashboard.web import WebServer, create_app
from tltrack.wire import keys
from tltrack.wire.messages import (
    EpisodeStart,
    EstimateMsg,
    Message,
    RejectCounter,
    Truth,
    encode,
)
from tltrack.wire.transport import LivelinessWatcher, Received

E = "ep-r0"
EYE = [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]]

# ---- helpers ----------------------------------------------------------------------------------


def received(key: str, payload: Message | bytes, t_recv: float | None = None) -> Received:
    data = payload if isinstance(payload, bytes) else encode(payload)
    return Received(key, data, zenoh.SampleKind.PUT, time.time() if t_recv is None else t_recv)


def truth(k: int, x: float, y: float, e: str = E) -> Truth:
    return Truth(
        episode=e, sender="sensor_sim", k=k, t_sensor=100.0 + k, x=[x, 0.0, y, 0.0], pos=[x, y]
    )


def estimate(name: str, k: int, x: float, y: float, used: bool = False, e: str = E) -> EstimateMsg:
    return EstimateMsg(
        episode=e,
        sender="t",
        k=k,
        t_sensor=100.0 + k,
        filter=name,
        x=[x, 0.0, y, 0.0],
        pos=[x, y],
        P=EYE,
        transfer_used=used,
        t_sent=100.0 + k,
        step_ms=2.0,
    )


def start(K: int = 3, e: str = E) -> EpisodeStart:
    cfg = make_config(preset="arasaratnam-haykin", K=K).model_dump(mode="json")
    return EpisodeStart(
        episode=e,
        sender="sensor_sim",
        k=0,
        t_sensor=100.0,
        run=0,
        config=cfg,
        K=K,
        steps_per_sec=10.0,
    )


Samples = dict[tuple[str, frozenset[tuple[str, str]]], float]


def samples(text: str) -> Samples:
    """Prometheus text -> {(sample name, labels): value}."""
    return {
        (s.name, frozenset(s.labels.items())): s.value
        for fam in text_string_to_metric_families(text)
        for s in fam.samples
    }


def value(m: Samples, name: str, **labels: str) -> float | None:
    return m.get((name, frozenset(labels.items())))


def make() -> tuple[State, Metrics, Ingest, RejectCounter]:
    state = State(max_episodes=2, max_steps=50, max_filters=3)
    metrics = Metrics(state)
    rejects = RejectCounter()
    return state, metrics, Ingest(state, metrics, rejects), rejects


def get(url: str) -> tuple[int, str, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status, r.headers.get("Content-Type", ""), r.read()
    except urllib.error.HTTPError as err:
        return err.code, "", b""


# ---- in-process: state, metrics, ingest -------------------------------------------------------


@pytest.mark.unit
def test_rmse_is_the_scorers_mean_of_position_errors_whatever_the_arrival_order():
    state, metrics, ingest, rejects = make()
    ingest.handle(received(keys.episode(E), start()))
    ingest.handle(received(keys.primary_estimate("tl", E), estimate("tl-pf", 1, 3.0, 4.0)))
    ingest.handle(received(keys.truth(E), truth(1, 0.0, 0.0)))  # truth after the estimate
    ingest.handle(received(keys.truth(E), truth(2, 10.0, 10.0)))
    ingest.handle(received(keys.primary_estimate("tl", E), estimate("tl-pf", 2, 10.0, 11.0, True)))
    ingest.handle(received(keys.source_estimate("s1", E), estimate("source-pf", 2, 16.0, 18.0)))
    snap = state.snapshot()
    ep = snap["episode"]
    assert ep["id"] == E and ep["K"] == 3 and ep["last_k"] == 2
    f = {x["name"]: x for x in ep["filters"]}
    assert f["tl-pf"]["error"] == [[1, 5.0], [2, 1.0]]
    assert f["tl-pf"]["rmse"] == pytest.approx(3.0)  # mean over k of RMSE(k), as the scorer
    assert f["source-pf"]["rmse"] == pytest.approx(10.0)
    assert (f["tl-pf"]["transfer_used"], f["tl-pf"]["transfer_skipped"]) == (1, 1)
    assert ep["transfer"] == [[1, 0], [2, 1]]
    assert [x["role"] for x in ep["filters"]] == ["source", "tl"]
    m = samples(generate_latest(metrics.registry).decode())
    assert value(m, "tltrack_rmse_meters", filter="tl-pf") == pytest.approx(3.0)
    assert value(m, "tltrack_rmse_step_meters", filter="tl-pf") == pytest.approx(1.0)
    assert value(m, "tltrack_transfer_steps_total", filter="tl-pf", used="true") == 1
    assert value(m, "tltrack_transfer_steps_total", filter="tl-pf", used="false") == 1
    assert value(m, "tltrack_messages_received_total", key="tltrack/truth/*") == 2
    assert value(m, "tltrack_latency_seconds_count", filter="tl-pf") == 2
    assert rejects.total == 0


@pytest.mark.unit
def test_each_filter_is_measured_against_the_truth_at_its_own_samples():
    """Off the shared clock the truth comes by tick of its grid (0.5 s here: a source sampling
    every 1.5 s from 0.5 s, the primary every second); a source's step 1 is tick 4, the
    primary's step 1 tick 2."""
    state, _metrics, ingest, rejects = make()
    cfg = make_config(
        preset="arasaratnam-haykin", K=3, sources=[{"id": "s1", "period_s": 1.5, "phase_s": 0.5}]
    )
    begin = start(3).model_copy(update={"config": cfg.model_dump(mode="json")})
    ingest.handle(received(keys.episode(E), begin))
    for n in range(1, 7):
        ingest.handle(received(keys.truth(E), truth(n, 10.0 * n, 0.0)))
    ingest.handle(received(keys.source_estimate("s1", E), estimate("source-pf", 1, 43.0, 0.0)))
    ingest.handle(received(keys.primary_estimate("tl", E), estimate("tl-pf", 1, 20.0, 1.0)))
    f = {x["name"]: x for x in state.snapshot()["episode"]["filters"]}
    assert f["source-pf"]["error"] == [[1, 3.0]]  # against tick 4 (x = 40), not tick 1
    assert f["tl-pf"]["error"] == [[1, 1.0]]  # against tick 2 (x = 20)
    assert rejects.total == 0


@pytest.mark.unit
def test_replays_and_floods_stay_bounded_and_are_counted():
    state, _metrics, ingest, rejects = make()  # 2 episodes, 50 steps, 3 filters
    key = keys.primary_estimate("tl", E)
    ingest.handle(received(key, estimate("tl-pf", 1, 1.0, 1.0)))
    ingest.handle(received(key, estimate("tl-pf", 1, 9.0, 9.0)))  # replay: first value wins
    assert rejects.count(key, "duplicate") == 1
    assert state.snapshot()["episode"]["filters"][0]["points"] == [[1, 1.0, 1.0]]
    for k in range(2, 60):
        ingest.handle(received(key, estimate("tl-pf", k, 1.0, 1.0)))
    assert rejects.count(key, "capacity") == 9
    for i in range(5):
        ingest.handle(received(key, estimate(f"f{i}", 1, 1.0, 1.0)))
    assert len(state.snapshot()["episode"]["filters"]) == 3
    for e in ("ep-a", "ep-b", "ep-c"):
        ingest.handle(received(keys.episode(e), start(e=e)))
    assert [x["id"] for x in state.snapshot()["episodes"]] == ["ep-b", "ep-c"]
    assert state.snapshot()["episode"]["id"] == "ep-c"  # the latest one is shown
    assert state.snapshot("ep-b")["episode"]["id"] == "ep-b"


@pytest.mark.unit
def test_the_page_gets_the_latest_steps_scan_with_its_false_alarms():
    state = State()
    for k, scan, fake in [(2, [[5.0, 6.0], [7.0, 8.0]], [False, True]), (1, [[0.0, 0.0]], [True])]:
        state.on_truth(truth(k, 0.0, 0.0).model_copy(update={"scan": scan, "scan_clutter": fake}))
    # the late step 1 changes nothing: the page shows the latest scan
    assert state.snapshot()["episode"]["scan"] == {"k": 2, "points": [[5.0, 6.0, 0], [7.0, 8.0, 1]]}
    state.on_truth(truth(3, 0.0, 0.0))  # nothing detected at step 3: an empty scan, drawn as none
    assert state.snapshot()["episode"]["scan"] == {"k": 3, "points": []}


@pytest.mark.unit
def test_many_steps_are_thinned_for_the_page_keeping_the_last():
    state = State(max_points=10)
    for k in range(1, 101):
        state.on_truth(truth(k, float(k), 0.0))
        state.on_estimate("tl", estimate("tl-pf", k, float(k), 1.0), 100.0 + k)
    ep = state.snapshot()["episode"]
    assert len(ep["truth"]) <= 11 and ep["truth"][-1][0] == 100
    assert len(ep["filters"][0]["error"]) <= 11 and ep["filters"][0]["rmse"] == pytest.approx(1.0)


@pytest.mark.unit
def test_bad_payloads_and_statistics_are_counted_never_raised():
    state, metrics, ingest, rejects = make()
    ingest.handle(received(keys.truth(E), b"\x00\x01garbage"))
    ingest.handle(received(keys.truth(E), msgpack.packb({"schema_version": 99, "type": "truth"})))
    ingest.handle(received("tltrack/nonsense/a/b/c/d", b"x"))
    stats_key = keys.stats(keys.PRIMARY, "primary_tracker")
    ingest.handle(received(stats_key, b"not json"))
    ingest.handle(received(stats_key, b"[" * 5000 + b"]" * 5000))
    ingest.handle(received(stats_key, b"[1, 2]"))
    assert rejects.count(keys.truth(E), "not_msgpack") == 1
    assert rejects.count(keys.truth(E), "unknown_version") == 1
    assert rejects.count("tltrack/nonsense/a/b/c/d", "bad_key") == 1
    assert rejects.count(stats_key, "bad_stats") == 3
    assert state.snapshot()["episode"] is None  # nothing bad made an episode
    junk = {
        "counters": {"steps": 3, "bad": -1, "worse": "x", "float": 1.5},
        "rejected": {"by_key": {"k": 2}, "by_reason": "oops"},
        "dropped": True,
        "links": {"s1": "cut", "s2": "maybe", "s3": 1},
    }
    assert clean_stats(junk) == {
        "counters": {"steps": 3},
        "rejected_by_key": {"k": 2},
        "rejected_by_reason": {},
        "dropped": 0,
        "links": {"s1": "cut"},
    }
    ingest.handle(
        received(
            stats_key,
            json.dumps(
                {
                    "counters": {"steps": 7},
                    "dropped": 1,
                    "rejected": {
                        "by_key": {"tltrack/primary/meas/ep-r0": 4},
                        "by_reason": {"invalid": 4},
                    },
                }
            ).encode(),
        )
    )
    ingest.handle(received("tltrack/alive/primary/primary_tracker", b""))
    m = samples(generate_latest(metrics.registry).decode())
    svc = "primary/primary_tracker"
    assert (
        value(m, "tltrack_messages_rejected_total", service=svc, key="tltrack/primary/meas/ep-r0")
        == 4
    )
    assert value(m, "tltrack_messages_rejected_by_reason_total", service=svc, reason="invalid") == 4
    assert value(m, "tltrack_service_events_total", service=svc, event="steps") == 7
    assert value(m, "tltrack_service_up", service=svc) == 1
    assert state.snapshot()["rejected"]["total"] == 4


@pytest.mark.unit
def test_the_web_app_serves_the_page_its_files_its_state_and_metrics():
    state, metrics, ingest, _ = make()
    ingest.handle(received(keys.episode(E), start()))
    ingest.handle(received(keys.truth(E), truth(1, 0.0, 0.0)))
    port = supervisor.free_port()
    web = WebServer(create_app(state, metrics), "127.0.0.1", port)
    web.start()
    try:
        base = f"http://127.0.0.1:{port}"
        status, ctype, body = get(f"{base}/")
        assert status == 200 and "text/html" in ctype
        html = body.decode()
        assert 'id="trajectory"' in html and 'id="rmse"' in html and "/static/dashboard.js" in html
        assert "http://" not in html.replace(" http://www.w3.org", "")  # nothing from a CDN
        for name, kind in (
            ("dashboard.js", "javascript"),
            ("dashboard.css", "css"),
            ("favicon.svg", "svg"),
        ):
            status, ctype, _ = get(f"{base}/static/{name}")
            assert status == 200 and kind in ctype, name
        assert get(f"{base}/static/..%2Fstate.py")[0] == 404
        status, ctype, body = get(f"{base}/api/state")
        assert status == 200 and ctype.startswith("application/json")
        assert json.loads(body)["episode"]["truth"] == [[1, 0.0, 0.0]]
        status, ctype, body = get(f"{base}/metrics")
        assert status == 200 and ctype.startswith("text/plain")
        assert b"tltrack_messages_received_total" in body
        assert get(f"{base}/healthz")[0] == 200
    finally:
        web.stop()
    assert not web.running


@pytest.mark.unit
def test_bad_settings_stop_the_dashboard_naming_the_field(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--port=70000"])
    assert exc.value.code == 2
    assert "port" in capsys.readouterr().err


@pytest.mark.unit
def test_sensor_sim_can_wait_for_the_dashboard_too(monkeypatch: pytest.MonkeyPatch) -> None:
    from tltrack.services.sensor_sim.simulator import Settings as SimSettings

    monkeypatch.setenv(
        "TLTRACK_SIM_WAIT_FOR", supervisor.sim_env(WAIT_WITH_DASHBOARD)["TLTRACK_SIM_WAIT_FOR"]
    )
    assert (
        SimSettings().wait_for == WAIT_WITH_DASHBOARD
        and WAIT_WITH_DASHBOARD[-1] == "referee:dashboard"
    )
    assert launch.url(8050, "0.0.0.0") == "http://127.0.0.1:8050/"
    assert launch.env(9000)["TLTRACK_DASHBOARD_PORT"] == "9000"


# ---- real processes ---------------------------------------------------------------------------

REJECTED = "tltrack_messages_rejected_total"
GARBAGE = [
    b"\x00\x01garbage",
    msgpack.packb(
        {
            "schema_version": 99,
            "type": "truth",
            "episode": E,
            "sender": "x",
            "k": 1,
            "t_sensor": 0.0,
            "x": [1.0, 0.0, 1.0, 0.0],
        }
    ),
    msgpack.packb({"schema_version": 1, "type": "measurement"})[:-3],
]


@pytest.mark.timeout(90)
@pytest.mark.integration
def test_a_live_episode_shows_on_the_page_and_in_metrics_as_the_scorer_scores_it(tmp_path):
    K = 30
    port = supervisor.free_port()
    page = launch.url(port)

    def state() -> dict[str, Any]:
        return dict(json.loads(get(f"{page}api/state")[2]))

    def metrics() -> Samples:
        return samples(get(f"{page}metrics")[2].decode())

    def settled() -> bool:
        """The whole episode is in, and the services' statistics (once a second) caught up."""
        ep, m = state()["episode"] or {}, metrics()
        ended = ep.get("ended") == "complete" and all(f["steps"] == K for f in ep["filters"])
        seen = [
            value(m, REJECTED, service="primary/primary_tracker", key=keys.primary_meas(E)),
            value(m, REJECTED, service="referee/scorer", key=keys.truth(E)),
            value(m, REJECTED, service="referee/dashboard", key=keys.truth(E)),
        ]
        return ended and all((n or 0) >= len(GARBAGE) for n in seen)

    with stack(tmp_path) as s:
        s.start_router()
        s.start_service("scorer", env={"TLTRACK_SCORER_DB": str(tmp_path / "scorer.sqlite")})
        s.start_service("primary_tracker", env={"TLTRACK_PRIMARY_LOCKSTEP": "true"})
        s.start_service("source_tracker")
        launch.start(s, port)
        with supervisor.client(s.endpoint) as session, LivelinessWatcher(session, keys.ALIVE) as w:
            for who in WAIT_WITH_DASHBOARD:
                assert w.wait_until(keys.alive(*who.split(":")), True, 60), logs(s)
            for payload in GARBAGE:
                session.put(keys.truth(E), payload)
                session.put(keys.primary_meas(E), payload)
        s.start_service(
            "sensor_sim", *sim_flags(K, 500, pace=0), env=supervisor.sim_env(WAIT_WITH_DASHBOARD)
        )
        assert s.wait("sensor_sim", 60) == 0, logs(s)
        assert supervisor.wait_for_scored(s.endpoint, 1, 30) is not None, logs(s)
        assert wait_until(settled, 15), f"{state()}\n{logs(s)}"

        def scorer_has_all() -> dict[str, Any] | None:
            # the scorer may call an episode scored before a lagging primary's last estimate
            summary = supervisor.fetch_summary(s.endpoint) or {}
            filters = summary.get("filters", {})
            done = len(filters) == 3 and all(f["steps"] == K for f in filters.values())
            return summary if done else None

        assert wait_until(lambda: scorer_has_all() is not None, 15), logs(s)
        summary = scorer_has_all()
        assert summary is not None
        snap, m = state(), metrics()

    ep = snap["episode"]
    assert (ep["id"], ep["K"], ep["last_k"], len(ep["truth"])) == (E, K, K, K)
    # the referee's own draw of the primary's last scan: the paper's sensor, one detection
    assert ep["scan"]["k"] == K and [p[2] for p in ep["scan"]["points"]] == [0], ep["scan"]
    scored = summary["filters"]
    assert {f["name"] for f in ep["filters"]} == set(scored) == {"source-rpf", "tl-rpf", "rpf"}
    for f in ep["filters"]:
        name, role = f["name"], f["role"]
        assert f["rmse"] == pytest.approx(scored[name]["rmse_overall"], rel=1e-9), name
        assert value(m, "tltrack_rmse_meters", filter=name) == pytest.approx(f["rmse"], rel=1e-9)
        key = (
            keys.source_estimate("s1", "*")
            if role == "source"
            else keys.primary_estimate(role, "*")
        )
        assert value(m, "tltrack_messages_received_total", key=key) == K
        inf = value(m, "tltrack_latency_seconds_bucket", filter=name, le="+Inf")
        assert value(m, "tltrack_latency_seconds_count", filter=name) == inf == K
        total = value(m, "tltrack_latency_seconds_sum", filter=name)
        assert total is not None and 0 < total / K < 5.0, f"mean latency {total} s"
        lat = f["latency_ms"]
        assert 0 < lat["p50"] <= lat["p95"] <= lat["p99"]
        stages = f["stages_ms"]  # the page's "p50 by stage" line: where the time goes
        assert None not in stages.values() and stages["step"] > 0, (name, stages)
    used = scored["tl-rpf"]["steps_with_transfer"]
    assert used == K - 1  # lock-step: every step but the first
    assert value(m, "tltrack_transfer_steps_total", filter="tl-rpf", used="true") == used
    assert value(m, "tltrack_transfer_steps_total", filter="tl-rpf", used="false") == K - used
    assert value(m, "tltrack_messages_received_total", key="tltrack/truth/*") == K + len(GARBAGE)
    here = value(m, REJECTED, service="referee/dashboard", key=keys.truth(E))
    assert here == len(GARBAGE)
    assert (value(m, REJECTED, service="referee/scorer", key=keys.truth(E)) or 0) >= 3
    alive = {x["name"] for x in snap["services"] if x["alive"]}
    everyone = {"primary/primary_tracker", "source/s1/source_tracker", "referee/scorer"}
    assert everyone | {"referee/dashboard"} <= alive
    # sensor_sim has exited, and its token's end may reach the page between the two reads
    for svc in everyone | {"referee/dashboard"}:
        assert value(m, "tltrack_service_up", service=svc) == 1
    assert snap["rejected"]["total"] >= 3 * len(GARBAGE)


@pytest.mark.timeout(60)
@pytest.mark.integration
def test_a_taken_port_stops_the_dashboard_at_once_with_the_reason(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        r = subprocess.run(
            [sys.executable, "-m", "tltrack.services.dashboard", f"--port={port}"],
            capture_output=True,
            text=True,
            timeout=30,
            env={**os.environ, "TLTRACK_ZENOH_ENDPOINTS": "tcp/127.0.0.1:1"},
        )
    assert r.returncode == 2, r.stderr
    assert f"cannot serve on host '127.0.0.1', port {port}: " in r.stderr
    assert "Address already in use" in r.stderr  # the reason, not a guess at it
    r = subprocess.run(
        [sys.executable, "-m", "tltrack.services.dashboard", "--host=bad host"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert r.returncode == 2 and "cannot serve on host 'bad host'" in r.stderr, r.stderr
    assert "port in use" not in r.stderr
