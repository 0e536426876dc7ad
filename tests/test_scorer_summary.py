"""The scorer's summary is computed when asked, never on its own while an episode runs: computed
from the whole store, it would take a core from the trackers at every refresh."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from doubles import Offline, episode_end, episode_start, received
from tltrack.services.scorer import scorer as scorer_svc
from tltrack.services.scorer.store import Store
from tltrack.services.scorer.summary import Summarizer
from tltrack.wire import keys
from tltrack.wire.messages import EstimateMsg, Truth, encode

pytestmark = pytest.mark.unit

E = "ep-r0"


def _estimate(k: int, e: str = E) -> bytes:
    return encode(
        EstimateMsg(
            episode=e, sender=keys.PRIMARY, k=k, t_sensor=time.time(), filter="tl-rpf",
            x=[1.0, 2.0, 3.0, 4.0], pos=[1.0, 3.0], P=np.eye(4) * 10.0, transfer_used=True,
            t_sent=time.time(), step_ms=1.0,
        )
    )  # fmt: skip


def _truth(k: int, e: str = E) -> bytes:
    return encode(
        Truth(episode=e, sender="sensor_sim", k=k, t_sensor=0.0, x=[1, 2, 7, 4], pos=[1.0, 7.0])
    )


def test_a_get_asks_for_a_fresh_summary_and_nothing_else_does(tmp_path: Path) -> None:
    svc = Offline("scorer", keys.REFEREE)
    scorer = scorer_svc.Scorer(
        scorer_svc.Settings.model_validate({}), svc, Store(tmp_path / "scorer.sqlite")
    )
    scorer.handle(received(keys.episode(E), episode_start(E, 10)))
    for k in (1, 2):
        scorer.handle(received(keys.truth(E), _truth(k)))
        scorer.handle(received(keys.primary_estimate("tl", E), _estimate(k)))
    first = json.loads(scorer.answer({}))  # a get: the last summary, and an ask for a fresh one
    assert first["filters"] == {}  # the empty store's, computed at the scorer's start

    scorer.refresh_if_asked(every=0.0)
    fresh = json.loads(scorer.answer({}))
    assert fresh["as_of"] > first["as_of"]
    assert fresh["filters"]["tl-rpf"]["steps"] == 2
    assert fresh["filters"]["tl-rpf"]["rmse_overall"] == 4.0  # |(1, 3) - (1, 7)|

    scorer.refresh_if_asked(every=0.0)  # the get above asked: served
    scorer.handle(received(keys.primary_estimate("tl", E), _estimate(3)))
    scorer.refresh_if_asked(every=0.0)  # nobody asked since: nothing computed
    assert json.loads(scorer.answer({}))["filters"]["tl-rpf"]["steps"] == 2
    scorer.refresh_if_asked(every=60.0)  # asked, but the last summary is not a minute old
    assert json.loads(scorer.answer({}))["filters"]["tl-rpf"]["steps"] == 2
    scorer.refresh_if_asked(every=0.0)
    assert json.loads(scorer.answer({}))["filters"]["tl-rpf"]["steps"] == 3


def test_a_scored_episode_is_not_read_again_until_a_late_row_arrives(tmp_path: Path) -> None:
    """A fresh summary reads only the episodes not yet scored, so it costs the same however many
    the store holds; a row that arrives after the scoring makes its episode be read again."""
    store = Store(tmp_path / "scorer.sqlite")
    settings = scorer_svc.Settings.model_validate({"grace_s": 0.01})
    scorer = scorer_svc.Scorer(settings, Offline("scorer", keys.REFEREE), store)
    for e in ("ep-a", "ep-b"):
        scorer.handle(received(keys.episode(e), episode_start(e, 3)))
        for k in (1, 2):
            scorer.handle(received(keys.truth(e), _truth(k, e)))
            scorer.handle(received(keys.primary_estimate("tl", e), _estimate(k, e)))
        scorer.handle(received(keys.episode(e), episode_end(e, 3)))
    time.sleep(0.05)
    scorer.score_finished()  # both quiet past the grace: scored, and their scores kept
    assert scorer.scored == {"ep-a", "ep-b"}

    read: list[str] = []
    store.db.set_trace_callback(read.append)
    scorer.refresh()
    assert not [q for q in read if "'ep-a'" in q or "'ep-b'" in q], read
    assert json.loads(scorer.answer({}))["filters"]["tl-rpf"]["steps"] == 4

    scorer.handle(received(keys.truth("ep-a"), _truth(3, "ep-a")))  # late, after the scoring
    scorer.handle(received(keys.primary_estimate("tl", "ep-a"), _estimate(3, "ep-a")))
    read.clear()
    scorer.refresh()
    assert [q for q in read if "'ep-a'" in q] and not [q for q in read if "'ep-b'" in q], read
    kept = json.loads(scorer.answer({}))
    assert kept["filters"]["tl-rpf"]["steps"] == 5
    assert kept["filters"]["tl-rpf"]["rmse_per_step"] == [4.0, 4.0, 4.0]
    scratch = Summarizer(store).summary()  # nothing kept: every episode read
    assert kept["filters"] == scratch["filters"] and kept["messages"] == scratch["messages"]
