"""The refactor that made models first-class parts changed no result, bit for bit.

The pre-refactor commit is checked out in a git worktree and run beside this tree, on this machine,
with the same interpreter and libraries: the same small experiment, every filter of both
scenarios, and the two ``results.json`` must agree exactly (RMSE per step, NEES, lost runs,
transfer rates, the PCRLB). One later fix is allowed for: where a filter's covariance went
singular (a collapsed cloud), the NEES is now that of the coordinates with spread, no longer a
solve's rounding noise, so there it must only be a NEES (not negative). No golden file is
committed: numba and NumPy pick CPU-specific code, and one ulp there moves a resampled particle.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
#: the last commit before the models became first-class parts
BEFORE = "d109480"
#: every filter the commit knew
FILTERS = (
    ",".join(
        f"{role}{kind}"
        for kind in ("pf", "ukf", "ckf3", "ckf5")
        for role in ("", "tl-", "robust-tl-", "source-")
    )
    + ",fusion-pf"
)
COMPARED = ("rmse_per_step", "rmse_overall", "nees", "lost_fraction", "transfer_rate")


def _git(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)


@pytest.fixture(scope="module")
def before(tmp_path_factory: pytest.TempPathFactory) -> Any:
    if _git("cat-file", "-e", f"{BEFORE}^{{commit}}").returncode != 0:
        pytest.skip(f"this clone lacks commit {BEFORE} (a shallow clone?)")
    tree = tmp_path_factory.mktemp("before") / "tree"
    added = _git("worktree", "add", "--detach", str(tree), BEFORE)
    assert added.returncode == 0, added.stderr
    yield tree / "shared"
    _git("worktree", "remove", "--force", str(tree))


def experiment(shared: Path, scenario: str, out: Path) -> dict[str, Any]:
    """``tltrack experiment`` with the package found in ``shared`` (and nowhere else)."""
    argv = [sys.executable, "-m", "tltrack", "experiment", "--scenario", scenario]
    argv += ["--filters", FILTERS, "--particles", "300", "--runs", "5", "--seed", "2"]
    argv += ["--workers", "1", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(shared), "MPLBACKEND": "Agg"}
    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads((out / "results.json").read_text())


@pytest.mark.parametrize("scenario", ["cv", "ct"])
def test_every_filter_gives_the_pre_refactor_results_bit_for_bit(
    scenario: str, before: Path, tmp_path: Path
) -> None:
    old = experiment(before, scenario, tmp_path / "before")
    new = experiment(ROOT / "shared", scenario, tmp_path / "now")
    assert old["provenance"]["git_commit"].startswith(BEFORE)
    assert new["filters"].keys() == old["filters"].keys()
    for name, was in old["filters"].items():
        now = new["filters"][name]
        collapsed = now["nees_singular_rate"] > 0
        for field in COMPARED:  # as text: exact, and NaN equals NaN
            if field == "nees" and collapsed:
                continue
            assert json.dumps(now[field]) == json.dumps(was[field]), (name, field)
        if collapsed:  # a singular P, where the old solve returned rounding noise (test_engine)
            assert now["nees"] >= 0 or math.isnan(was["nees"]), (name, now["nees"], was["nees"])
    assert json.dumps(new["pcrlb"]) == json.dumps(old["pcrlb"])
