"""The tutorials that the documentation's build does not run: each script as its page includes
it, run here, and checked for what its page says it shows."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

TUTORIALS = Path(__file__).resolve().parents[1] / "examples" / "tutorials"


def tutorial(name: str) -> ModuleType:
    """``examples/tutorials/<name>.py`` as a module (it runs nothing on import)."""
    spec = importlib.util.spec_from_file_location(f"tutorial_{name}", TUTORIALS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.integration
@pytest.mark.timeout(300)
def test_the_first_live_demo_scores_every_step_with_the_transfer(tmp_path: Path) -> None:
    steps = 30
    summary = tutorial("live_demo").main(tmp_path, steps=steps, particles=500)
    assert summary["access_control"] is True and summary["topology"] == "federated"
    filters = summary["filters"]
    assert {"rpf", "tl-rpf", "source-rpf"} <= set(filters), filters.keys()
    for name, f in filters.items():
        assert f["steps"] == steps and f["rmse_overall"] is not None, (name, f)
    assert filters["tl-rpf"]["steps_with_transfer"] >= steps - 2  # none at k = 1
    assert (tmp_path / "summary.json").is_file() and (tmp_path / "logs").is_dir()


@pytest.mark.unit
def test_recorded_tracks_tl_follows_the_vessel_more_closely(tmp_path: Path) -> None:
    doc = tutorial("recorded_tracks").main(tmp_path, runs=4, particles=500)
    rmse = {n: r["rmse_overall"] for n, r in doc["filters"].items()}
    assert doc["truth"]["mode"] == "file" and doc["truth"]["K"] == 600
    assert rmse["tl-rpf"] < rmse["rpf"] and rmse["tl-ukf"] < rmse["ukf"], rmse
    for figure in ("results.json", "rmse.png", "trajectory.png"):
        assert (tmp_path / figure).stat().st_size > 0


@pytest.mark.unit
def test_robust_transfer_keeps_the_gain_and_ignores_a_biased_source() -> None:
    res = tutorial("robust_transfer").main(runs=10, particles=500)
    honest, biased = res["none"], res["bias"]
    rmse = {f: {n: r.rmse_overall for n, r in d.items()} for f, d in res.items()}
    # honest source: robust TL uses it nearly always and keeps TL's gain
    assert honest["robust-tl-rpf"].transfer_rate > 0.9, rmse
    assert rmse["none"]["robust-tl-rpf"] < rmse["none"]["rpf"], rmse
    # biased source: plain TL follows it off; robust TL stays with the isolated filter
    assert rmse["bias"]["tl-rpf"] > 2 * rmse["bias"]["rpf"], rmse
    assert abs(rmse["bias"]["robust-tl-rpf"] - rmse["bias"]["rpf"]) < 0.05 * rmse["bias"]["rpf"]
    assert biased["robust-tl-rpf"].transfer_rate < 0.05, rmse


@pytest.mark.unit
def test_three_sources_help_more_than_one() -> None:
    res = tutorial("many_sources").main(runs=10, particles=500)
    one, three = res["one source"], res["three sources"]
    assert {"source-rpf/s1", "source-rpf/s2", "source-rpf/s3"} <= set(three), three.keys()
    assert three["tl-rpf"].rmse_overall < one["tl-rpf"].rmse_overall < one["rpf"].rmse_overall
