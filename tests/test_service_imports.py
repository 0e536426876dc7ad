"""A service that never filters never loads the filters, nor numba, which they compile with: a
sensor, sensor_sim, the scorer and the dashboard import (with their plugins) in 0.23-0.36 s and
55-65 MB of resident memory, against 0.37-0.47 s and 117-126 MB while they loaded the filters
(docs/contributing.md, "What makes the tests slow")."""

import subprocess
import sys

import pytest

pytestmark = pytest.mark.unit

NO_FILTERS = (
    "tltrack.services.sensor.sensor",
    "tltrack.services.sensor_sim.simulator",
    "tltrack.services.scorer.scorer",
    "tltrack.services.dashboard.server",
)


def test_the_services_that_do_not_filter_import_no_filter_nor_numba() -> None:
    code = (
        "import importlib, sys\n"
        f"for m in {NO_FILTERS!r}: importlib.import_module(m)\n"
        "from tltrack.config import plugins, load_config\n"
        "plugins.load()\n"
        "load_config(None, sources=[{'id': 's1'}, {'id': 's2'}])\n"
        "print(*(m for m in sys.modules if m == 'numba' or m.startswith('tltrack.filters.')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    # the registry, the interface, and the NIS band the scorer and the dashboard report
    light = {"base", "kinds", "chi2", "consistency"}
    assert {m.removeprefix("tltrack.filters.") for m in out.stdout.split()} <= light, out.stdout
