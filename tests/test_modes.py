"""Multiple-model filtering: every filter kind follows a target that switches between flying
straight and turning, and with one mode it is the single-model filter, bit for bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tltrack.config import ConfigError, load_config, make_config
from tltrack.engine.driver import Driver, StepRecord
from tltrack.engine.montecarlo import run_batch
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import Setup

pytestmark = pytest.mark.unit

BASE = {"preset": "arasaratnam-haykin", "truth": "fixed", "K": 30, "particles": 300, "seed": 5}


def test_one_mode_is_the_single_model_filter_bit_for_bit() -> None:
    single = make_config(**BASE)
    one = make_config(**BASE, motion_modes=[{"kind": "ct", "q1": single.q1, "q2": single.q2}])
    names = [
        f"{r}{k}" for k in ("pf", "rpf", "ukf", "ckf3", "ckf5") for r in ("", "tl-", "robust-tl-")
    ]
    names += ["fusion-rpf", "source-ckf5"]
    a, b = run_batch(single, names, [0, 1]), run_batch(one, names, [0, 1])
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_array_equal(a[name].sq_err, b[name].sq_err, err_msg=name)
        np.testing.assert_array_equal(a[name].nees, b[name].nees, err_msg=name)
        assert a[name].nis_sum == b[name].nis_sum, name


def _straight_turn_straight(path: Path) -> Path:
    """150 m/s straight for 30 s, a 3 deg/s turn for 30 s, straight again: reports every second."""
    heading, xy = 0.5, [(2000.0, -3000.0)]
    for k in range(1, 91):
        heading += np.deg2rad(3.0) if 30 <= k - 1 < 60 else 0.0
        xy.append((xy[-1][0] + 150.0 * np.cos(heading), xy[-1][1] + 150.0 * np.sin(heading)))
    path.write_text("t,x,y\n" + "".join(f"{t},{x},{y}\n" for t, (x, y) in enumerate(xy)))
    return path


def test_the_turn_mode_takes_over_within_five_steps_of_a_turn_and_lets_go_after_it(
    tmp_path: Path,
) -> None:
    modes = [{"kind": "cv", "q1": 0.1}, {"kind": "ct", "q1": 0.1, "q2": 1e-3}]
    cfg = load_config(
        None,
        truth_file=_straight_turn_straight(tmp_path / "turn.csv"),
        particles=2000,
        seed=2,
        motion_modes=modes,
        mode_transition=[[0.95, 0.05], [0.05, 0.95]],
    )
    setup, runs = Setup(cfg), [0, 1, 2, 3]
    sims = [simulate(setup, r) for r in runs]
    turning: dict[str, list[np.ndarray]] = {}

    def collect(r: StepRecord) -> None:
        turning.setdefault(r.name, []).append(r.filter.mode_probabilities[1].copy())  # type: ignore[attr-defined]

    names = ["ukf", "pf", "rpf"]
    x0 = np.stack([s.x0_hat for s in sims], axis=1)
    driver = Driver([setup], names, x0, runs, collectors=[[collect]])
    for k in range(1, cfg.K + 1):
        z = {
            i: setup.sensors[i].observe(np.stack([s.z[i][k - 1] for s in sims], 1))
            for i in setup.sensor_ids
        }
        driver.step(k, [z])
    for name in names:
        p = np.array(turning[name]).mean(axis=1)  # P(ct) at k = 1..K, over the runs
        assert p[20:30].max() < 0.5, (name, p[20:30])  # straight: the cv mode holds
        over = np.flatnonzero(p[30:] > 0.5)  # the turn starts at k = 31
        assert over.size and 31 + over[0] <= 36, (name, np.round(p[28:40], 2))
        assert p[75:].max() < 0.5, (name, p[75:])  # straight again


def test_modes_are_refused_unless_they_fit_together() -> None:
    two = [{"kind": "cv", "q1": 1.0}, {"kind": "ct", "q1": 1.0, "q2": 1e-3}]
    with pytest.raises(ConfigError, match="mode_transition"):
        make_config(motion_modes=two)
    with pytest.raises(ConfigError, match="scenario ct"):
        make_config(scenario="cv", motion_modes=two[:1])
    with pytest.raises(ConfigError, match="sum to 1"):
        make_config(motion_modes=two, mode_transition=[[0.9, 0.1], [0.5, 0.6]])
    with pytest.raises(ConfigError, match="no q2"):
        make_config(motion_modes=[{"kind": "cv", "q1": 1.0, "q2": 1.0}])


def test_the_compiled_propagation_of_mixed_modes_is_each_mode_s_model() -> None:
    """Particles of three modes in one run: the compiled kernel moves each as its own mode's f
    and Q_sqrt do in NumPy, from the same Gaussians (and the look-ahead's means likewise)."""
    from tltrack.filters.kernels.gaussians import gaussians, uniforms_per_run
    from tltrack.filters.particle_modes import ParticleModes
    from tltrack.models.coordinated_turn import CoordinatedTurn
    from tltrack.models.modes import MotionModes, Straight

    models = (Straight(1.0, 1.0), CoordinatedTurn(1.0, 4.0, 1e-2), CoordinatedTurn(1.0, 4.0, 1e-4))
    chain = MotionModes(("cv", "ct1", "ct2"), models, np.full((3, 3), 1 / 3), np.full(3, 1 / 3))
    B, N = 2, 700
    rng = np.random.default_rng(0)
    pm = ParticleModes(chain, [np.random.default_rng(b) for b in range(B)], N)
    assert pm._mixed is not None
    x = np.ascontiguousarray(
        rng.normal(size=(5, B, N)) * [[[100]], [[50]], [[100]], [[50]], [[0.05]]]
    )
    x[4, 0, :5] = [0.0, 1e-7, -1e-7, 40.0, -3.0]  # turn rates tiny, and beyond the fast sin/cos
    anc = rng.integers(0, N, size=(B, N + 1))
    modes = rng.integers(0, 3, size=(B, N))
    U = rng.random((B, uniforms_per_run(3, N)))

    def normals() -> np.ndarray:
        E = np.empty((B, 3, N))
        gaussians(U, E)
        return np.ascontiguousarray(E.transpose(1, 0, 2))

    compiled = pm.propagate(x, anc, modes, U, normals)
    means = pm.means(x, modes)
    pm._mixed = None
    np.testing.assert_allclose(
        compiled, pm.propagate(x, anc, modes, U, normals), rtol=1e-9, atol=1e-9
    )
    np.testing.assert_allclose(means, pm.means(x, modes), rtol=1e-9, atol=1e-9)


def test_a_target_class_sets_the_filters_modes_and_their_chain_at_any_period() -> None:
    from tltrack.config.target_classes import TARGET_CLASSES

    for name, cls in TARGET_CLASSES.items():
        one, two = make_config(target_class=name), make_config(target_class=name, Ts=2.0)
        assert [m.model_dump(exclude_defaults=True) for m in one.motion_modes or []] == [
            {k: v for k, v in m.items() if v} for m in cls.modes
        ]
        Pi1, Pi2 = np.array(one.mode_transition), np.array(two.mode_transition)
        np.testing.assert_allclose(Pi1.sum(axis=1), 1.0)
        np.testing.assert_allclose(Pi1 @ Pi1, Pi2, atol=1e-12)  # one chain, exp(G Ts)
        np.testing.assert_allclose(one.with_(Ts=2.0).mode_transition, Pi2, atol=1e-12)
    assert make_config().motion_modes is None  # without a class, nothing changes
    own = [{"kind": "ct", "q1": 3.0, "q2": 1e-3}]
    assert make_config(target_class="aircraft", motion_modes=own).mode_transition is None
    with pytest.raises(ConfigError, match=r"target_class aircraft.*scenario ct"):
        make_config(target_class="aircraft", scenario="cv")
    with pytest.raises(ConfigError, match="target_class"):
        make_config(target_class="submarine")


def test_the_manoeuvre_study_writes_one_model_against_the_modes_on_every_truth(
    tmp_path: Path,
) -> None:
    import re

    from tltrack.studies import Runner, Setting, manoeuvres
    from tltrack.studies.manoeuvres import TRUTHS

    tracks = Path(__file__).resolve().parents[1] / "examples" / "tracks"
    path = manoeuvres(
        Setting(runs=2, particles=200), Runner(workers=1), tmp_path, tracks=tracks, longest_s=20
    )
    text = path.read_text()
    for truth in TRUTHS:
        assert f"| {truth.label} | one model |" in text and f"| {truth.label} | modes |" in text
    assert re.search(r"[+-]\d+\.\d{3} \(\d+\.\d{3}\)", text), text  # TL - iso (MC error)
    assert (tmp_path / "manoeuvres.png").stat().st_size > 10_000
    with pytest.raises(ValueError, match="no such track"):
        manoeuvres(Setting(runs=1), Runner(workers=1), tmp_path, tracks=tmp_path)
    partial = tmp_path / "partial"  # the last truth's track missing: refused before any run
    partial.mkdir()
    for truth in TRUTHS[:-1]:
        (partial / truth.file).parent.mkdir(parents=True, exist_ok=True)
        (partial / truth.file).write_bytes((tracks / truth.file).read_bytes())
    ran: list[object] = []
    runner = Runner(workers=1, progress=lambda n: ran.append(n))
    with pytest.raises(ValueError, match=f"{TRUTHS[-1].file}: no such track"):
        manoeuvres(Setting(runs=1, particles=200), runner, tmp_path, tracks=partial, longest_s=20)
    assert ran == []  # it ran the first four truths (hours at 1000 runs), then lost them


def test_gather_is_take_along_axis_on_the_ancestors_slots() -> None:
    """Each slot's ancestor's mode, as np.take_along_axis gives it, past the scratch column."""
    from tltrack.filters.particle_modes import ParticleModes
    from tltrack.models.coordinated_turn import CoordinatedTurn
    from tltrack.models.modes import MotionModes, Straight

    models = (Straight(1.0, 1.0), CoordinatedTurn(1.0, 4.0, 1e-2), CoordinatedTurn(1.0, 4.0, 1e-4))
    chain = MotionModes(("cv", "ct1", "ct2"), models, np.full((3, 3), 1 / 3), np.full(3, 1 / 3))
    pm = ParticleModes(chain, [np.random.default_rng(b) for b in range(3)], 50)
    modes = np.random.default_rng(9).integers(0, 3, (3, 50))
    anc = np.random.default_rng(8).integers(0, 50, (3, 51))  # (B, N + 1), as the filters keep it
    got = pm.gather(modes, anc)
    assert got.dtype == np.int64 and got.shape == (3, 50)
    np.testing.assert_array_equal(got, np.take_along_axis(modes, anc[:, :50], axis=1))
