"""``tltrack scores --jsonl``: the scorer's per-step scores, read from a file the scorer's own
:class:`~tltrack.services.scorer.store.Store` wrote, agree with its summary."""

from __future__ import annotations

import json
import math
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from doubles import episode_start
from tltrack.app import app
from tltrack.services.scorer.store import Store
from tltrack.services.scorer.summary import Summarizer
from tltrack.wire.messages import EpisodeStart, EstimateMsg, Truth, decode
from typer.testing import CliRunner, Result

pytestmark = pytest.mark.unit

runner = CliRunner()
T0 = 1_700_000_000.0
P = np.eye(4).tolist()


def truth(e: str, k: int) -> Truth:
    return Truth(
        episode=e, sender="sensor_sim", k=k, t_sensor=T0 + k, x=[k, 0.0, 1.0, 0.0], pos=[k, 1.0]
    )


def estimate(e: str, name: str, k: int) -> EstimateMsg:
    return EstimateMsg(
        episode=e, sender="primary", k=k, t_sensor=T0 + k, filter=name, x=[k, 0.0, 1.0, 0.0],
        pos=[k + 3.0, 1.0 + 4.0 * (name == "tl-rpf")], P=P, transfer_used=k % 2 == 0,
        t_sent=T0 + k + 0.002, step_ms=1.0,
    )  # fmt: skip


def recv_time(k: int) -> float:
    return T0 + k + 0.004 + k * 1e-4


def scorer_file(path: Path, commit: bool = True) -> Store:
    """Episode ep-a: 3 steps of tl-rpf and rpf, no truth at step 3; episode ep-b: 1 step."""
    store = Store(path)
    for e, K in (("ep-a", 3), ("ep-b", 1)):
        store.episode_start(decode(episode_start(e, K), EpisodeStart))
        for k in range(1, K + 1):
            if k < 3:
                store.truth(truth(e, k))
            for name in ("tl-rpf", "rpf"):
                store.estimate(estimate(e, name, k), recv_time(k))
    if commit:
        store.commit()
    return store


def scores(*args: str) -> Result:
    return runner.invoke(app, ["scores", *args])


def lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_one_object_per_filter_and_step(tmp_path: Path) -> None:
    db, out = tmp_path / "scorer.sqlite", tmp_path / "out" / "scores.jsonl"
    scorer_file(db).close()
    r = scores("--jsonl", str(out), "--db", str(db))
    assert r.exit_code == 0, r.output
    got = lines(out)
    assert [(o["episode"], o["filter"], o["k"]) for o in got] == [
        ("ep-a", name, k) for name in ("rpf", "tl-rpf") for k in (1, 2, 3)
    ] + [("ep-b", "rpf", 1), ("ep-b", "tl-rpf", 1)]
    assert all(set(o) == {"episode", "filter", "k", "error_m", "latency_ms", "transfer_used"}
               for o in got)  # fmt: skip
    first = got[3]  # ep-a, tl-rpf, k = 1: 3 m east and 4 m north of the truth
    assert first["error_m"] == 5.0 and first["transfer_used"] is False
    assert first["latency_ms"] == pytest.approx(4.1, abs=1e-3)  # ms, of times near 1.7e9 s
    assert got[4]["transfer_used"] is True
    assert got[5]["error_m"] is None  # no truth at k = 3: no error, a latency still
    assert got[5]["latency_ms"] == pytest.approx(4.3, abs=1e-3)


