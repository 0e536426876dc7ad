"""Operators with their own periods, phases and clocks (issue 34): the timeline, the truth grid,
the transfers' horizons, and the engine stepping them."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from doubles import Offline, received
from tltrack.config import Config, ConfigError, make_config
from tltrack.config.timeline import US
from tltrack.engine.driver import Sources
from tltrack.engine.montecarlo import run_batch, trace_run
from tltrack.engine.results import assemble
from tltrack.engine.scan_file import ScanFile, ScansDoNotFitError
from tltrack.engine.scenario import sampled, simulate, truth
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.engine.track import track
from tltrack.live.tracking import SourceEpisode
from tltrack.services.primary_tracker import tracker as primary_svc
from tltrack.wire import keys
from tltrack.wire.messages import EpisodeStart, Measurement, encode

pytestmark = pytest.mark.unit

BASE = {"preset": "arasaratnam-haykin", "K": 20, "particles": 300, "seed": 4}


def config(**source: float) -> Config:
    return make_config(BASE, sources=[{"id": "s1", **source}])


def test_the_papers_timeline_is_one_grid_at_ts_and_a_transfer_for_k_plus_1() -> None:
    t = make_config(BASE).timeline
    assert t.synchronous and t.grid_us == US and t.ticks == 20
    assert t.indices(PRIMARY).tolist() == t.indices("s1").tolist() == list(range(1, 21))
    assert [t.targets("s1", k) for k in (1, 7, 20)] == [[(2, US)], [(8, US)], [(21, US)]]
    assert t.sends_ahead == 1


def test_a_slower_source_sends_for_each_primary_sample_until_its_next_step() -> None:
    t = config(period_s=4.0).timeline
    assert not t.synchronous and t.grid_us == US and t.steps("s1") == 5
    # after its step at t = 4 s: the primary's samples at 5, 6, 7 and 8 s
    assert t.targets("s1", 1) == [(j, (j - 4) * US) for j in (5, 6, 7, 8)]
    assert t.sends_ahead == 4


def test_a_faster_source_sends_only_from_its_last_step_before_each_primary_sample() -> None:
    t = config(period_s=0.25).timeline
    assert t.grid_us == US // 4 and t.ticks == 80 and t.steps("s1") == 80
    sent = {k: t.targets("s1", k) for k in range(1, 9)}
    # steps at 0.75 s and 1.75 s send for the primary's 1 s and 2 s, a quarter period ahead
    assert {k: v for k, v in sent.items() if v} == {3: [(1, US // 4)], 7: [(2, US // 4)]}


def test_a_clock_offset_moves_the_horizon_and_equal_offsets_cancel() -> None:
    bound = {**BASE, "max_clock_offset_s": 0.25}
    ahead = make_config(bound, sources=[{"id": "s1", "clock_offset_s": 0.25}])
    assert ahead.timeline.targets("s1", 3) == [(4, 3 * US // 4)]
    both = make_config(
        bound, primary_clock_offset_s=0.25, sources=[{"id": "s1", "clock_offset_s": 0.25}]
    )
    assert both.timeline.targets("s1", 3) == [(4, US)]
    names = ["ukf", "tl-ukf", "pf", "tl-pf"]
    plain, shifted = trace_run(make_config(bound), names, 1), trace_run(both, names, 1)
    for n in names:
        np.testing.assert_array_equal(plain[n], shifted[n], err_msg=n)


def test_a_phase_puts_samples_between_the_grid_of_ts() -> None:
    cfg = make_config(BASE, truth="noise-free", sources=[{"id": "s1", "phase_s": 0.5}])
    t = cfg.timeline
    assert t.grid_us == US // 2 and t.indices("s1")[:3].tolist() == [3, 5, 7]
    fine, coarse = truth(Setup(cfg), 0), truth(Setup(make_config(BASE, truth="noise-free")), 0)
    # the coordinated turn over two half steps is the same turn over one step
    np.testing.assert_allclose(fine[::2], coarse, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(sampled(Setup(cfg), fine, PRIMARY), fine[2::2])
    # the source's prior is the initial estimate carried over its phase
    setup = Setup(cfg)
    x0 = np.asarray(cfg.x0)[:, None]
    m, P = setup.operator("s1").start("s1", x0)
    np.testing.assert_allclose(m[:, 0], setup.motion.with_period(0.5).f(x0)[:, 0])
    assert np.all(np.linalg.eigvalsh(P) > 0) and not np.allclose(P, setup.P0)
    assert setup.operator(PRIMARY).start(PRIMARY, x0)[0] is x0


def test_each_operator_is_scored_at_its_own_samples() -> None:
    res = run_batch(config(period_s=4.0), ["tl-ukf"], [0, 1])
    assert res["source-ukf"].K == 5 and res["tl-ukf"].K == 20
    fast = run_batch(config(period_s=0.25), ["tl-ukf"], [0, 1])
    assert fast["source-ukf"].K == 80 and fast["tl-ukf"].K == 20
    # its step at 0.75 s already sends for the primary's first sample: 2 runs x 20 steps, where
    # the paper's source (and a slower one) sends nothing before the primary's first step
    assert fast["tl-ukf"].transfer_steps == 2 * 20
    assert run_batch(make_config(BASE), ["tl-ukf"], [0, 1])["tl-ukf"].transfer_steps == 2 * 19
    assert res["tl-ukf"].transfer_steps == 2 * 16  # nothing before its first step, at 4 s


def test_a_transfer_off_the_sources_steps_is_its_own_at_its_own_period() -> None:
    """``ahead`` carries the posterior by the unscented transform; over the source's own period
    a UKF source's own prediction does the same, so the two agree."""
    cfg = make_config(BASE)
    setup = Setup(cfg)
    sims = [simulate(setup, r) for r in (0, 1)]
    x0 = np.stack([s.x0_hat for s in sims], axis=1)
    sources = Sources(setup, [("source-ukf", "s1")], x0, [0, 1])
    for k in range(1, 6):
        z = setup.sensors["s1"].observe(np.stack([s.z["s1"][k - 1] for s in sims], 1))
        own = sources.step(k, {"s1": z})["source-ukf", "s1"]
        carried = sources.ahead(("source-ukf", "s1"), cfg.Ts)
        np.testing.assert_allclose(carried.mean, own.mean, rtol=1e-10)
        np.testing.assert_allclose(carried.cov, own.cov, rtol=1e-8)
        assert carried.origin == "s1"


