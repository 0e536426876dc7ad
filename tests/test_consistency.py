"""The consistency monitor: a filter whose motion model does not fit its target says so, from
the NIS of its own measurements (no truth needed), in the CLI, the scorer and the dashboard.

The mismatched case is the one a user met: a light aircraft circling in wind, tracked with the
arasaratnam-haykin preset's noise. The simulated one (tltrack.studies.tracks) loses every run as
the recorded one did, and every filter's windowed NIS sits above its band.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import zenoh
from prometheus_client import generate_latest
from tltrack.app import app
from tltrack.config import load_config
from tltrack.engine.montecarlo import run_experiment
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.live.summary import warnings
from tltrack.live.tracking import PrimaryEpisode, StepReport
from tltrack.services.dashboard.ingest import Ingest
from tltrack.services.dashboard.metrics import Metrics
from tltrack.services.dashboard.state import State
from tltrack.services.scorer.store import Store
from tltrack.services.scorer.summary import Summarizer
from tltrack.studies.tracks import circling_aircraft, write_csv
from tltrack.wire import keys
from tltrack.wire.messages import (
    EpisodeStart,
    EstimateMsg,
    Measurement,
    RejectCounter,
    Truth,
    encode,
)
from tltrack.wire.transport import Received
from typer.testing import CliRunner

pytestmark = pytest.mark.unit

E = "ep-r0"


@pytest.fixture(scope="module")
def aircraft(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_csv(tmp_path_factory.mktemp("tracks") / "circling.csv", *circling_aircraft())


def test_the_cli_warns_that_the_preset_is_too_quiet_for_a_circling_aircraft(aircraft: Path) -> None:
    out = aircraft.parent / "exp"
    args = ["experiment", "--truth-file", str(aircraft), "--preset", "arasaratnam-haykin"]
    args += ["--filters", "ukf,tl-ukf", "--runs", "4", "--workers", "1", "--out", str(out)]
    done = CliRunner().invoke(app, args)
    assert done.exit_code == 0, done.output
    text = " ".join(done.output.split())
    for name in ("ukf", "tl-ukf"):
        assert f"warning: {name}: NIS above its 99% band" in text, text
    assert "the motion model's noise is too low for this target" in text


def _live_estimates(aircraft: Path) -> tuple[EpisodeStart, list[Truth], list[EstimateMsg]]:
    """The primary tracker's messages of run 0 (its own code, without the transport)."""
    cfg = load_config(None, truth_file=aircraft, preset="arasaratnam-haykin", particles=300)
    run = simulate(Setup(cfg), 0)
    tracker = PrimaryEpisode(cfg, 0, "ukf")
    config = cfg.model_dump(mode="json")
    start = EpisodeStart(episode=E, sender="sensor_sim", k=0, t_sensor=time.time(), run=0,
                         config=config, K=cfg.K, steps_per_sec=0.0)  # fmt: skip
    truths, estimates = [], []
    for k in range(1, cfg.K + 1):
        z = Measurement(episode=E, sender="sensor", k=k, t_sensor=time.time(), sensor=PRIMARY,
                        z=[run.z[PRIMARY][k - 1]])  # fmt: skip
        est = tracker.step(z, {})
        nis = tracker.monitor.last[tracker.tl_name]
        report = StepReport(z, keys.PRIMARY, tracker.tl_name, tracker.layout, est, False, False,
                            time.time(), 1.0, nis)  # fmt: skip
        estimates.append(report.message())
        x = run.truth[k]
        truths.append(Truth(episode=E, sender="sensor_sim", k=k, t_sensor=z.t_sensor, x=x,
                            pos=tracker.layout.position(x)))  # fmt: skip
    return start, truths, estimates


def test_the_scorer_and_the_dashboard_warn_from_the_live_trackers_messages(
    aircraft: Path, tmp_path: Path
) -> None:
    start, truths, estimates = _live_estimates(aircraft)
    assert all(m.nis is not None for m in estimates) and estimates[-1].nis_window is not None
    store = Store(tmp_path / "scorer.sqlite")
    store.episode_start(start)
    for t, m in zip(truths, estimates, strict=True):
        store.truth(t)
        store.estimate(m, time.time())
    summary = Summarizer(store).summary()
    said = warnings(summary)
    assert any(w.startswith("tl-ukf: NIS above its 99% band") for w in said), summary["filters"]
    store.close()

    state, rejects = State(), RejectCounter()
    metrics = Metrics(state)
    ingest = Ingest(state, metrics, rejects)
    sample = lambda key, m: Received(key, encode(m), zenoh.SampleKind.PUT, time.time())  # noqa: E731
    ingest.handle(sample(keys.episode(E), start))
    for t, m in zip(truths, estimates, strict=True):
        ingest.handle(sample(keys.truth(E), t))
        ingest.handle(sample(keys.primary_estimate("tl", E), m))
    assert rejects.total == 0, rejects.snapshot()
    (tl,) = state.snapshot()["episode"]["filters"]
    assert tl["consistency"] is not None and "noise is too low" in tl["consistency"], tl
    assert tl["nis_window"] > band_high(estimates)
    exposed = generate_latest(metrics.registry).decode()
    assert 'tltrack_nis_window{filter="tl-ukf"}' in exposed
    ratio = [ln for ln in exposed.splitlines() if ln.startswith("tltrack_nis_above_band_ratio{")]
    assert ratio and float(ratio[0].split()[-1]) >= 0.5, ratio


def band_high(estimates: list[EstimateMsg]) -> float:
    band = estimates[-1].nis_band
    assert band is not None
    return float(band[1])


def test_a_fitting_model_raises_no_warning() -> None:
    """The arasaratnam-haykin scenario itself, its own noise: the NIS stays in its band."""
    cfg = load_config(None, preset="arasaratnam-haykin", truth="random", runs=20, K=60)
    res = run_experiment(cfg, ["ukf", "tl-ukf"], workers=1, time_steps=False)
    for name, r in res.items():
        assert r.consistency is None and abs(r.nis - 2.0) < 0.3, (name, r.nis, r.nis_above_band)
    assert np.isfinite(res["ukf"].rmse_overall)
