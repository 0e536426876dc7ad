"""The zenoh-cli decoder (``--decoder tltrack``) and its config file
(``tltrack access zenoh-cli-config``).

Unit: every message type on its key decodes to its fields, and every refusal is the one the
service behind the key counts (the same payload is handed to the real handler). Integration: the
real ``zenoh`` command, under the primary's identity, against a router enforcing the shipped ACL,
prints the transfer a source published, and nothing of that source's raw data.
"""

from __future__ import annotations

import json
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import msgpack
import pytest
import zenoh
from doubles import RADAR, Offline, episode_start, received
from tltrack.app import app
from tltrack.config import make_config
from tltrack.interop.zenoh_cli import decode
from tltrack.live.manifest import Manifest
from tltrack.services.primary_tracker import tracker as primary_svc
from tltrack.services.scorer import scorer as scorer_svc
from tltrack.services.scorer.store import Store
from tltrack.wire import keys
from tltrack.wire.messages import (
    MAX_PAYLOAD_BYTES,
    EpisodeEnd,
    EpisodeStart,
    EstimateMsg,
    Measurement,
    Message,
    Schedule,
    Tick,
    Transfer,
    Truth,
    encode,
)
from typer.testing import CliRunner, Result

E = "ep-r0"
T0 = 1_700_000_000.0
P4 = [[4.0, 0.0, 1.0, 0.0], [0.0, 4.0, 0.0, 1.0], [1.0, 0.0, 2.0, 0.0], [0.0, 1.0, 0.0, 2.0]]

runner = CliRunner()


def transfer(sender: str = "s1", k: int = 3) -> Transfer:
    return Transfer(
        episode=E, sender=sender, k=k, t_sensor=T0, k_apply=k + 1, sensor=RADAR,
        eta=[1500.0, 0.7], P_eta=[[4.0, 1.0], [1.0, 3.0]],
    )  # fmt: skip


def estimate(sender: str = "primary", episode: str = E) -> EstimateMsg:
    return EstimateMsg(
        episode=episode, sender=sender, k=5, t_sensor=T0, filter="tl-rpf", x=[1.0, 2.0, 3.0, 4.0],
        pos=[1.0, 3.0], P=P4, transfer_used=True, t_sent=T0 + 0.01, step_ms=1.5,
    )  # fmt: skip


def truth(sender: str = "sensor_sim") -> Truth:
    return Truth(episode=E, sender=sender, k=3, t_sensor=T0, x=[1.0, 2.0, 3.0, 4.0], pos=[1.0, 3.0])


def measurement(sender: str, sensor: str, z: list[list[float]], t: float = T0) -> Measurement:
    return Measurement(episode=E, sender=sender, k=3, t_sensor=t, sensor=sensor, z=z)


def on_their_keys() -> list[tuple[str, Message]]:
    """One message of every type, each on a key it belongs to, from the key's owner."""
    cfg = make_config(preset="arasaratnam-haykin", K=10, particles=50)
    start = EpisodeStart(
        episode=E, sender="sensor_sim", k=0, t_sensor=T0, run=0, config=cfg.model_dump(), K=10,
        steps_per_sec=0.0,
    )  # fmt: skip
    end = EpisodeEnd(episode=E, sender="sensor_sim", k=10, t_sensor=T0, steps_sent=10)
    z = [[1500.0, 0.7], [900.0, -0.2]]
    return [
        (keys.episode(E), start),
        (keys.episode(E), end),
        (keys.clock(E), Tick(episode=E, sender="sensor_sim", k=3, t_sensor=T0)),
        (keys.truth(E), truth()),
        (keys.primary_meas(E), measurement("sensor_sim", "primary", z)),
        (keys.source_meas("s1", E), measurement("s1", "s1", z[:1])),
        (keys.transfer("s1", E), transfer()),
        (keys.source_estimate("s1", E), estimate(sender="s1")),
        (keys.primary_estimate("tl", E), estimate()),
        (
            keys.schedule(E),
            Schedule(episode=E, sender="primary", k=0, t_sensor=T0, period_s=1.0, t0_s=0.0),
        ),
    ]


def line(key: Any, payload: Any) -> dict[str, Any]:
    """What the decoder prints, parsed: one line of JSON, always."""
    text = decode(key, payload)
    assert isinstance(text, str) and "\n" not in text
    out: dict[str, Any] = json.loads(text)
    return out