def test_a_clock_bound_widens_every_transfer_by_the_state_moving_in_that_time() -> None:
    """With clocks within b of the truth, the horizon is off by up to 2b; to first order the
    transfer's covariance grows by (2b)^2 H v v' H', v the carried state's velocity."""
    cfg = make_config(BASE, max_clock_offset_s=0.2)
    setup = Setup(cfg)
    sims = [simulate(setup, r) for r in (0, 1)]
    x0 = np.stack([s.x0_hat for s in sims], axis=1)
    sources = Sources(setup, [("source-ukf", "s1")], x0, [0, 1])
    z = setup.sensors["s1"].observe(np.stack([s.z["s1"][0] for s in sims], 1))
    sources.step(1, {"s1": z})
    role = sources.roles["source-ukf", "s1"]
    sure = role.ahead(setup.motion.with_period, 1.0)
    unsure = sources.ahead(("source-ukf", "s1"), 1.0)
    # a wider prior moves E[h(x)] only by the sensor's curvature
    np.testing.assert_allclose(unsure.mean, sure.mean, rtol=1e-2)
    grown = unsure.cov - sure.cov
    assert np.all(np.linalg.eigvalsh(grown) > -1e-9)  # it only ever widens
    assert np.all(np.einsum("bii->b", grown) > 0)
    assert sources.clock_spread_s == pytest.approx(0.4)
    # each run's growth in range is (sigma_t times the range rate)^2, to first order
    x = role.filter.m  # the UKF source's own prediction over its period: the carried mean
    r_dot = np.einsum("ib,ib->b", x[[0, 2]], x[[1, 3]]) / np.hypot(x[0], x[2])
    np.testing.assert_allclose(grown[:, 0, 0], (sources.clock_spread_s * r_dot) ** 2, rtol=0.05)