def test_the_lines_are_what_the_scorer_summary_aggregates(tmp_path: Path) -> None:
    db, out = tmp_path / "scorer.sqlite", tmp_path / "scores.jsonl"
    store = scorer_file(db)  # the scorer still has it open, in WAL mode, and may write on
    r = scores("--jsonl", str(out), "--db", str(db), "--episode", "ep-a")
    assert r.exit_code == 0, r.output
    got = lines(out)
    assert {o["episode"] for o in got} == {"ep-a"} and len(got) == 6
    summary = Summarizer(store).summary(["ep-a"])
    for name, f in summary["filters"].items():
        mine = [o for o in got if o["filter"] == name]
        errors = [o["error_m"] for o in mine if o["error_m"] is not None]
        assert f["rmse_per_step"] == errors  # one episode: RMSE(k) is the error at k, to the bit
        assert f["rmse_overall"] == float(np.mean(errors))
        p50 = float(np.percentile([o["latency_ms"] for o in mine], 50))
        assert f["latency_ms"]["p50"] == p50
        assert f["steps_with_transfer"] == sum(o["transfer_used"] for o in mine)
    store.close()


def test_to_stdout_and_an_episode_it_does_not_hold(tmp_path: Path) -> None:
    db = tmp_path / "scorer.sqlite"
    scorer_file(db).close()
    r = scores("--jsonl", "-", "--db", str(db), "--episode", "ep-b")
    assert r.exit_code == 0, r.output
    got = [json.loads(line) for line in r.stdout.splitlines()]
    assert [(o["filter"], o["error_m"]) for o in got] == [("rpf", 3.0), ("tl-rpf", 5.0)]
    kept = tmp_path / "kept.jsonl"
    kept.write_text("an earlier export\n")
    for typo in ("ep-zz", ""):  # refused before a file is written: the earlier one stays
        r = scores("--jsonl", str(kept), "--db", str(db), "--episode", typo)
        said = " ".join(r.output.split())
        assert r.exit_code == 2 and f"no estimate of episode {typo!r}" in said, r.output
        assert "['ep-a', 'ep-b']" in said and kept.read_text() == "an earlier export\n"


def test_the_database_comes_from_the_scorers_variable(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    db = tmp_path / "elsewhere.sqlite"
    scorer_file(db).close()
    monkeypatch.setenv("TLTRACK_SCORER_DB", str(db))
    r = scores("--jsonl", "-")
    assert r.exit_code == 0 and len(r.stdout.splitlines()) == 8


def _a_damaged_row(tmp_path: Path, pos: str = "[1]", column: str = "pos") -> Path:
    p = tmp_path / "scorer.sqlite"
    scorer_file(p).close()
    with sqlite3.connect(p) as con:
        con.execute(f"UPDATE estimates SET {column} = ? WHERE k = 2 AND filter = 'rpf'", (pos,))
    return p


def _not_the_scorers(tmp_path: Path) -> Path:
    p = tmp_path / "other.sqlite"
    with sqlite3.connect(p) as con:
        con.execute("CREATE TABLE truth (episode TEXT, k INTEGER)")
    return p


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda tmp: tmp / "absent.sqlite", "no such file"),
        (lambda tmp: tmp, "a folder, not the scorer's file"),
        (lambda tmp: (tmp / "notes.txt").write_text("not sqlite" * 100) and tmp / "notes.txt",
         "not an SQLite database"),
        (_not_the_scorers, "not a scorer's database"),
        (_a_damaged_row, "a position is two numbers within 1e9 m, not '[1]'"),
        (lambda tmp: _a_damaged_row(tmp, "[NaN, 1]"), "within 1e9 m, not '[NaN, 1]'"),
        # its square overflowed: OverflowError, a traceback
        (lambda tmp: _a_damaged_row(tmp, "[1e155, 1]"), "within 1e9 m, not '[1e155, 1]'"),
        (lambda tmp: _a_damaged_row(tmp, None, "t_recv"), "t_recv is None, not a time"),
    ],
    ids=["missing", "directory", "text", "other-sqlite", "damaged-row", "nan", "huge", "no-time"],
)  # fmt: skip
def test_bad_input_exits_2_with_the_reason(tmp_path: Path, make: Any, needle: str) -> None:
    db = make(tmp_path)
    r = scores("--jsonl", str(tmp_path / "out.jsonl"), "--db", str(db))
    assert r.exit_code == 2, r.output
    assert needle in " ".join(r.output.split()) and "Traceback" not in r.output
    assert isinstance(r.exception, SystemExit)
    assert not (tmp_path / "out.jsonl").exists()