def tampered(msg: Message, **fields: Any) -> bytes:
    """``msg`` on the wire with ``fields`` replaced, past every check of the sender's side."""
    return msgpack.packb({**msgpack.unpackb(encode(msg)), **fields})


# ---- every message type ---------------------------------------------------------------------


@pytest.mark.unit
@pytest.mark.parametrize(
    ("key", "msg"), on_their_keys(), ids=lambda v: v.TYPE if isinstance(v, Message) else ""
)
def test_every_type_prints_its_kind_step_and_every_field(key: str, msg: Message) -> None:
    got = line(zenoh.KeyExpr(key), encode(msg))  # zenoh-cli passes the sample's KeyExpr
    assert got["key"] == key and got["kind"] == msg.TYPE
    assert got["k"] == msg.k and got["t_sensor"] == msg.t_sensor
    assert got.get("k_apply") == getattr(msg, "k_apply", None)
    assert "refused" not in got
    assert got["fields"] == msg.model_dump(mode="json")
    assert type(msg).model_validate(got["fields"]) == msg  # nothing lost on the way to JSON


@pytest.mark.unit
def test_arrays_are_lists() -> None:
    got = line(keys.transfer("s1", E), encode(transfer()))
    assert got["k_apply"] == 4
    assert got["fields"]["eta"] == [1500.0, 0.7]
    assert got["fields"]["P_eta"] == [[4.0, 1.0], [1.0, 3.0]]
    assert got["fields"]["sensor"]["kind"] == "range-bearing"


# ---- what a service would refuse, and why -----------------------------------------------------


def _primary() -> tuple[primary_svc.PrimaryTracker, Offline]:
    svc = Offline("primary_tracker")
    tracker = primary_svc.PrimaryTracker(primary_svc.Settings.model_validate({}), svc)
    tracker.handle(received(keys.episode(E), episode_start(E, 10)))
    return tracker, svc


def _scorer(tmp: Path) -> tuple[scorer_svc.Scorer, Offline]:
    svc = Offline("scorer", keys.REFEREE)
    scorer = scorer_svc.Scorer(
        scorer_svc.Settings.model_validate({}), svc, Store(tmp / "scorer.sqlite")
    )
    scorer.handle(received(keys.episode(E), episode_start(E, 10)))
    return scorer, svc


TK = keys.transfer("s1", E)
TL = keys.primary_estimate("tl", E)

#: (service, key, payload, reason): what the service behind the key refuses, and why
REFUSED = [
    ("primary", TK, encode(transfer(sender="s2")), "wrong_sender"),
    ("primary", TK, encode(estimate()), "wrong_type"),
    ("primary", TK, b"\xc1 not msgpack", "not_msgpack"),
    ("primary", TK, b"\x00" * (MAX_PAYLOAD_BYTES + 1), "too_large"),
    ("primary", TK, tampered(transfer(), schema_version=4), "unknown_version"),
    ("primary", TK, tampered(transfer(), eta=[1.0]), "bad_shape"),
    ("primary", TK, tampered(transfer(), eta=[1.0, float("nan")]), "non_finite"),
    ("primary", TK, tampered(transfer(), P_eta=[[1.0, 2.0], [0.0, 1.0]]), "not_symmetric"),
    ("primary", TK, tampered(transfer(), P_eta=[[1.0, 0.0], [0.0, -1.0]]), "not_spd"),
    ("primary", TK, tampered(transfer(), k_apply=9), "invalid"),
    ("scorer", keys.source_estimate("s1", E), encode(estimate(sender="s2")), "wrong_sender"),
    ("scorer", TL, encode(estimate(sender="s1")), "wrong_sender"),
    ("scorer", TL, encode(estimate(episode="ep-r1")), "unknown_episode"),
    ("scorer", keys.truth(E), encode(truth(sender="primary")), "wrong_sender"),
    ("scorer", keys.stats("primary", "primary_tracker"), b"[1, 2]", "bad_stats"),
    ("scorer", "tltrack/nowhere/x", encode(transfer()), "bad_key"),
]
REFUSED_IDS = [f"{service}-{reason}" for service, _, _, reason in REFUSED]


@pytest.mark.unit
@pytest.mark.parametrize(("service", "key", "payload", "reason"), REFUSED, ids=REFUSED_IDS)
def test_a_refused_message_prints_the_reason_its_service_counts(
    tmp_path: Path, service: str, key: str, payload: bytes, reason: str
) -> None:
    got = line(key, payload)
    assert got["key"] == key and got["refused"] == reason and got["detail"]
    handler, svc = _primary() if service == "primary" else _scorer(tmp_path)
    handler.handle(received(key, payload))
    assert svc.rejects.by_reason() == {reason: 1}, "the service gives another reason"


