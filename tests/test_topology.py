"""tltrack.live.topology: who dials whom, and each router's rules and dictionary (no process)."""

from __future__ import annotations

import dataclasses
import json

import pytest
import zenoh
from security_helpers import passwords
from tltrack.live.access import ACCESS_DIR, router_env
from tltrack.live.manifest import load_manifest
from tltrack.live.topology import federated, identity_operator, router_argv

MANIFEST = load_manifest()


def access_env(operator: str, out):
    return router_env(MANIFEST, operator, out)


pytestmark = pytest.mark.unit


def test_each_source_dials_the_primary_and_every_router_the_referee() -> None:
    topo = federated(["s1", "s2"])
    dials = {op: set(r.dials) for op, r in topo.routers.items()}
    assert dials == {
        "referee": set(),
        "primary": {"referee"},
        "source/s1": {"primary", "referee"},
        "source/s2": {"primary", "referee"},
    }
    assert len({r.endpoint for r in topo.routers.values()}) == 4
    assert topo.endpoint("dashboard") == topo.referee.endpoint
    assert topo.endpoint("source-s2") == topo.routers["source/s2"].endpoint


def test_a_router_dials_through_a_relay_when_told() -> None:
    topo = federated(["s1"])
    relayed = dataclasses.replace(topo, via={("source/s1", "primary"): "tcp/127.0.0.1:9"})
    argv = router_argv(relayed, relayed.routers["source/s1"])
    assert argv[:2] == ["router", "--operator=source/s1"]
    assert "--connect=tcp/127.0.0.1:9" in argv
    assert f"--connect={topo.referee.endpoint}" in argv


@pytest.mark.parametrize(
    ("identity", "operator"),
    [
        ("sensor", "referee"),
        ("dashboard", "referee"),
        ("primary", "primary"),
        ("source-s3", "source/s3"),
    ],
)
def test_each_identity_logs_in_to_its_operators_router(identity: str, operator: str) -> None:
    assert identity_operator(identity) == operator


@pytest.mark.parametrize(
    ("operator", "known", "dials_as"),
    [
        ("referee", {"sensor", "referee", "dashboard", "router-primary"}, None),
        ("primary", {"primary", "router-source-s1", "router-source-s3"}, "router-primary"),
        ("source/s2", {"source-s2"}, "router-source-s2"),
    ],
)
def test_each_router_knows_its_services_and_the_routers_that_dial_it(
    tmp_path, operator: str, known: set[str], dials_as: str | None
) -> None:
    env = access_env(operator, tmp_path)
    users = passwords(tmp_path / env["TLTRACK_ZENOH_USRPWD_DICTIONARY_FILE"])
    assert known <= users.keys()
    if operator != "referee":  # a router's dictionary never lets another operator's service in
        assert not {"sensor", "referee", "dashboard"} & users.keys()
    assert env.get("TLTRACK_ZENOH_USERNAME") == dials_as
    acl = (tmp_path / env["TLTRACK_ZENOH_ACCESS_CONTROL_FILE"]).read_text()
    assert "SID" not in acl
    zenoh.Config().insert_json5("access_control", acl)  # zenoh parses it


def test_the_routers_rules_ship_with_the_package() -> None:
    routers = ACCESS_DIR / "routers"
    assert {p.name for p in routers.iterdir()} >= {"referee.json5", "primary.json5", "users.txt"}
    assert (ACCESS_DIR / "templates" / "routers" / "source.json5").is_file()


def test_each_source_router_brings_in_its_own_transfers_only(tmp_path) -> None:
    """The primary's router: router-source-sX may put tltrack/source/sX/transfer/* and its
    heartbeat, no other key; towards them goes the primary's schedule alone."""
    env = access_env("primary", tmp_path)
    cfg = zenoh.Config()
    cfg.insert_json5(
        "access_control", (tmp_path / env["TLTRACK_ZENOH_ACCESS_CONTROL_FILE"]).read_text()
    )
    acl = json.loads(cfg.get_json("access_control"))
    rules = {r["id"]: r for r in acl["rules"]}
    for sid in ("s1", "s2", "s3"):
        (policy,) = [p for p in acl["policies"] if p["subjects"] == [f"router-source-{sid}"]]
        puts = {
            ke
            for rid in policy["rules"]
            if "put" in rules[rid]["messages"]
            for ke in rules[rid]["key_exprs"]
        }
        own = {f"tltrack/source/{sid}/transfer/*", f"tltrack/source/{sid}/heartbeat"}
        assert puts == own, (sid, puts)
    grouped = [rules[r] for p in acl["policies"] if "source-routers" in p["subjects"]
               for r in p["rules"]]  # fmt: skip
    allowed = [r for r in grouped if r["permission"] == "allow"]
    # towards the sources' routers only the primary's schedule (when it samples, none of its data)
    assert [(r["flows"], r["messages"], r["key_exprs"]) for r in allowed] == [
        (["egress"], ["put"], ["tltrack/schedule/*"])
    ]


def test_the_demo_reads_its_progress_only_from_statistics_that_say_it() -> None:
    """Without access control anyone may publish on sensor_sim's statistics key: a payload that
    is not its statistics moves no bar and stops no demo (json.loads raised out of it)."""
    from tltrack.live.supervisor import _steps_reported

    assert _steps_reported(b'{"counters": {"steps": 7}, "rejects": {}}') == 7
    for bad in (b"[", b"[" * 100_000, b'{"counters": 3}', b'{"counters": {"steps": "7"}}', b"{}"):
        assert _steps_reported(bad) is None, bad
    for count in (b"true", b"-1", b"7.5"):  # counted as the dashboard counts: whole, >= 0
        assert _steps_reported(b'{"counters": {"steps": ' + count + b"}}") is None, count


def test_the_scorer_summary_is_read_only_from_a_reply_that_is_one() -> None:
    """A reply on the summary key that is not the scorer's summary is passed over: it ended
    `tltrack demo` (and every wait for an episode) with a traceback."""
    from tltrack.live.supervisor import _summary

    assert _summary(b'{"episodes": [{"scored": true}]}') == {"episodes": [{"scored": True}]}
    for bad in (b"", b"[1]", b"[" * 100_000, b'{"episodes": 3}', b"\xff"):
        assert _summary(bad) is None, bad