def test_the_error_is_the_root_of_what_the_rmse_squares() -> None:
    from tltrack.live.scores import squared_error

    assert squared_error([4.0, 5.0], [1.0, 1.0]) == 25.0
    assert math.sqrt(squared_error([1e6 + 0.1, -2.0], [1e6, -2.0])) == pytest.approx(0.1)


def test_an_episodes_estimates_as_tltrack_tracks_csv(tmp_path: Path) -> None:
    """--estimates writes the CSV `tltrack track` writes, from the states the scorer stored;
    with several episodes in the file it asks which, naming them."""
    from tltrack.engine.track import write_estimates

    db, out, want = tmp_path / "scorer.sqlite", tmp_path / "ep-a.csv", tmp_path / "want.csv"
    store = Store(db)
    store.episode_start(decode(episode_start("ep-a", 2), EpisodeStart))
    store.episode_start(decode(episode_start("ep-b", 2), EpisodeStart))
    rows = []
    for k in (1, 2):
        for name in ("rpf", "tl-rpf"):
            x = [10.0 * k, 1.0, 20.0 * k, -1.0, 0.01 * k]
            P = (np.eye(5) * k).tolist()
            store.estimate(
                EstimateMsg(
                    episode="ep-a",
                    sender="primary",
                    k=k,
                    t_sensor=T0 + k,
                    filter=name,
                    x=x,
                    pos=[x[0], x[2]],
                    P=P,
                    transfer_used=False,
                    t_sent=T0 + k,
                    step_ms=1.0,
                ),
                recv_time(k),
            )
            rows.append((k, name, np.array(x), np.array(P)))
    store.commit()
    store.close()
    r = scores("--db", str(db), "--estimates", str(out))
    assert r.exit_code == 2
    text = " ".join(r.output.split())  # the console wraps a long --db path
    assert "name one episode (--episode) of the 2 held: ['ep-a', 'ep-b']" in text
    r = scores("--db", str(db), "--episode", "ep-a", "--estimates", str(out))
    assert r.exit_code == 0, r.output
    write_estimates(want, "ct", rows)
    assert out.read_text() == want.read_text()
    assert scores("--db", str(db)).exit_code == 2  # nothing asked for
    with sqlite3.connect(db) as con:  # a foreign row: it printed a KeyError's "'scenario'"
        con.execute("UPDATE episodes SET config = '{}' WHERE episode = 'ep-a'")
    r = scores("--db", str(db), "--episode", "ep-a", "--estimates", str(out))
    said = " ".join(r.output.split())
    assert r.exit_code == 2 and "'ep-a': its config names no motion model (scenario)" in said
    with sqlite3.connect(db) as con:  # a NULL state: json.loads(None), a TypeError's traceback
        con.execute('UPDATE episodes SET config = \'{"scenario": "ct"}\'')
        con.execute("UPDATE estimates SET x = NULL WHERE k = 2 AND filter = 'rpf'")
    r = scores("--db", str(db), "--episode", "ep-a", "--estimates", str(out))
    said = " ".join(r.output.split())
    assert r.exit_code == 2 and "rpf's x at k = 2 is None, not JSON text" in said, said


def test_jsonl_to_a_device_is_written_through(tmp_path: Path) -> None:
    """Not replaced by a file of its own: /dev/stdout, a FIFO, a shell's >(gzip ...)."""
    import os
    import threading

    db = tmp_path / "scorer.sqlite"
    scorer_file(db).close()
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    got: list[str] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()))
    reader.start()
    r = scores("--jsonl", str(fifo), "--db", str(db))
    reader.join(10)
    assert r.exit_code == 0, r.output
    assert fifo.is_fifo() and len(got[0].splitlines()) == 8, got