@pytest.mark.unit
def test_a_well_formed_refusal_still_shows_the_message() -> None:
    got = line(keys.transfer("s1", E), encode(transfer(sender="s2")))
    assert got["refused"] == "wrong_sender" and "'s2'" in got["detail"]
    assert got["kind"] == "transfer" and got["fields"]["sender"] == "s2"


@pytest.mark.unit
def test_a_payload_it_cannot_read_says_what_the_key_expects() -> None:
    got = line(keys.episode(E), b"garbage \xff\x00 bytes")
    assert got["refused"] == "not_msgpack" and "fields" not in got
    assert got["expected"] == "episode_start or episode_end"


@pytest.mark.unit
@pytest.mark.parametrize("key", ["demo/example", "tltrack", "tltrack/source/s1/transfer/*", ""])
def test_a_key_that_is_not_tltrack_s_says_so(key: str) -> None:
    got = line(key, encode(transfer()))
    assert got == {"key": key, "refused": "bad_key", "detail": got["detail"]}
    assert "tltrack key" in got["detail"]


@pytest.mark.unit
def test_statistics_pass_through_as_json() -> None:
    stats = {"service": "scorer", "counters": {"steps": 3}, "rejected": {"total": 0}}
    got = line(keys.stats(keys.REFEREE, "scorer"), json.dumps(stats).encode())
    assert got == {"key": keys.stats(keys.REFEREE, "scorer"), "kind": "stats", "fields": stats}
    summary = line(keys.SCORER_SUMMARY, b'{"filters": {}}')
    assert summary["kind"] == "scorer_summary" and summary["fields"] == {"filters": {}}


@pytest.mark.unit
def test_a_liveliness_key_is_named_not_decoded() -> None:
    got = line(keys.alive(keys.PRIMARY, "primary_tracker"), b"")
    assert got["kind"] == "alive" and "refused" not in got


class _Unprintable:
    def __str__(self) -> str:
        raise RuntimeError("no key")


@pytest.mark.unit
@pytest.mark.parametrize(
    ("key", "payload"),
    [
        (keys.transfer("s1", E), None),
        (keys.transfer("s1", E), "a str"),
        (keys.stats("primary", "x"), None),
        (keys.stats("primary", "x"), b"[" * 100_000),
        (_Unprintable(), b""),
    ],
    ids=["none", "str", "stats-none", "stats-deep", "bad-key-object"],
)
def test_the_decoder_never_raises(key: Any, payload: Any) -> None:
    """Each is refused; only a key that cannot be printed is the decoder's own "internal" (the
    statistics' None was one, a TypeError)."""
    got = line(key, payload)
    assert got["refused"] and (got["refused"] == "internal") == isinstance(key, _Unprintable)


# ---- the config file --------------------------------------------------------------------------


def cli_config(out: Path, *args: str) -> Result:
    """``tltrack access zenoh-cli-config --as primary --out OUT ARGS``."""
    cmd = ["access", "zenoh-cli-config", "--as", "primary", "--out", str(out), *args]
    return runner.invoke(app, cmd)


@pytest.mark.unit
def test_the_config_logs_in_as_the_operator_with_the_services_settings(tmp_path: Path) -> None:
    out = tmp_path / "cli" / "primary.json5"
    endpoint = "tcp/127.0.0.1:7999"
    r = cli_config(out, "--endpoint", endpoint)
    assert r.exit_code == 0, r.output
    assert stat.S_IMODE(out.stat().st_mode) == 0o600
    cfg = zenoh.Config.from_file(str(out))  # as zenoh-cli reads it
    got = {k: json.loads(cfg.get_json(k)) for k in ("mode", "connect/endpoints")}
    assert got == {"mode": "client", "connect/endpoints": [endpoint]}
    assert json.loads(cfg.get_json("transport/auth/usrpwd")) | {"dictionary_file": None} == {
        "user": "primary", "password": Manifest.password("primary"), "dictionary_file": None
    }  # fmt: skip
    assert json.loads(cfg.get_json("scouting/multicast/enabled")) is False
    out.chmod(0o644)  # written again: private again
    assert cli_config(out).exit_code == 0
    assert stat.S_IMODE(out.stat().st_mode) == 0o600