@pytest.mark.parametrize(
    ("given", "says"),
    [
        ({"sources": [{"id": "s1", "period_s": 1 / 3}]}, "share no grid of 1 ms"),
        ({"sources": [{"id": "s1", "period_s": 0}]}, "sources.0.period_s"),
        ({"sources": [{"id": "s1", "phase_s": 1.0}]}, "sources.s1.phase_s = 1 s is not in [0"),
        ({"primary_phase_s": 1.5}, "primary_phase_s = 1.5 s is not in [0, Ts = 1 s)"),
        ({"sources": [{"id": "s1", "clock_offset_s": -2}]}, "sources.s1.clock_offset_s = -2 s"),
        ({"sources": [{"id": "s1", "clock_offset_s": 0.1}]}, "max_clock_offset_s = 0 s"),
        ({"primary_clock_offset_s": 0.5, "max_clock_offset_s": 0.1}, "max_clock_offset_s = 0.1"),
        ({"duration_s": 30, "K": 10}, "give duration_s or K, not both"),
        ({"duration_s": 0.5}, "holds no primary sample"),
    ],
)
def test_a_bad_clock_is_refused_naming_its_field(given: dict[str, object], says: str) -> None:
    with pytest.raises(ConfigError, match=re.escape(says)):
        make_config({"preset": "arasaratnam-haykin", **given})


def test_duration_gives_the_primarys_steps() -> None:
    cfg = make_config({"duration_s": 30.5, "primary_phase_s": 0.5})
    assert cfg.K == 30 and cfg.timeline.indices(PRIMARY)[-1] == 61  # 30.5 s on a 0.5 s grid


def test_fusion_needs_one_clock() -> None:
    from tltrack.engine.montecarlo import check_filters

    with pytest.raises(ValueError, match="centralized fusion"):
        check_filters(config(period_s=2.0), ["fusion-pf"])


def test_where_one_clock_is_assumed_another_is_refused_with_the_reason(tmp_path: Path) -> None:
    """A scan file's steps and the PCRLB assume one clock: each refuses, or leaves out,
    operators with their own, and says so."""
    cfg = config(period_s=2.0)
    scans = ScanFile(tmp_path / "scans.csv", 20, {}, {}, [], {})
    with pytest.raises(ScansDoNotFitError, match="on one clock"):
        track(cfg, ["ukf"], scans)
    doc = assemble(cfg, {})
    assert doc["pcrlb"] == {} and "no PCRLB" in doc["pcrlb_note"]
    assert len(assemble(make_config(BASE), {})["pcrlb"]["primary"]) == 20


def _open_off_the_clock(tracker: Any) -> Config:
    """Open episode "e" on ``tracker``: a source s1 sampling every 4 s on a clock 0.25 s ahead,
    off the paper's shared clock; its config."""
    cfg = make_config(
        BASE,
        max_clock_offset_s=0.25,
        sources=[{"id": "s1", "period_s": 4.0, "clock_offset_s": 0.25}],
    )
    start = EpisodeStart(
        episode="e", sender="sensor_sim", k=0, t_sensor=time.time(), run=0,
        config=cfg.model_dump(mode="json"), K=cfg.K, steps_per_sec=0.0,
    )  # fmt: skip
    tracker.handle(received(keys.episode("e"), encode(start)))
    return cfg


