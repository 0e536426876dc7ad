"""The step driver: the one place the roles step, its transfer channel, and its collectors."""

from __future__ import annotations

import ast
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from tltrack.config import LinkSpec, make_config
from tltrack.engine.driver import Direct, Driver, Lossy, StepRecord, effective_sample_size
from tltrack.engine.montecarlo import Scores, run_batch
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import Setup

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
#: the product's code: every module here steps the roles through the driver
PRODUCT = ("shared/tltrack", "services", "benchmarks", "examples", "scripts", "papers")
DRIVER = ROOT / "shared/tltrack/engine/driver.py"
ROLES = ROOT / "shared/tltrack/filters/transfer.py"


def test_no_module_but_the_driver_uses_the_roles() -> None:
    """Source and Primary (Algorithms 1 and 2) are built and stepped in the driver only; the
    roles' own tests (test_fast_pf) are the one exception outside the product."""
    offenders = []
    for folder in PRODUCT:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path.resolve() in (DRIVER.resolve(), ROLES.resolve()) or ".venv" in path.parts:
                continue
            tree = ast.parse(path.read_text(), str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.module == "tltrack.filters.transfer":
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
                if isinstance(node, ast.Attribute) and node.attr in ("Source", "Primary"):
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not offenders, f"roles used outside the driver: {offenders}"


CFG = make_config(preset="arasaratnam-haykin", truth="fixed", K=20, particles=300, seed=4)
RUNS = [0, 1, 2]


def _steps(
    channel: object | None, names: list[str], also: Callable[[StepRecord], None] | None = None
) -> dict[str, list[StepRecord]]:
    """Every record of ``names`` over the runs, the transfers carried by ``channel``; ``also``
    sees each record as it is made (its filter is the live one, stepped on afterwards)."""
    setup = Setup(CFG)
    sims = [simulate(setup, r) for r in RUNS]
    x0 = np.stack([s.x0_hat for s in sims], axis=1)
    out: dict[str, list[StepRecord]] = {}
    keep: list[Callable[[StepRecord], None]] = [lambda r: out.setdefault(r.name, []).append(r)]
    driver = Driver(
        [setup],
        names,
        x0,
        RUNS,
        channel=channel,
        collectors=[keep + ([also] if also else [])],
    )
    for k in range(1, CFG.K + 1):
        z = {
            i: setup.sensors[i].observe(np.stack([s.z[i][k - 1] for s in sims], 1))
            for i in setup.sensor_ids
        }
        driver.step(k, [z])
    return out


def _means(records: list[StepRecord]) -> np.ndarray:
    return np.stack([r.estimate.mean for r in records])


def _link(seed: int = 1, **spec: float) -> Lossy:
    return Lossy(RUNS, seed, {"s1": LinkSpec(**spec)}, CFG.Ts)


def _used(records: list[StepRecord]) -> np.ndarray:
    """Per step and run: did the update use a transfer."""
    return np.array([np.zeros(len(RUNS), bool) if r.used is None else r.used for r in records])


@pytest.mark.parametrize(
    ("spec", "counter"),
    [({"loss": 1.0}, "lost"), ({"delay_s": 1.3, "deadline_s": 0.25}, "late")],
    ids=["every-transfer-lost", "every-transfer-late"],
)
def test_a_link_that_delivers_nothing_leaves_tl_exactly_the_isolated_filter(spec, counter) -> None:
    """Common random numbers: TL with nothing delivered is the isolated filter, bit for bit; a
    transfer past the primary's deadline is refused and counted, never used at a later step."""
    link = _link(**spec)
    got = _steps(link, ["pf", "tl-pf"])
    np.testing.assert_array_equal(_means(got["tl-pf"]), _means(got["pf"]))
    assert not _used(got["tl-pf"]).any()
    made = CFG.K  # a transfer per step, for k = 2 .. K + 1
    assert getattr(link, counter)["s1"].tolist() == [made] * len(RUNS)
    other = "late" if counter == "lost" else "lost"
    assert getattr(link, other)["s1"].tolist() == [0] * len(RUNS)


def test_a_perfect_link_is_the_direct_one_and_a_lossy_one_is_seeded() -> None:
    direct = _steps(Direct(), ["tl-pf"])["tl-pf"]
    on_time = _steps(_link(delay_s=1.2, deadline_s=0.25), ["tl-pf"])["tl-pf"]  # within Ts + 0.25
    np.testing.assert_array_equal(_means(on_time), _means(direct))
    lossy = {"loss": 0.3, "delay_s": 1.0, "jitter_s": 0.5, "deadline_s": 0.25}
    a = _steps(_link(1, **lossy), ["tl-pf"])["tl-pf"]
    b = _steps(_link(1, **lossy), ["tl-pf"])["tl-pf"]
    c = _steps(_link(2, **lossy), ["tl-pf"])["tl-pf"]
    np.testing.assert_array_equal(_means(a), _means(b))
    assert not np.array_equal(_means(a), _means(c))
    # 70% are not lost, and half of those arrive in time (1 + U(0, 0.5) s <= 1.25 s)
    assert 0.15 < _used(a)[1:].mean() < 0.6


def test_a_transfer_is_taken_only_at_its_own_step_and_only_by_the_runs_it_reached() -> None:
    setup = Setup(CFG)
    z = setup.sensors["s1"].observe(np.zeros((2, len(RUNS))))
    link = _link(3, loss=0.5)
    for k_apply in range(2, 12):
        link.send(("source-pf", "s1"), k_apply, z)
        got = link.receive(("source-pf", "s1"), k_apply)
        reached = link.reached["s1", k_apply]
        assert (got is None) == (not reached.any())
        assert got is None or got.mask.tolist() == reached.tolist()
        assert link.receive(("source-pf", "s1"), k_apply + 1) is None  # never at a later step
    assert 0 < link.lost["s1"].sum() < 10 * len(RUNS)


def test_a_stale_source_has_no_link_of_its_own() -> None:
    with pytest.raises(ValueError, match="stale source's lateness is its fault"):
        make_config(sources=[{"id": "s1", "fault": "stale", "link": {"loss": 0.1}}])
    with pytest.raises(ValueError, match="loss"):
        make_config(sources=[{"id": "s1", "link": {"loss": 1.5}}])


def test_the_engine_is_the_driver_with_the_scores_collector() -> None:
    """run_batch's statistics are those a Scores collector gathers from the driver's records."""
    setup = Setup(CFG)
    sims = [simulate(setup, r) for r in RUNS]
    truth = np.stack([s.truth for s in sims], axis=1)
    records = _steps(None, ["rpf", "tl-rpf"])
    scores = Scores(truth, setup.layout, timing=False, keep_tracks=False)
    for rs in records.values():
        for r in rs:
            scores(r)
    mine, engine = scores.close(), run_batch(CFG, ["rpf", "tl-rpf"], RUNS)
    assert mine.keys() == engine.keys()
    for name in engine:
        np.testing.assert_array_equal(mine[name].sq_err, engine[name].sq_err)
        assert mine[name].transfer_steps == engine[name].transfer_steps


def test_collectors_see_the_diagnostics_of_every_step() -> None:
    seen: list[np.ndarray | None] = []

    def ess_now(r: StepRecord) -> None:
        if r.name == "tl-rpf":
            seen.append(effective_sample_size(r.filter))

    records = _steps(None, ["tl-rpf", "robust-tl-rpf"], also=ess_now)
    assert {len(v) for v in records.values()} == {CFG.K}
    assert records.keys() == {"tl-rpf", "robust-tl-rpf", "source-rpf"}
    ess = np.array(seen)
    assert ess.shape == (CFG.K, len(RUNS)) and np.all((ess >= 1) & (ess <= CFG.particles))
    assert len({tuple(e) for e in ess}) == CFG.K  # each step's own weights, not the last's
    sent = [r.transfer for r in records["source-rpf"]]
    assert all(t is not None and t.origin == "s1" for t in sent)
    assert records["tl-rpf"][0].used is None  # no transfer exists for k = 1
    assert all(r.used.all() for r in records["tl-rpf"][1:])  # type: ignore[union-attr]


def test_a_stale_source_beside_a_linked_one_keeps_its_lag() -> None:
    """The engine's channel: a link for one source leaves another's staleness as it was."""
    from tltrack.engine.faults import STALE_LAG
    from tltrack.engine.montecarlo import channel

    cfg = make_config(sources=[{"id": "s1", "fault": "stale"}, {"id": "s2", "link": {"loss": 1.0}}])
    ch = channel(cfg, RUNS)
    z = Setup(CFG).sensors["s1"].observe(np.zeros((2, len(RUNS))))
    made = {}
    for k_apply in range(2, 8):
        made[k_apply] = replace(z, mean=z.mean + k_apply)
        ch.send(("source-pf", "s1"), k_apply, made[k_apply])
        ch.send(("source-pf", "s2"), k_apply, z)
        assert ch.receive(("source-pf", "s2"), k_apply) is None  # every one lost
    got = ch.receive(("source-pf", "s1"), 7)
    assert got is made[7 - STALE_LAG]
