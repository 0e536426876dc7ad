"""tltrack fit recovers known process noise from simulated tracks, its intervals cover the truth
as often as they claim, and what it writes is a config the tools take."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tltrack.app import app
from tltrack.config import load_config
from tltrack.engine.fit import Reports, fit
from tltrack.models.constant_velocity import ConstantVelocity
from typer.testing import CliRunner

pytestmark = pytest.mark.unit


def simulate(q: float, sigma: float, seed: int, reports: int = 200) -> Reports:
    """A CV track with acceleration noise q, reported with noise sigma at irregular times
    (1-3 s apart, as AIS or ADS-B reports come)."""
    g = np.random.default_rng(seed)
    t = np.cumsum(np.r_[0.0, g.uniform(1.0, 3.0, reports - 1)])
    x, xy = np.array([0.0, 20.0, 0.0, -10.0]), []
    for k in range(reports):
        if k:
            m = ConstantVelocity(T=float(t[k] - t[k - 1]), q=q)
            x = m.A @ x + m.Q_sqrt @ g.standard_normal(2)
        xy.append(x[[0, 2]] + sigma * g.standard_normal(2))
    return Reports(f"q{q}-{seed}", t, np.array(xy))


@pytest.mark.parametrize("q", [0.1, 1.0, 10.0])
def test_the_95_percent_interval_covers_the_true_noise_in_17_of_20_tracks(q: float) -> None:
    fits = [fit([simulate(q, 10.0, seed)], "cv") for seed in range(20)]
    covered = sum(f.intervals["q1"][0] <= q <= f.intervals["q1"][1] for f in fits)
    assert covered >= 17, [f.intervals["q1"] for f in fits]
    estimates = np.array([f.values["q1"] for f in fits])
    assert 0.7 * q < np.median(estimates) < 1.4 * q, estimates  # no bias worth the name
    sigmas = np.array([f.values["sigma"] for f in fits])
    assert np.all(np.abs(sigmas - 10.0) < 2.0), sigmas


def test_the_cli_writes_a_config_that_loads(tmp_path: Path) -> None:
    r = simulate(1.0, 10.0, 3)
    track = tmp_path / "track.csv"
    track.write_text(
        "t,x,y\n" + "".join(f"{a},{b},{c}\n" for a, (b, c) in zip(r.t, r.xy, strict=True))
    )
    out = tmp_path / "fitted.toml"
    done = CliRunner().invoke(app, ["fit", "--truth-file", str(track), "--out", str(out)])
    assert done.exit_code == 0, done.output
    assert "95% interval" in done.output
    cfg = load_config(out)
    assert cfg.scenario == "cv" and 0.3 < cfg.q1 < 3.0, cfg.q1
    bad = tmp_path / "bad.csv"
    bad.write_text("t,x,y\n0,1,2\n")
    done = CliRunner().invoke(app, ["fit", "--truth-file", str(bad)])
    assert done.exit_code == 2 and "error" in done.output


def test_a_fit_of_modes_writes_their_chain_at_the_filters_period(tmp_path: Path) -> None:
    from tltrack.app.fit import config_text
    from tltrack.config.target_classes import transition, uniform_rates
    from tltrack.engine.fit import PARAMETERS, Fit

    values = dict(
        zip(PARAMETERS["manoeuvres"], [0.1, 5.0, 1e-5, 40.0, 1e-3, 0.02, 3.0], strict=True)
    )
    done = Fit("manoeuvres", values, {}, 0.0, 10, ["a.csv"])
    (tmp_path / "m.toml").write_text(config_text(done, Ts=2.0))
    cfg = load_config(tmp_path / "m.toml")
    assert [(m.kind, m.q1, m.q2) for m in cfg.motion_modes or []] == [
        ("cv", 0.1, 0.0),
        ("ct", 5.0, 1e-5),
        ("ct", 40.0, 1e-3),
    ]
    np.testing.assert_allclose(
        cfg.mode_transition, transition(uniform_rates(3, 0.02), 2.0), atol=1e-6
    )
    assert cfg.Ts == 2.0
    (tmp_path / "third.toml").write_text(config_text(done, Ts=1 / 3))  # {Ts:g} wrote 0.333333
    assert load_config(tmp_path / "third.toml").Ts == 1 / 3


@pytest.mark.parametrize(
    ("ts", "says"),
    [
        ("0.0005", "share no grid of 1 ms"),
        ("nan", "finite"),
        ("inf", "finite"),
        ("0", "greater than 0"),
        ("-1", "greater than 0"),
    ],
)
def test_a_period_no_config_takes_is_refused_before_the_fit(ts: str, says: str) -> None:
    """0.5 ms passed, and the config written was refused when loaded; the others never did."""
    done = CliRunner().invoke(app, ["fit", "--truth-file", "absent.csv", "--ts", ts])
    assert done.exit_code == 2 and says in " ".join(done.output.split()), done.output


def test_the_cli_warns_when_the_grid_cuts_the_fit_off(tmp_path: Path) -> None:
    """A track reported with almost no noise puts sigma's maximum below the cv fit's grid: the
    CLI says so, and says nothing of the kind on a track well inside it."""
    quiet, plain = simulate(1.0, 1e-3, 4), simulate(1.0, 10.0, 4)
    for name, r in (("quiet", quiet), ("plain", plain)):
        (tmp_path / f"{name}.csv").write_text(
            "t,x,y\n" + "".join(f"{a},{b},{c}\n" for a, (b, c) in zip(r.t, r.xy, strict=True))
        )
    runner = CliRunner()
    done = runner.invoke(app, ["fit", "--truth-file", str(tmp_path / "quiet.csv")])
    said = " ".join(done.output.split())  # the console wraps at its width
    assert done.exit_code == 0, done.output
    assert "sigma = 0.03162 is not the maximum: the likelihood is higher at 0.02512" in said
    assert "sigma's 95% interval runs past 0.03162" in said
    done = runner.invoke(app, ["fit", "--truth-file", str(tmp_path / "plain.csv")])
    assert done.exit_code == 0 and "warning" not in done.output, done.output