def test_the_primary_takes_a_transfer_only_for_its_own_samples_time() -> None:
    """Live, a transfer names the primary's sample (k_apply) and its time on the primary's
    schedule (t_apply): one for another time, or none at all off the shared clock, or one made
    later than now beyond the hosts' clock skew, is refused and counted, never kept for a step."""
    svc = Offline("primary_tracker")
    tracker = primary_svc.PrimaryTracker(primary_svc.Settings.model_validate({}), svc)
    cfg = _open_off_the_clock(tracker)
    src = SourceEpisode(cfg, 0, "ukf", "s1")
    z = Measurement(episode="e", sender="s", k=1, t_sensor=0.0, sensor="s1",
                    z=[simulate(Setup(cfg), 0).z["s1"][0]])  # fmt: skip
    eta = src.step(z)[1]
    assert src.sends(eta) == [] and not src.addressed  # off the shared clock: the schedule first
    announced = [m for key, m in svc.published if key == keys.schedule("e")]
    assert announced and announced[0].period_s == 1.0 and announced[0].t0_s == 0.0
    src.heard(announced[0])  # type: ignore[arg-type]
    (j, t_apply, eta), *_ = src.sends(eta)
    assert (j, t_apply) == (5, 5.0)

    def offer(t_apply: float | None, t_sensor: float | None = None) -> None:
        k = 1 if t_apply is not None else j - 1  # unstamped: as on the shared clock
        msg = src.transfer_message(eta, "e", k, time.time() if t_sensor is None else t_sensor,
                                   j, t_apply)  # fmt: skip
        tracker.handle(received(keys.transfer("s1", "e"), encode(msg)))

    offer(5.0 + 0.002)  # 2 ms off, beyond the 1 ms tolerance
    offer(None)  # off the shared clock a transfer must say its time
    offer(5.0, t_sensor=time.time() + 2.0)  # made 2 s from now: beyond the hosts' 1 s skew
    assert svc.rejects.by_reason() == {"wrong_time": 2, "from_the_future": 1}
    assert tracker.episodes.get("e").transfers == {}  # type: ignore[union-attr]
    offer(5.0 + 0.0005)
    assert set(tracker.episodes.get("e").transfers[5]) == {"s1"}  # type: ignore[union-attr]


@pytest.mark.parametrize(
    ("period_s", "t0_s"),
    [(1e-7, 0.0), (1e-4, 0.0), (2.0, 0.0), (1.0, -0.5), (1.0, 1.25), (1.0, 1e300)],
    ids=["rounds-to-zero", "ten-thousand-a-step", "not-Ts", "before", "after", "far"],
)
def test_a_schedule_that_cannot_be_the_episodes_is_refused_and_counted(
    period_s: float, t0_s: float
) -> None:
    """A period of 1e-7 s divided by zero in the source (its tracker ended), 1e-4 s made it
    compute 10,000 transfers a step; any period but Ts, or a first sample no phase in [0, Ts)
    and clock offset within max_clock_offset_s gives, is not the primary's: refused."""
    from tltrack.services.source_tracker import tracker as source_svc
    from tltrack.wire.messages import Schedule

    svc = Offline("source_tracker", keys.source_operator("s1"))
    tracker = source_svc.SourceTracker(source_svc.Settings.model_validate({}), svc)
    _open_off_the_clock(tracker)
    for period, t0 in ((period_s, t0_s), (1.0, 0.0)):  # then the primary's own
        msg = Schedule(episode="e", sender=keys.PRIMARY, k=0, t_sensor=time.time(),
                       period_s=period, t0_s=t0)  # fmt: skip
        tracker.handle(received(keys.schedule("e"), encode(msg)))
    assert svc.rejects.by_reason() == {"invalid": 1}
    assert tracker.episodes.get("e").tracker.addressed  # type: ignore[union-attr]


def test_the_primarys_own_schedule_is_heard_at_an_offset_of_no_whole_microsecond() -> None:
    """The primary stamps its first sample in whole microseconds (-0.123457 s for an offset of
    -0.1234567 s): the bounds are checked in microseconds too, or its own schedule is refused."""
    from tltrack.wire.messages import Schedule

    cfg = make_config(
        BASE,
        max_clock_offset_s=0.1234567,
        primary_clock_offset_s=-0.1234567,
        sources=[{"id": "s1", "period_s": 4.0}],
    )
    t0 = cfg.timeline.stamp(PRIMARY, 0) / US
    src = SourceEpisode(cfg, 0, "ukf", "s1")
    src.heard(Schedule(episode="e", sender=keys.PRIMARY, k=0, t_sensor=0.0, period_s=1.0, t0_s=t0))
    assert src.addressed
