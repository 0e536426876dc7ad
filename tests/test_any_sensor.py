"""Any pair of sensors, any scenario: every filter kind and role runs, and so does the PCRLB.

Tiny N and K: this checks that everything composes (shapes, angles, layouts), not accuracy;
tltrack study heterogeneous measures that.
"""

from __future__ import annotations

import numpy as np
import pytest
from tltrack.config import make_config
from tltrack.engine.montecarlo import check_filters, run_batch
from tltrack.engine.results import position_bounds
from tltrack.engine.setup import Setup
from tltrack.filters.decision import NotComparableError
from tltrack.filters.kinds import FILTERS
from tltrack.models.base import PositionFix
from tltrack.models.kinds import SENSORS

pytestmark = pytest.mark.unit

SENSOR_KINDS = SENSORS.names()
#: every filter, robust transfer aside (it needs sensors that fix a position)
NAMES = [f"{role}{kind}" for kind in FILTERS.names() for role in ("", "tl-", "source-")] + [
    "fusion-pf"
]


def config(scenario: str, primary: str, source: str) -> object:
    return make_config(
        scenario=scenario,
        K=6,
        particles=60,
        primary_sensor={"kind": primary, "position": [0.0, 0.0]},
        sources=[{"id": "s1", "sensor": {"kind": source, "position": [-3000.0, -5000.0]}}],
    )


@pytest.mark.parametrize("scenario", ["cv", "ct", "ca"])
@pytest.mark.parametrize("primary", SENSOR_KINDS)
def test_every_filter_runs_for_a_pair_of_sensors_of_any_kind(scenario: str, primary: str) -> None:
    source = SENSOR_KINDS[(SENSOR_KINDS.index(primary) + 1) % len(SENSOR_KINDS)]
    cfg = config(scenario, primary, source)
    names = list(NAMES)
    comparable = all(isinstance(Setup(cfg).sensor(i), PositionFix) for i in ("primary", "s1"))
    if comparable:
        names.append("robust-tl-pf")
    stats = run_batch(cfg, names, [0, 1])
    expected = {*names, "source-pf", "source-ukf", "source-ckf3", "source-ckf5"}
    assert set(stats) == expected
    for name, s in stats.items():
        assert s.sq_err.shape == (6,) and np.all(np.isfinite(s.sq_err)), (name, s.sq_err)
    bounds = position_bounds(cfg)
    for b in bounds.values():
        assert len(b) == 6 and np.all(np.isfinite(b)) and np.all(np.asarray(b) > 0)
    assert np.all(np.asarray(bounds["with_source"]) <= np.asarray(bounds["primary"]) + 1e-9)


def test_robust_transfer_is_refused_at_start_for_a_sensor_that_fixes_no_position() -> None:
    cfg = config("ct", "bearing", "range-bearing")
    with pytest.raises(NotComparableError, match="bearing sensor's measurement fixes no position"):
        check_filters(cfg, ["robust-tl-pf"])
    check_filters(cfg, ["tl-pf", "fusion-pf"])  # unjudged transfer is fine


def test_a_preset_changes_only_what_it_names_for_the_scenario() -> None:
    for preset in ("paper", "arasaratnam-haykin"):
        ca = make_config(scenario="ca", preset=preset)
        assert ca.n_x == 6 and ca.x0 == make_config(scenario="ca").x0