@pytest.mark.unit
@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--as", "primray"], "not in the manifest"),
        (["--as", "referee", "--identity", "primary"], "not an identity"),
        (["--as", "primary", "--endpoint", "tcp-127.0.0.1"], "is not <protocol>/<address>"),
    ],
)
def test_the_config_refuses_what_it_cannot_log_in_as(
    tmp_path: Path, args: list[str], needle: str
) -> None:
    out = tmp_path / "x.json5"
    r = runner.invoke(app, ["access", "zenoh-cli-config", *args, "--out", str(out)])
    assert r.exit_code == 2 and needle in " ".join(r.output.split())
    assert r.exception is None or isinstance(r.exception, SystemExit)
    assert not out.exists()


# ---- the real zenoh-cli, against a router enforcing the shipped ACL ----------------------------

ZENOH = Path(sys.executable).parent / "zenoh"


class Cli:
    """``zenoh --config CONFIG subscribe -k KEY... --decoder tltrack`` in the background; its
    lines as they come (a thread reads them)."""

    def __init__(self, config: Path, *keys_: str) -> None:
        argv = [str(ZENOH), "--config", str(config), "subscribe", "--decoder", "tltrack"]
        for k in keys_:
            argv += ["-k", k]
        self.proc = subprocess.Popen(
            argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for text in self.proc.stdout:
            self.lines.append(text.rstrip("\n"))

    def stop(self) -> str:
        """Stop it; what it said on stderr."""
        self.proc.terminate()
        try:
            _, err = self.proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        self._reader.join(5)
        return str(err)


@pytest.mark.integration
@pytest.mark.timeout(120)
@pytest.mark.skipif(not ZENOH.exists(), reason="zenoh-cli is not installed (tltrack[cli])")
def test_the_real_zenoh_cli_prints_a_published_transfer_under_the_primarys_identity(
    tmp_path: Path,
) -> None:
    from livestack import wait_until
    from tltrack.live import supervisor
    from tltrack.live.tracking import SourceEpisode
    from tltrack.wire.transport import Publisher, Subscriber

    cfg = make_config(preset="arasaratnam-haykin", truth="fixed", seed=7, K=10, particles=200)
    source = SourceEpisode(cfg, 0, "rpf", "s1")  # the source's own tracker, one step
    _, eta = source.step(None)
    sent = source.transfer_message(eta, E, 1, time.time())

    endpoint = f"tcp/127.0.0.1:{supervisor.free_port()}"
    config = tmp_path / "primary.json5"
    r = cli_config(config, "--endpoint", endpoint)
    assert r.exit_code == 0, r.output
    with supervisor.Stack(endpoint, tmp_path / "logs", secure=True) as stack:
        stack.start_router()  # the shipped ACL, rendered from the manifest
        stack.wait_listening("router")
        cli = Cli(config, keys.transfer("s1", keys.ANY), keys.source_meas("s1", keys.ANY))
        try:
            with (
                supervisor.client(endpoint, "source-s1") as src,
                supervisor.client(endpoint, "sensor") as sensor,
                Subscriber(src, keys.source_meas("s1", E)) as own,  # the source reads its raw data
                Publisher(src, keys.transfer("s1", E)) as pub,
                Publisher(sensor, keys.source_meas("s1", E)) as meas,
            ):
                assert pub.wait_for_subscribers(30), cli.stop()  # zenoh-cli's subscription is in
                assert meas.wait_for_subscribers(10)
                meas.put(measurement("sensor_sim", "s1", [[1500.0, 0.7]], time.time()))
                assert own.recv(10) is not None  # through the router, before the transfer
                pub.put(sent)
                assert wait_until(lambda: cli.lines, 20, 0.05), cli.stop()
                time.sleep(0.5)  # anything else on its way
        finally:
            err = cli.stop()
    printed = cli.lines
    assert len(printed) == 1, (printed, err)  # the transfer, and nothing of the source's meas
    got = json.loads(printed[0])
    assert got["key"] == keys.transfer("s1", E) and got["kind"] == "transfer"
    assert (got["k"], got["k_apply"], got["t_sensor"]) == (sent.k, sent.k_apply, sent.t_sensor)
    assert "refused" not in got
    assert got["fields"] == sent.model_dump(mode="json")
    assert Transfer.model_validate(got["fields"]) == sent
